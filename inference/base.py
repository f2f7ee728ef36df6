"""The one interface of the calibration's likelihoods.

A likelihood object holds the data, the :class:`~.layout.Layout` and what its model
needs, and is vectorised over walkers: theta (W, dim) -> (W,). Subclasses give
:meth:`LogPosteriorBase.pointwise` (the log-likelihood per measurement, or per bin);
the base adds the prior (``__call__``, what the samplers call), the fit's
objective and the hooks the fit uses, so the fit and the samplers never ask which
likelihood they hold.
"""
from __future__ import annotations

import numpy as np


class LogPosteriorBase:
    """log p(theta | data) up to a constant; see the module doc."""

    layout = None
    noise_model = ""  # one sentence for the posterior's metadata
    sigma_bounds = None  # the tail's bounds when they are not the layout's (fitted phases)

    # ---- what a subclass gives ------------------------------------------------------------
    def pointwise(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood per measurement (W, M) or per bin (W, M, L)."""
        raise NotImplementedError

    def settings(self) -> dict:
        return {"likelihood": getattr(self, "kind", type(self).__name__)}

    # ---- derived ---------------------------------------------------------------------------
    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood (W,) of theta (W, dim), prior ignored."""
        ll = self.pointwise(np.atleast_2d(theta))
        return ll.reshape(ll.shape[0], -1).sum(axis=1)

    def log_prior(self, theta: np.ndarray, *, any_tail: bool = False) -> np.ndarray:
        return self.layout.log_prior(theta, self.sigma_bounds, any_tail=any_tail)

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        lp = self.log_prior(theta)
        ok = np.isfinite(lp)
        out = np.full(theta.shape[0], -np.inf)
        if ok.any():
            out[ok] = lp[ok] + self.log_likelihood(theta[ok])
        return out

    # ---- the fit (see .fit) ------------------------------------------------------------------
    def fit_objective(self, v: np.ndarray) -> np.ndarray:
        """Negative log-likelihood (W,) at fit-space points, +inf where the ordering
        constraints fail (the tail's bounds are left to the fit's box)."""
        v = np.atleast_2d(v)
        ok = np.isfinite(self.log_prior(v, any_tail=True))
        out = np.full(len(v), np.inf)
        if ok.any():
            out[ok] = -self.log_likelihood(v[ok])
        return out

    def fit_start(self, x: np.ndarray) -> np.ndarray:
        """The fit-space point of class vector x (13E,) (each measurement's own terms in
        the middle of their prior)."""
        lay = self.layout
        start = lay.z_from_physics(x)
        if lay.marginal:
            start = lay.theta_from_z(start[None], np.full((1, lay.M), np.mean(lay.tail_bounds)))[0]
        return self.canonical_fit(start[None])[0]

    def coarse(self) -> "LogPosteriorBase":
        """A cheaper copy for the fit's global stage (the same object when there is none)."""
        return self

    def nuisance_cols(self) -> np.ndarray:
        """Fit-space columns the fit polishes first at its start point (none by default)."""
        return np.zeros(0, dtype=int)


class MarginalLikelihood(LogPosteriorBase):
    """Base of the likelihoods with the phases marginalised (a marginal Layout): the fit
    works on all of theta, the measurements' own terms polished first."""

    def fit_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.layout.theta_bounds()

    def canonical_fit(self, v: np.ndarray) -> np.ndarray:
        v = np.atleast_2d(v)
        return np.concatenate([self.layout.canonical(v[:, : self.layout.dim_z]), v[:, self.layout.dim_z:]], axis=1)

    def fit_objective(self, v: np.ndarray) -> np.ndarray:
        """The objective at the mirror image that meets the ordering constraints (the same
        profiles), so a global search over the whole box is not a plateau of +inf."""
        return super().fit_objective(self.canonical_fit(v))

    def nuisance_cols(self) -> np.ndarray:
        """Fit-space columns of the measurements' own terms (the tail and their z block)."""
        return np.arange(self.layout.n_shared, self.layout.dim)

    def fit_noise(self, v: np.ndarray) -> np.ndarray:
        """Noise floor (W, M) in dB at fit-space points."""
        return np.atleast_2d(v)[:, self.layout.dim_z:]

    def theta_from_fit(self, v: np.ndarray) -> np.ndarray:
        return np.atleast_2d(np.asarray(v, float)).copy()
