"""The emcee plugin of :mod:`.samplers`: the ensemble from the fit's modes, run by the
one driver :func:`.emcee_run.run_ensemble` (its docstring: moves, the 50 tau rule,
resume, memory), with its knobs in :class:`EmceeSettings`.

* Walkers start around the best fit with per-coordinate spreads from the local
  curvature of log p (:func:`.toolbox.curvature_scales`, x ``init_ball``): tight where the
  data pin a parameter, wide (up to 0.3 prior widths) where they do not; with
  ``init_modes`` also around every distinct rival mode the fit found
  (:func:`.toolbox.fit_modes`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...radar.seeds import rng as seeded_rng
from ...generator.model import wrap_phase
from .base import PluginSettings, SamplerRun
from .emcee_run import run_ensemble
from .toolbox import curvature_scales, fit_modes


@dataclass(frozen=True)
class EmceeSettings(PluginSettings):
    """The emcee plugin's knobs (and the driver's, :func:`.emcee_run.run_ensemble`).

    ``n_walkers`` walkers (0 = 2 x dimensions + 2, the least differential evolution
    needs, since every walker costs a likelihood evaluation per step; at least 32), run
    in blocks of ``check_every`` steps until the chain is ``min_tau_multiple`` integrated
    autocorrelation times long and tau changed by less than ``tau_rtol`` between checks:
    convergence sets the length; ``max_steps`` (steps per walker; None = no cap) ends a
    run that has not converged by then (flagged; the shared ``time_budget`` does too).
    Burn-in ``burn_tau`` x max tau, thinning ``thin_tau`` x min tau (at least 1 step).
    ``store_every``: keep every k-th step in memory and in the HDF5 checkpoint (0 =
    auto: the chain stays under ~160 MB; tau, burn-in and thinning count steps).
    Walkers start at the best fit + ``init_ball`` x the local curvature scale of every
    coordinate (:func:`.toolbox.curvature_scales`); with ``init_modes`` they are split
    over every distinct fit start within 10 nats of the best (rival modes).
    """

    n_walkers: int = 0
    max_steps: int | None = None
    check_every: int = 500
    store_every: int = 0
    min_tau_multiple: float = 50.0
    tau_rtol: float = 0.05
    burn_tau: float = 3.0
    thin_tau: float = 0.5
    init_ball: float = 0.5
    init_modes: bool = True

    BUDGETS = ("max_steps",)  # a resumed run may be given another

    def __post_init__(self) -> None:
        positive = {"check_every": self.check_every, "min_tau_multiple": self.min_tau_multiple,
                    "init_ball": self.init_ball}
        if self.max_steps is not None:
            positive["max_steps"] = self.max_steps
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"CalibrationSettings.{name} must be > 0, got {value!r}")
        if self.n_walkers < 0 or self.store_every < 0:
            raise ValueError("CalibrationSettings.n_walkers and store_every must be >= 0")

    @classmethod
    def quick(cls) -> "EmceeSettings":
        """A short chain for tests and ``--quick`` (usually ends before 50 tau, flagged)."""
        return cls(n_walkers=32, max_steps=1000, check_every=250)


def initial_ball(layout, theta_best: np.ndarray, log_post, n_walkers: int, scale,
                 rng: np.random.Generator) -> np.ndarray:
    """n_walkers points theta_best + scale * N(0, 1) (scale: (dim,) or a fraction of the
    prior widths), all inside the prior support (reflected at bounds, redrawn when
    they break the ordering constraints)."""
    lo, hi = layout.theta_bounds()
    if np.ndim(scale) == 0:
        scale = float(scale) * (hi - lo)
    out = np.empty((0, layout.dim))
    box = np.ones(layout.dim, bool)
    box[layout.phase_cols] = False
    for attempt in range(200):
        th = theta_best + scale * rng.standard_normal((n_walkers, layout.dim))
        th[:, box] = lo[box] + np.abs(th[:, box] - lo[box])
        th[:, box] = hi[box] - np.abs(hi[box] - th[:, box])
        th[:, layout.phase_cols] = wrap_phase(th[:, layout.phase_cols])
        th[:, : layout.dim_z] = layout.canonical(th[:, : layout.dim_z])  # the mirror image: same density
        th = th[np.isfinite(log_post(th))]
        out = np.concatenate([out, th])[:n_walkers]
        if len(out) == n_walkers:
            return out
        if attempt % 10 == 9:  # a narrow support near the best fit: a smaller ball
            scale = scale * 0.5
    raise ValueError("could not place walkers inside the prior around the best fit "
                     "(is the best fit on the boundary of the ordering constraint w_a < w_b?)")


def start_walkers(post, fit, settings, n_walkers: int, rng) -> tuple[np.ndarray, int]:
    """Initial walkers (n_walkers, dim): around the best fit, and with ``init_modes``
    also around every distinct rival mode the fit found (:func:`fit_modes`), split
    evenly, so the ensemble starts on every competitive mode it knows of.
    Returns (walkers, number of modes started on)."""
    layout = post.layout
    own = settings.of("emcee")
    centres = fit_modes(post, fit) if own.init_modes else [fit.best_z]
    counts = np.full(len(centres), n_walkers // len(centres))
    counts[0] += n_walkers - counts.sum()
    groups = []
    for v, n in zip(centres, counts):
        theta = post.theta_from_fit(np.asarray(v)[None])[0]
        scales = own.init_ball * curvature_scales(layout, theta, post)
        groups.append(initial_ball(layout, theta, post, int(n), scales, rng))
    return np.concatenate(groups), len(centres)


class EmceeSampler:
    """The default sampler: emcee's ensemble (DE moves on the circle + line relabelling),
    run in blocks of ``check_every`` steps until ``min_tau_multiple`` x max tau or the
    time budget (module doc). Resumable from its HDF5 checkpoint. ``settings``: the
    shared :class:`~mdaug.inference.settings.CalibrationSettings`, its own knobs
    :class:`EmceeSettings` at ``settings.of("emcee")``."""

    name = "emcee"

    def run(self, post, fit, settings, seed_seq, *, backend_path=None, fingerprint: str = "") -> SamplerRun:
        layout = post.layout
        ball_ss, mc_ss = seed_seq.spawn(2)
        least = 2 * layout.dim + 2  # DE needs > 2 dim
        n_walkers = max(settings.of("emcee").n_walkers or least, least, 32)
        n_walkers += n_walkers % 2
        p0, n_modes = start_walkers(post, fit, settings, n_walkers, seeded_rng(ball_ss))
        run = run_ensemble(post, p0, settings, seed=int(mc_ss.generate_state(1)[0]), backend_path=backend_path,
                           fp=fingerprint, phase_cols=layout.phase_cols,
                           relabel=layout.random_relabel if settings.relabel > 0 and layout.labelled else None)
        run.extra["n_start_modes"] = int(n_modes)
        return run
