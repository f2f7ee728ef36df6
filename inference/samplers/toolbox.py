"""What the sampler plugins share, so that no plugin imports another: the problem's
fingerprint (:func:`fingerprint`), the integrated autocorrelation time
(:func:`estimate_tau`), the local curvature (:func:`curvature_scales`, :func:`hessian`),
the fit's distinct modes to start from (:func:`fit_modes`), the one systematic
resampler (:func:`systematic_resample`) and the one Laplace approximation + Student-t
mixture (:func:`laplace_at`, :func:`laplace_covariance`, :class:`StudentMixture`): the
``laplace`` plugin's importance-sampling proposal and the ``smc`` plugin's mode jumps.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from ...generator.model import wrap_phase
from ...radar.keys import cache_key

STEP = 0.5  # finite-difference step of the Laplace Hessian, in curvature scales
DOF = 5.0  # Student-t degrees of freedom of a mixture component (heavy tails cover a mode's skew)
INFLATE = 1.5  # a component's scale over its Laplace scale
FLOOR = 1e-3  # least eigenvalue of the standardised precision: no direction wider than ~32 curvature scales


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


def hessian(log_f, theta: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central-difference Hessian (d, d) of a vectorised log density at theta (d,) with
    steps h (d,), one batched call of 2 d^2 + 1 points: the diagonal from theta +- h_i e_i,
    the cross terms from the four points theta +- h_i e_i +- h_j e_j."""
    d = len(theta)
    i, j = np.triu_indices(d, 1)
    pts = [theta[None]]
    for k in (1, -1):  # diagonal: f(x +- h e_i)
        p = np.repeat(theta[None], d, 0)
        p[np.arange(d), np.arange(d)] += k * h
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
    H[np.arange(d), np.arange(d)] = (plus - 2 * f0 + minus) / h**2
    H[i, j] = H[j, i] = (q[0] - q[1] - q[2] + q[3]) / (4 * h[i] * h[j])
    return H


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices (n,) of a systematic resample of normalised weights (n,)."""
    n = len(weights)
    pos = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(weights), pos), n - 1)


def laplace_covariance(hess: np.ndarray, scale: np.ndarray, max_sd: np.ndarray | None = None) -> np.ndarray:
    """The Laplace covariance -H^-1 (d, d) from a log-density Hessian ``hess`` (d, d).

    A direction the Hessian cannot see (a non-finite entry: a bound within reach; a
    flat or convex diagonal) gets its curvature ``scale`` (d,) alone. Computed in
    coordinates standardised by ``scale``, with the precision's eigenvalues floored at
    FLOOR (a nearly flat direction is wide, not infinite); then every sd is capped at
    ``max_sd`` (d,) when given, correlations kept (:func:`cap_cov`)."""
    s = np.asarray(scale, float)
    H = np.array(hess, float)
    bad = ~np.isfinite(np.diag(H)) | (np.diag(H) >= 0) | ~np.all(np.isfinite(H), axis=1)
    H[bad, :] = 0.0
    H[:, bad] = 0.0
    H[bad, bad] = -1.0 / s[bad] ** 2
    A = -H * s[:, None] * s[None, :]
    w, V = np.linalg.eigh((A + A.T) / 2)
    cov = (V / np.maximum(w, FLOOR)) @ V.T * s[:, None] * s[None, :]
    cov = (cov + cov.T) / 2
    return cov if max_sd is None else cap_cov(cov, max_sd)


def cap_cov(cov: np.ndarray, max_sd: np.ndarray) -> np.ndarray:
    """cov (d, d) with every coordinate's sd shrunk to at most max_sd (d,) (correlations kept)."""
    sd = np.sqrt(np.diag(cov))
    c = np.minimum(1.0, max_sd / sd)
    return cov * c[:, None] * c[None, :]


def laplace_at(log_post, layout, theta: np.ndarray, *, log_f=None, max_sd=None) -> tuple[np.ndarray, int]:
    """The Laplace covariance (d, d) of ``log_f`` (default ``log_post``) at theta (d,):
    the curvature scales of ``log_post`` (:func:`curvature_scales`), the Hessian with
    steps STEP x those scales (:func:`hessian`), then :func:`laplace_covariance`.
    Returns (covariance, log-density evaluations used: 2 d^2 + 2 d + 2)."""
    scale = curvature_scales(layout, theta, log_post)
    H = hessian(log_post if log_f is None else log_f, theta, STEP * scale)
    d = len(theta)
    return laplace_covariance(H, scale, max_sd), 2 * d * d + 2 * d + 2


