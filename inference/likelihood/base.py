"""The one interface of the calibration's likelihoods.

A likelihood object holds the data, the :class:`~..space.layout.Layout` and what its model
needs, and is vectorised over walkers: theta (W, dim) -> (W,). Subclasses give
:meth:`LogPosteriorBase.pointwise` (the log-likelihood per measurement, or per bin);
the base adds the prior (``__call__``, what the samplers call), the fit's
objective and the hooks the fit uses, so the fit and the samplers never ask which
likelihood they hold.
"""
from __future__ import annotations

import numpy as np

from ...radar import RadarConfig, centred_slices, normalise

LOG_2PI = float(np.log(2 * np.pi))
"""log(2 pi): the Gaussian normaliser of every likelihood of this room."""


def prepare_measured(profiles, radar: RadarConfig, normalisation: str, what: str = "measured profiles"):
    """Check and normalise measured linear-magnitude profiles.

    profiles: (n, L) or (L,) with L = radar.slice_length. A profile whose maximum is
    not at index L // 2 is re-centred (zero-filled, as f(x) does). Returns
    (normalised (n, L) float64, shifts (n,) in bins). Raises ValueError for a wrong
    length, non-finite values or an all-zero profile.
    """
    y = np.asarray(profiles, dtype=np.float64)
    if y.ndim == 1:
        y = y[None, :]
    if y.ndim != 2 or y.shape[0] == 0:
        raise ValueError(f"{what}: expected shape (n, {radar.slice_length}) or ({radar.slice_length},), got {y.shape}")
    if y.shape[1] != radar.slice_length:
        raise ValueError(f"{what}: profiles have {y.shape[1]} bins; expected {radar.slice_length} "
                         "(peak-centred slices, SPEC section 2)")
    if not np.all(np.isfinite(y)):
        row = int(np.argwhere(~np.isfinite(y))[0, 0])
        raise ValueError(f"{what}: profile {row} holds NaN or inf; expected finite linear magnitudes")
    zero = ~np.any(y != 0, axis=1)
    if zero.any():
        raise ValueError(f"{what}: profile(s) {np.flatnonzero(zero).tolist()} are all zeros; "
                         "nothing to calibrate against")
    if np.any(y < 0):
        raise ValueError(f"{what}: negative values; expected linear magnitudes (>= 0), not dB")
    half = radar.slice_length // 2
    peak = np.argmax(y, axis=1)
    shifts = peak - half
    if np.any(shifts):
        y, _ = centred_slices(y, peak, radar.slice_length)
    return normalise(y, normalisation), shifts


class LogPosteriorBase:
    """log p(theta | data) up to a constant; see the module doc."""

    layout = None
    acquisition = None  # the Acquisition the measurements were made under (the result records it)
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
    works on all of theta, the measurements' own terms polished first. Holds what every
    marginal likelihood checks and keeps: data (M, L) against the marginal layout, the
    acquisition, the radar and the stride of the compared bins."""

    def _take_data(self, data: np.ndarray, layout, acquisition, radar: RadarConfig, stride: int) -> None:
        """The shared constructor checks (a marginal layout, data (M, L), stride >= 1 bin)
        and attributes (data, layout, radar, acquisition, stride, n_calls)."""
        if not layout.marginal:
            raise ValueError(f"{type(self).__name__} needs a marginal Layout (Layout(..., marginal=True))")
        self.data = np.asarray(data, dtype=np.float64)
        if self.data.shape != (layout.M, radar.slice_length):
            raise ValueError(f"data: expected shape ({layout.M}, {radar.slice_length}), got {self.data.shape}")
        if int(stride) < 1:
            raise ValueError(f"stride must be >= 1 bin, got {stride}")
        self.layout, self.radar, self.acquisition, self.stride = layout, radar, acquisition, int(stride)
        self.n_calls = 0

    @property
    def n_bins(self) -> int:
        """Bins compared per measurement."""
        return self.y.shape[1]

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
