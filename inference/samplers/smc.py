"""The ``smc`` plugin of :mod:`.samplers`: tempered sequential Monte Carlo from the prior
(the algorithm in :mod:`.tempering`, its mode jumps in :mod:`.modes`), with its knobs
in :class:`SMCSettings`. Output: the N final particles as one stored step, tau = N /
ESS, and the evidence among the diagnostics (:func:`smc_diagnostics`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import PluginSettings, SamplerRun
from .tempering import SMCResult, run_smc


@dataclass(frozen=True)
class SMCSettings(PluginSettings):
    """The SMC plugin's knobs.

    ``n_particles`` (0 = auto: max(500, 40 x dim)); reweighting to an ESS of ``ess`` x N
    per stage (0.9: slow tempering; at 0.5 the population collapsed onto a wrong mode
    on HELI); a share ``redraw`` of the rejuvenation proposals redraws one coordinate
    from its uniform prior range (jumps between distant narrow modes), a share ``jump``
    are mode jumps (:mod:`.modes`; 0 switches them off) from optima found by polishing
    ``polish`` particles at each discovery level; rejuvenation sweeps until a particle
    has moved with probability ``p_move`` (at most ``max_sweeps`` per stage); at most
    ``max_stages`` stages. The shared ``relabel`` share and ``time_budget`` apply too.
    ``route_moves``: the smc route of an amortized estimator (tempering from its
    posterior, :mod:`mdaug.inference.amortized.tempered`) adds its moves across the
    golf course at the shares measured (``tempered.MOVES``); off by default (why: there).
    ``route_ess``, ``route_p_move``, ``route_max_sweeps``: that route's tempering, lighter
    than the plugin's own (it starts from the amortized posterior, near the target);
    :data:`THOROUGH_ROUTE` is slower tempering with longer rejuvenation (the sampler
    QUAD's 35 quantities need: ``tempered`` says what it measured). The four ``route_*``
    knobs are None unless set: then the estimator file's own (its meta field
    ``route_settings``, the knobs its route table was made with), else
    :data:`ROUTE_DEFAULTS` (:meth:`route`).
    """

    n_particles: int = 0
    ess: float = 0.9
    redraw: float = 0.3
    p_move: float = 0.99
    max_sweeps: int = 40
    max_stages: int = 500
    jump: float = 0.1
    polish: int = 8
    route_moves: bool | None = None
    route_ess: float | None = None
    route_p_move: float | None = None
    route_max_sweeps: int | None = None

    LEGACY = {"smc_ess": "ess", "smc_redraw": "redraw", "smc_p_move": "p_move", "smc_max_sweeps": "max_sweeps",
              "smc_max_stages": "max_stages", "smc_jump": "jump", "smc_polish": "polish"}  # the old flat names

    def __post_init__(self) -> None:
        if not (0 <= self.jump < 1 and self.redraw + self.jump < 1 and self.polish >= 0):
            raise ValueError(f"smc_jump must be in [0, 1) with smc_redraw + smc_jump < 1 and smc_polish >= 0, "
                             f"got {self.jump}, {self.redraw}, {self.polish}")
        if not (0 < self.ess < 1 and 0 < self.p_move < 1 and 0 <= self.redraw < 1):
            raise ValueError(f"smc_ess and smc_p_move must be in (0, 1) and smc_redraw in [0, 1), got "
                             f"{self.ess}, {self.p_move}, {self.redraw}")
        check_route_knobs({k: getattr(self, k) for k in ROUTE_DEFAULTS})
        if self.n_particles < 0 or self.n_particles == 1 or self.max_sweeps < 2 or self.max_stages < 1:
            raise ValueError("CalibrationSettings: n_particles must be 0 (auto) or >= 2, smc_max_sweeps >= 2 "
                             "and smc_max_stages >= 1")

    def route(self, file_knobs: dict | None = None) -> dict:
        """The smc route's knobs (:data:`ROUTE_KNOBS`), each this setting's where set (a
        ``route_*`` knob not None, ``n_particles`` not 0), else the estimator file's
        (``file_knobs``, its meta field ``route_settings``), else :data:`ROUTE_DEFAULTS`
        (``n_particles`` 0 then: the route's own count, ``tempered.n_particles``)."""
        file_knobs = file_knobs or {}
        out = {k: getattr(self, k) if getattr(self, k) is not None else file_knobs.get(k, v)
               for k, v in ROUTE_DEFAULTS.items()}
        out["n_particles"] = self.n_particles or int(file_knobs.get("n_particles", 0))
        return out

    @classmethod
    def quick(cls) -> "SMCSettings":
        """For tests and ``--quick``: 3 particles polished per mode search."""
        return cls(polish=3)


ROUTE_DEFAULTS = {"route_moves": False, "route_ess": 0.7, "route_p_move": 0.9, "route_max_sweeps": 20}
"""The smc route's tempering where neither the settings nor the estimator file set it
(HELI's 8 quantities are sampled well at these; :mod:`mdaug.inference.amortized.tempered`)."""
ROUTE_KNOBS = (*ROUTE_DEFAULTS, "n_particles")
"""The knobs an estimator file may state for its smc route (meta field ``route_settings``)."""


def describe_route_knobs(knobs: dict, particles: bool = True) -> str:
    """The smc route's knobs (:data:`ROUTE_KNOBS`, resolved) in words: one wording for the
    report, ``mdaug sbc`` and the route tables. particles: name the particle count too."""
    words = (f"ESS share {knobs['route_ess']:g} a stage, sweeps until a particle has moved with probability "
             f"{knobs['route_p_move']:g} (at most {knobs['route_max_sweeps']}), moves across the golf course "
             f"{'on' if knobs['route_moves'] else 'off'}")
    return words + (f", {knobs['n_particles']} particles" if particles and "n_particles" in knobs else "")


def check_route_knobs(knobs: dict, where: str = "CalibrationSettings") -> None:
    """ValueError naming ``where`` and the knob for a route knob (:data:`ROUTE_KNOBS`) out
    of range or of the wrong type; None passes (not set). Keys outside ROUTE_KNOBS are refused."""
    unknown = sorted(set(knobs) - set(ROUTE_KNOBS))
    if unknown:
        raise ValueError(f"{where}: unknown route knob(s) {', '.join(unknown)}; expected some of {', '.join(ROUTE_KNOBS)}")
    rules = {"route_moves": (lambda v: isinstance(v, bool), "true or false"),
             "route_ess": (lambda v: _number(v) and 0 < v < 1, "a number in (0, 1)"),
             "route_p_move": (lambda v: _number(v) and 0 < v < 1, "a number in (0, 1)"),
             "route_max_sweeps": (lambda v: _integer(v) and v >= 2, "an integer >= 2"),
             "n_particles": (lambda v: _integer(v) and (v == 0 or v >= 4), "0 (auto) or an integer >= 4")}
    for k, v in knobs.items():
        ok, expected = rules[k]
        if v is not None and not ok(v):
            raise ValueError(f"{where}: {k} must be {expected}, got {v!r}")


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)


