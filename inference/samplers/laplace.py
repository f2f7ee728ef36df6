"""The ``laplace`` sampler plugin: importance sampling from a Gaussian at the best fit.

For a deterministic, smooth likelihood (the closed form, :mod:`..likelihood.closed_form`) the
posterior of a well-measured drone is close to a Gaussian at the fit. This plugin
builds that Gaussian and corrects it exactly:

1. the Hessian of the log posterior at the fit's best point, by central differences
   (steps ``0.3`` x the per-coordinate curvature scale, every pair in one batched
   call: 2 d^2 evaluations); a direction the data do not constrain (or a prior bound
   on one side) gets its curvature scale from :func:`.toolbox.curvature_scales`;
2. ``n_particles`` draws, inside the prior, from multivariate Student-t's (5 degrees
   of freedom, the Gaussian's covariance inflated by ``1.5^2``: heavier tails than the
   target, so the weights stay bounded), one at each distinct mode the fit found
   (:func:`.toolbox.fit_modes`; step 1 at each), weighted by their Laplace masses.
   A mode the fit did not find is not proposed: IS cannot see it (the fit's starts
   are the guard, as they are for emcee's start);
3. importance weights p/q, Pareto-smoothed (arviz ``psislw``): the Pareto k-hat says
   whether they can be trusted (< 0.7) and the weights' ESS how many draws they are
   worth; the run is converged when k-hat < 0.7 and ESS >= 400, and says which
   failed otherwise;
4. the draws resampled by weight (systematic resampling) into an equally weighted
   set, stored as SMC stores its particles (one step; tau = N / ESS).

Cost: 2 d^2 per mode + N evaluations, one batch each, no chain: seconds on HELI.
"""
from __future__ import annotations

import time

import numpy as np

from .base import SamplerRun
from .toolbox import curvature_scales, fit_modes, hessian, systematic_resample

NU = 5.0  # Student-t degrees of freedom of the proposal
INFLATE = 1.5  # proposal sd / Laplace sd
KHAT_MAX, ESS_MIN = 0.7, 400


def laplace_covariance(log_post, layout, theta: np.ndarray) -> np.ndarray:
    """The Gaussian's covariance (d, d) at theta: -H^-1, with directions the Hessian
    cannot see (a bound within reach, a flat or convex direction) given their
    curvature scale alone."""
    scale = curvature_scales(layout, theta, log_post)
    h = 0.3 * scale
    H = hessian(log_post, theta, h, 2 * h)
    bad = ~np.isfinite(np.diag(H)) | (np.diag(H) >= 0)
    bad |= ~np.all(np.isfinite(H), axis=1)
    H[bad, :] = 0.0
    H[:, bad] = 0.0
    H[bad, bad] = -1.0 / scale[bad] ** 2
    # standardise, then clamp to a negative-definite matrix (eigenvalues at most -1e-3 of unit curvature)
    D = np.diag(scale)
    A = -D @ H @ D
    w, V = np.linalg.eigh((A + A.T) / 2)
    w = np.maximum(w, 1e-3)
    cov = D @ (V / w) @ V.T @ D
    return (cov + cov.T) / 2


def mixture_t(centres: list, covs: list, log_mass: np.ndarray):
    """The proposal: Student-t(NU) components at the modes (covariances ``INFLATE^2`` x
    their Laplace covariances), weighted by their Laplace masses floored at 10% / K
    (a mode the fit ranks low is still explored). Returns (draw(n, rng), logpdf(x))."""
    from scipy.stats import multivariate_t

    comps = [multivariate_t(loc=c, shape=INFLATE**2 * v, df=NU, allow_singular=True) for c, v in zip(centres, covs)]
    w = np.exp(log_mass - np.max(log_mass))
    w = np.maximum(w / w.sum(), 0.1 / len(w))
    w /= w.sum()

    def draw(n, rng):
        counts = rng.multinomial(n, w)
        return np.concatenate([np.atleast_2d(c.rvs(size=k, random_state=rng)).reshape(k, -1)
                               for c, k in zip(comps, counts) if k])

    def logpdf(x):
        return np.logaddexp.reduce([np.log(wk) + c.logpdf(x) for wk, c in zip(w, comps)], axis=0)

    return draw, logpdf


class LaplaceSampler:
    """Importance sampling from the Laplace approximation at the fit (module doc)."""

    name = "laplace"

    def run(self, post, fit, settings, seed_seq, *, backend_path=None, fingerprint: str = "") -> SamplerRun:
        from ..result.posterior import import_arviz

        t0 = time.perf_counter()
        layout = post.layout
        rng = np.random.default_rng(seed_seq)
        centres = [post.theta_from_fit(np.asarray(z)[None])[0] for z in fit_modes(post, fit)]
        covs = [laplace_covariance(post, layout, c) for c in centres]
        log_mass = np.array([post(c[None])[0] + 0.5 * np.linalg.slogdet(v)[1] for c, v in zip(centres, covs)])
        draw, logpdf = mixture_t(centres, covs, log_mass)
        n = settings.n_particles or max(2000, 40 * layout.dim)
        pts = np.empty((0, layout.dim))
        while len(pts) < n:  # draws inside the prior (the proposal is unbounded)
            x = draw(n, rng)
            pts = np.concatenate([pts, x[np.isfinite(post.log_prior(x))]])
        pts = pts[:n]
        logq = logpdf(pts)
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
                                 "evaluations": int(len(centres) * (2 * layout.dim**2 + 1) + n),
                                 "n_modes": len(centres)})
