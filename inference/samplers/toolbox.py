"""What the sampler plugins share, so that no plugin imports another: the problem's
fingerprint (:func:`fingerprint`), the integrated autocorrelation time
(:func:`estimate_tau`), the local curvature (:func:`curvature_scales`, :func:`hessian`),
the fit's distinct modes to start from (:func:`fit_modes`) and the one systematic
resampler (:func:`systematic_resample`).
"""
from __future__ import annotations

import numpy as np

from ...radar.keys import cache_key


def fingerprint(*arrays, text: str = "") -> str:
    return cache_key(text=text, arrays=arrays, dtype=np.float64, length=32)


def estimate_tau(chain: np.ndarray, phase_cols=(), discard: float = 1 / 3) -> np.ndarray:
    """Integrated autocorrelation time per coordinate (emcee's estimator, c=5), in steps.

    The first ``discard`` of the chain (the expansion from the start ball) is left
    out. Phases are measured through cos and sin (the larger tau of the two), so a
    wrap at +-pi is not mistaken for a jump.
    """
    import emcee

    chain = chain[int(discard * chain.shape[0]):]
    cols = np.asarray(phase_cols, dtype=int)
    if cols.size:
        ang = chain[..., cols]
        chain = np.concatenate([chain, np.cos(ang), np.sin(ang)], axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = emcee.autocorr.integrated_time(chain, c=5, tol=0, quiet=True)
    # a coordinate some walker never moved in has no estimate: count it as the whole chain
    tau = np.where(np.isfinite(tau), tau, chain.shape[0])
    d = chain.shape[2] - 2 * cols.size
    if cols.size:
        tau_c, tau_s = tau[d: d + cols.size], tau[d + cols.size:]
        tau = tau[:d].copy()
        tau[cols] = np.maximum(tau_c, tau_s)
    return tau


def curvature_scales(layout, theta_best: np.ndarray, log_post, rel_step: float = 0.01, cap: float = 0.3):
    """Per-coordinate scales (dim,) of the posterior at theta_best: 1 / sqrt(-d2 log p / d theta_j^2)
    by central differences (step ``rel_step`` x prior width), clipped to
    [1e-4, ``cap``] x width. A coordinate the data do not constrain (flat log p) gets
    ``cap`` x its prior width, so walkers start spread over it instead of in a
    ball that would take thousands of steps to expand."""
    lo, hi = layout.theta_bounds()
    width = hi - lo
    if not layout.marginal:
        width[layout.dim_z:] = 2.0  # ln sigma: 2 nats (its prior box is far wider than the data allow)
    h = rel_step * width
    pts = np.repeat(theta_best[None], 2 * layout.dim + 1, axis=0)
    idx = np.arange(layout.dim)
    pts[1 + idx, idx] += h
    pts[1 + layout.dim + idx, idx] -= h
    lp = log_post(pts)
    plus, minus = lp[1: 1 + layout.dim], lp[1 + layout.dim:]
    with np.errstate(invalid="ignore"):
        curv = -(plus - 2 * lp[0] + minus) / h**2
    one_sided = ~np.isfinite(curv)  # a bound or the ordering constraint on one side
    side = np.where(np.isfinite(plus), plus, minus)
    curv[one_sided] = -2 * (side[one_sided] - lp[0]) / h[one_sided] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(np.isfinite(curv) & (curv > 0), 1.0 / np.sqrt(curv), np.inf)
    return np.clip(scale, 1e-4 * width, cap * width)


def fit_modes(post, fit) -> list[np.ndarray]:
    """The fit-space centres of the distinct modes the fit found: the best, then every
    start within RIVAL_MISFIT nats of it and more than AGREE_DISTANCE prior widths
    from each centre already taken (in the shared parameters)."""
    from ..fit import AGREE_DISTANCE, RIVAL_MISFIT

    layout = post.layout
    lo, hi = layout.z_bounds()
    width = (hi - lo)[: layout.n_shared]
    centres = [np.asarray(fit.best_z)]
    for i in np.argsort(fit.starts_misfit):
        z = fit.starts_z[i]
        if fit.starts_misfit[i] - fit.misfit > RIVAL_MISFIT:
            break
        if all(np.max(np.abs(z[: layout.n_shared] - c[: layout.n_shared]) / width) > AGREE_DISTANCE
               for c in centres):
            centres.append(np.asarray(z))
    return centres


def hessian(log_f, theta: np.ndarray, h: np.ndarray, diag_h: np.ndarray | None = None) -> np.ndarray:
    """Central-difference Hessian (d, d) of a vectorised log density at theta (d,), one
    batched call of 2 d^2 + 1 points: the cross terms from the four points
    theta +- h_i e_i +- h_j e_j, the diagonal from theta +- diag_h e_i (``h`` when not
    given). The Laplace sampler takes diag_h = 2 h, the mode finder diag_h = h."""
    d = len(theta)
    dh = h if diag_h is None else diag_h
    i, j = np.triu_indices(d, 1)
    pts = [theta[None]]
    for k in (1, -1):  # diagonal: f(x +- diag_h e_i)
        p = np.repeat(theta[None], d, 0)
        p[np.arange(d), np.arange(d)] += k * dh
        pts.append(p)
    for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        p = np.repeat(theta[None], len(i), 0)
        p[np.arange(len(i)), i] += si * h[i]
        p[np.arange(len(i)), j] += sj * h[j]
        pts.append(p)
    lp = log_f(np.concatenate(pts))
    f0, plus, minus = lp[0], lp[1:1 + d], lp[1 + d:1 + 2 * d]
    q = lp[1 + 2 * d:].reshape(4, len(i))
    H = np.zeros((d, d))
    H[np.arange(d), np.arange(d)] = (plus - 2 * f0 + minus) / dh**2
    H[i, j] = H[j, i] = (q[0] - q[1] - q[2] + q[3]) / (4 * h[i] * h[j])
    return H


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices (n,) of a systematic resample of normalised weights (n,)."""
    n = len(weights)
    pos = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(weights), pos), n - 1)