def _integer(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


THOROUGH_ROUTE = {"route_moves": True, "route_ess": 0.9, "route_p_move": 0.99, "route_max_sweeps": 60,
                  "n_particles": 1000}
"""The smc route's knobs, its particle count included (``CalibrationSettings().with_plugin("smc",
**THOROUGH_ROUTE)``), at which QUAD's self-check came near an exact sampler's: 0.114 outer-10%
share on 12 drones at 151 s a drone (docs/calibration-history.md, "QUAD's sampler")."""


def posterior_target(post):
    """(log prior, log likelihood) of a :class:`..likelihood.fitted_phases.LogPosterior` for a batch theta (n, dim)."""

    def target(theta):
        lp = post.layout.log_prior(theta)
        out = post(theta)
        ll = np.where(np.isfinite(lp), out - np.where(np.isfinite(lp), lp, 0.0), -np.inf)
        return lp, ll

    return target


class SMCSampler:
    """The tempered-SMC plugin of :mod:`mdaug.inference.samplers` (:mod:`.tempering`)."""

    name = "smc"

    def run(self, post, fit, settings, seed_seq, *, backend_path=None, fingerprint: str = "") -> SamplerRun:
        """settings: the shared :class:`~mdaug.inference.settings.CalibrationSettings`
        (its own knobs, :class:`SMCSettings`, at ``settings.of("smc")``)."""
        layout = post.layout
        own = settings.of("smc")
        n = own.n_particles or max(500, 40 * layout.dim)
        n += n % 2
        bounds = layout.theta_bounds()
        modes = None
        if own.jump > 0:
            from .modes import ModeFinder

            seeds = None if fit is None else post.theta_from_fit(fit.starts_z)
            modes = ModeFinder(post, n_polish=own.polish, seed_thetas=seeds)
        tail = None if layout.marginal else (settings.sigma_min, settings.sigma_max)
        smc = run_smc(posterior_target(post), lambda k, rng: layout.sample_prior(k, rng, tail), n, seed_seq,
                      ess_target=own.ess, p_move=own.p_move, max_sweeps=own.max_sweeps,
                      max_stages=own.max_stages, phase_cols=layout.phase_cols, bounds=bounds,
                      p_redraw=own.redraw, modes=modes, p_jump=own.jump,
                      kernels=((settings.relabel, layout.random_relabel),) if layout.labelled else (),
                      backend_path=backend_path,
                      fp=fingerprint, progress=settings.progress, time_budget=settings.time_budget)
        return sampler_run(smc)


def sampler_run(smc: SMCResult) -> SamplerRun:
    """The SMC run as every sampler returns it: the N particles as one stored step; tau =
    N / ESS (ESS: the weight ESS of the last reweighting: the particles are equally
    weighted afterwards but share ancestors); the diagnostics of :func:`smc_diagnostics`."""
    n, dim = smc.particles.shape
    ess = float(smc.ess[-1]) if smc.ess.size else float(n)
    acc = float(smc.acceptance[-1]) if smc.acceptance.size else 1.0
    return SamplerRun(chain=smc.particles[None], log_prob=(smc.log_lik + smc.log_prior)[None],
                      tau=np.full(dim, n / ess), burn=0, thin=1, acceptance=np.full(n, acc),
                      converged=smc.converged, reason=smc.reason, seconds=smc.seconds,
                      resumed_at=smc.resumed_at, store_every=1, sampler="smc", extra=smc_diagnostics(smc))


def smc_diagnostics(smc: SMCResult) -> dict:
    """Plain-number summary of an SMC run for the result's diagnostics."""
    uniq = len(np.unique(np.round(smc.particles, 12), axis=0)) / len(smc.particles)
    return {"sampler": "smc", "smc_stages": int(len(smc.betas) - 1), "smc_log_z": float(smc.log_z),
            "smc_n_particles": int(len(smc.particles)), "smc_n_evals": int(smc.n_evals),
            "smc_modes": int(smc.n_modes),
            "smc_unique_share": float(uniq), "smc_betas": smc.betas.tolist(),
            "smc_acceptance": smc.acceptance.tolist(), "smc_sweeps": smc.sweeps.tolist(),
            "smc_ess": smc.ess.tolist()}