@dataclass
class StudentMixture:
    """A mixture of multivariate Student-t (DOF) components, truncated to [-pi, pi) on
    the phase coordinates (measured on the circle), so its density is exact there.

    means (K, dim); chols (K, dim, dim) lower Cholesky factors of the scale matrices;
    phase_cols: coordinates on the circle; log_mass (K,): log of each component's
    probability of a draw inside [-pi, pi) in every phase coordinate (0 without
    phases); weights (K,) summing to 1, or None for equal weights."""

    means: np.ndarray
    chols: np.ndarray
    phase_cols: np.ndarray
    log_mass: np.ndarray
    weights: np.ndarray | None = None
    _inv: np.ndarray | None = None  # inverse Cholesky factors and log normalisers, made on first use
    _const: np.ndarray | None = None

    @classmethod
    def build(cls, means, covs, phase_cols, rng: np.random.Generator, n_mc: int = 4000,
              weights=None) -> "StudentMixture":
        """Components at means (K, dim) with scale matrices covs (K, dim, dim); each
        component's truncation mass by ``n_mc`` Monte-Carlo draws (phases only)."""
        means = np.atleast_2d(np.asarray(means, float))
        chols = np.array([np.linalg.cholesky(c + 1e-12 * np.diag(np.diag(c))) for c in covs])
        w = None if weights is None else np.asarray(weights, float) / np.sum(weights)
        mix = cls(means, chols, np.asarray(phase_cols, int), np.zeros(len(means)), w)
        if mix.phase_cols.size:
            mass = [np.mean(mix._inside(mix._t_draws(k, n_mc, rng))) for k in range(len(means))]
            mix.log_mass = np.log(np.maximum(mass, 1.0 / n_mc))
        return mix

    def _t_draws(self, k: int, n: int, rng) -> np.ndarray:
        d = self.means.shape[1]
        z = rng.standard_normal((n, d)) * np.sqrt(DOF / rng.chisquare(DOF, size=(n, 1)))
        return z @ self.chols[k].T

    def _inside(self, y: np.ndarray) -> np.ndarray:
        p = self.phase_cols
        return np.all((y[:, p] >= -np.pi) & (y[:, p] < np.pi), axis=1) if p.size else np.ones(len(y), bool)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n draws (n, dim), phases wrapped."""
        k_all = len(self.means)
        comp = rng.integers(k_all, size=n) if self.weights is None else rng.choice(k_all, size=n, p=self.weights)
        out = np.empty((n, self.means.shape[1]))
        for k in np.unique(comp):
            idx = np.flatnonzero(comp == k)
            got = np.empty((0, out.shape[1]))
            while len(got) < idx.size:
                y = self._t_draws(k, 2 * idx.size, rng)
                got = np.concatenate([got, y[self._inside(y)]])
            out[idx] = self.means[k] + got[: idx.size]
        if self.phase_cols.size:
            out[:, self.phase_cols] = wrap_phase(out[:, self.phase_cols])
        return out

    def logpdf(self, theta: np.ndarray) -> np.ndarray:
        """Log density (n,) of the mixture at theta (n, dim)."""
        theta = np.atleast_2d(theta)
        d = theta.shape[1]
        if self._inv is None:
            self._inv = np.linalg.inv(self.chols)
            self._const = (special.gammaln((DOF + d) / 2) - special.gammaln(DOF / 2) - 0.5 * d * np.log(DOF * np.pi)
                           - np.log(np.diagonal(self.chols, axis1=1, axis2=2)).sum(axis=1) - self.log_mass)
        y = theta[None] - self.means[:, None]  # (K, n, d)
        if self.phase_cols.size:
            y[..., self.phase_cols] = wrap_phase(y[..., self.phase_cols])
        sol = np.einsum("kij,knj->kni", self._inv, y)
        logs = self._const[:, None] - 0.5 * (DOF + d) * np.log1p(np.sum(sol * sol, axis=2) / DOF)
        log_w = np.full(len(self.means), -np.log(len(self.means))) if self.weights is None else np.log(self.weights)
        return special.logsumexp(logs + log_w[:, None], axis=0)
