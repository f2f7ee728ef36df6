"""The ``laplace`` sampler plugin: importance sampling from a Gaussian at the best fit.

For a deterministic, smooth likelihood (the closed form, :mod:`..likelihood.closed_form`) the
posterior of a well-measured drone is close to a Gaussian at the fit. This plugin
builds that Gaussian and corrects it exactly:

1. the Laplace covariance of the log posterior at the fit's best point
   (:func:`.toolbox.laplace_at`, the one the SMC's mode jumps use: a central-difference
   Hessian in one batched call, a direction the data do not constrain or a prior
   bound on one side given its curvature scale, :func:`.toolbox.curvature_scales`);
2. ``n_particles`` draws, inside the prior, from the toolbox's Student-t mixture
   (:class:`.toolbox.StudentMixture`: 5 degrees of freedom, the Gaussian's covariance
   inflated by ``1.5^2``: heavier tails than the target, so the weights stay bounded;
   phases on the circle), one component at each distinct mode the fit found
   (:func:`.toolbox.fit_modes`; step 1 at each), weighted by their Laplace masses.
   A mode the fit did not find is not proposed: IS cannot see it (the fit's starts
   are the guard, as they are for emcee's start);
3. importance weights p/q, Pareto-smoothed (arviz ``psislw``): the Pareto k-hat says
   whether they can be trusted (< 0.7) and the weights' ESS how many draws they are
   worth; the run is converged when k-hat < 0.7 and ESS >= 400, and says which
   failed otherwise;
4. the draws resampled by weight (systematic resampling) into an equally weighted
   set, stored as SMC stores its particles (one step; tau = N / ESS).

Cost: 2 d^2 + 2 d + 3 per mode + N evaluations, one batch each, no chain: seconds on HELI.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .base import PluginSettings, SamplerRun
from .toolbox import INFLATE, StudentMixture, fit_modes, laplace_at, systematic_resample

KHAT_MAX, ESS_MIN = 0.7, 400
MASS_FLOOR = 0.1  # a mode's least share of the proposal, x 1 / (number of modes)


@dataclass(frozen=True)
class LaplaceSettings(PluginSettings):
    """The laplace plugin's knob: ``n_particles`` importance draws (0 = auto:
    max(2000, 40 x dim); the command line's ``--particles`` sets it with the SMC's)."""

    n_particles: int = 0

    def __post_init__(self) -> None:
        if self.n_particles < 0 or self.n_particles == 1:
            raise ValueError(f"CalibrationSettings: n_particles must be 0 (auto) or >= 2, got {self.n_particles}")


def proposal(post, centres: list, rng: np.random.Generator) -> tuple[StudentMixture, int]:
    """The importance-sampling proposal: a Student-t component at each centre (d,),
    scale ``INFLATE^2`` x its Laplace covariance (:func:`.toolbox.laplace_at`), weighted
    by its Laplace mass floored at MASS_FLOOR / K (a mode the fit ranks low is still
    explored). Returns (the mixture, log-posterior evaluations used)."""
    layout = post.layout
    covs, evals = [], 0
    for c in centres:
        cov, n = laplace_at(post, layout, c)
        covs.append(cov)
        evals += n
    log_mass = np.array([post(c[None])[0] + 0.5 * np.linalg.slogdet(v)[1] for c, v in zip(centres, covs)])
    w = np.exp(log_mass - np.max(log_mass))
    w = np.maximum(w / w.sum(), MASS_FLOOR / len(w))
    mix = StudentMixture.build(centres, [INFLATE**2 * v for v in covs], layout.phase_cols, rng, weights=w)
    return mix, evals + len(centres)


class LaplaceSampler:
    """Importance sampling from the Laplace approximation at the fit (module doc);
    ``settings``: the shared :class:`~mdaug.inference.settings.CalibrationSettings`
    (its own knobs, :class:`LaplaceSettings`, at ``settings.of("laplace")``)."""

    name = "laplace"

    def run(self, post, fit, settings, seed_seq, *, backend_path=None, fingerprint: str = "") -> SamplerRun:
        from ..result.posterior import import_arviz

        t0 = time.perf_counter()
        layout = post.layout
        rng = np.random.default_rng(seed_seq)
        centres = [post.theta_from_fit(np.asarray(z)[None])[0] for z in fit_modes(post, fit)]
        mix, evals = proposal(post, centres, rng)
        n = settings.of("laplace").n_particles or max(2000, 40 * layout.dim)
        pts = np.empty((0, layout.dim))
        while len(pts) < n:  # draws inside the prior (the proposal is unbounded)
            x = mix.sample(n, rng)
            pts = np.concatenate([pts, x[np.isfinite(post.log_prior(x))]])
        pts = pts[:n]
        logq = mix.logpdf(pts)
        lp = post(pts)
        lw = lp - logq
        lw = np.where(np.isfinite(lw), lw, -np.inf)
        with np.errstate(all="ignore"):
            slw, khat = import_arviz().psislw(lw - np.max(lw))
        w = np.exp(slw - np.logaddexp.reduce(slw))
        ess = float(1.0 / np.sum(w**2))
        khat = float(np.asarray(khat))
        keep = systematic_resample(w, rng)
        ok_k, ok_ess = khat < KHAT_MAX, ess >= ESS_MIN
        converged = bool(ok_k and ok_ess)
        reason = ("converged" if converged else
                  f"importance weights unreliable (Pareto k-hat {khat:.2f} >= {KHAT_MAX})" if not ok_k else
                  f"importance-sampling ESS {ess:.0f} < {ESS_MIN}")
        if converged:
            reason = f"converged (Pareto k-hat {khat:.2f}, ESS {ess:.0f} of {n})"
        return SamplerRun(chain=pts[keep][None], log_prob=lp[keep][None], tau=np.full(layout.dim, n / max(ess, 1.0)),
                          burn=0, thin=1, acceptance=np.full(n, ess / n), converged=converged, reason=reason,
                          seconds=time.perf_counter() - t0, sampler="laplace",
                          extra={"khat": khat, "is_ess": ess, "n_proposals": int(n),
                                 "evaluations": int(evals + n),
                                 "n_modes": len(centres)})
