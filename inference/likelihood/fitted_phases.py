"""The likelihood of measured profiles given the model, vectorised over walkers.

Noise model (stated once): after the same normalisation as f(x) (``peak`` by
default), every bin of measurement m is the model profile plus independent
Gaussian noise of a per-measurement level sigma_m, which is inferred (log-uniform
prior). For a measured linear-magnitude profile with a noise floor this is an
approximation (magnitudes are Rician; the noisy peak used for normalisation
carries noise too); it keeps the per-bin log-likelihood available for LOO/WAIC.
The fit uses the same model with sigma_m profiled out: misfit =
sum_m (L/2) ln(SSR_m / L), a monotone map of the sum of squared residuals.
"""
from __future__ import annotations

import numpy as np

from ...generator import profiles as model_profiles
from ...generator import spectra as model_spectra
from ...generator.acquisition import Acquisition
from ...radar import RadarConfig, normalise
from .base import LOG_2PI, LogPosteriorBase
from ..space.layout import Layout

ALIGNMENTS = ("tone", "peak")


class LogPosterior(LogPosteriorBase):
    """log p(theta | data) for a batch of theta (W, dim); callable by emcee with vectorize=True.

    data: (M, L) normalised measured profiles; layout: the :class:`Layout`;
    acquisition: how they were measured (default the published single chirp; fixed
    phases, one ramp, no MTI: the acquisitions this likelihood models).
    """

    noise_model = "Gaussian iid per bin on the normalised profile, sigma per measurement (log-uniform)"

    def __init__(self, data: np.ndarray, layout: Layout, radar: RadarConfig = RadarConfig(), *,
                 normalisation: str = "peak", dtype: str = "float32", sigma_bounds=(1e-4, 1.0),
                 alignment: str = "tone", acquisition: Acquisition = Acquisition()):
        self.data = np.asarray(data, dtype=np.float64)
        self.acquisition = acquisition
        self.layout, self.radar, self.normalisation = layout, radar, normalisation
        self.dtype, self.sigma_bounds = dtype, tuple(sigma_bounds)
        self.n_bins = self.data.shape[1]
        self.n_calls = 0  # profiles computed (for benchmarks)
        if alignment not in ALIGNMENTS:
            raise ValueError(f"alignment must be one of {ALIGNMENTS}, got {alignment!r}")
        self.alignment = alignment
        centre = int(round(radar.model_range_to_bin(radar.model_range_m)))
        lo = centre - radar.slice_length // 2
        if lo < 0 or lo + radar.slice_length > radar.n_bins:
            raise ValueError(f"model range {radar.model_range_m} m puts the profile window outside the spectrum")
        self._window = slice(lo, lo + radar.slice_length)

    def model(self, z: np.ndarray) -> np.ndarray:
        """Model profiles (W, M, L) of fit-space points z (W, dim_z).

        ``alignment="tone"`` (default): the window is centred on the bin of the
        carrier tone at the model range, and the per-measurement offset moves the tone
        within it (R0 = model range + offset x model range per bin). Unlike f(x)'s
        argmax centring, this is continuous in the parameters: the flat-topped main
        lobe's argmax flips between neighbouring bins under tiny parameter changes,
        and with it the whole window, which makes the likelihood a field of cliffs.
        The offset's prior must cover where the data's window (centred on its own
        maximum) sits relative to the tone. ``alignment="peak"``: f(x) exactly.
        """
        x, off = self.layout.physics(z)
        w, m, _ = x.shape
        r0 = self.radar.model_range_m + off.reshape(-1) * self.radar.model_range_per_bin()
        if self.alignment == "peak":
            prof = model_profiles(x.reshape(w * m, -1), self.radar, r0=r0, normalisation=self.normalisation,
                                  dtype=self.dtype, on_edge="pad")
        else:
            mag = model_spectra(x.reshape(w * m, -1), self.radar, r0=r0, dtype=self.dtype)
            prof = normalise(mag[:, self._window], self.normalisation)
        self.n_calls += w * m
        return prof.reshape(w, m, -1).astype(np.float64)

    def ssr(self, z: np.ndarray) -> np.ndarray:
        """Sum of squared residuals per measurement (W, M)."""
        r = self.model(z) - self.data[None]
        return np.einsum("wml,wml->wm", r, r)

    def misfit(self, z: np.ndarray) -> np.ndarray:
        """Negative profile log-likelihood (sigma_m at its maximum), up to a constant: (W,)."""
        ssr = np.maximum(self.ssr(z), 1e-300)
        return 0.5 * self.n_bins * np.sum(np.log(ssr / self.n_bins), axis=1)

    # ---- the fit space (z, noise level profiled out; see .fit) ----------------------
    def fit_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.layout.z_bounds()

    def fit_objective(self, v: np.ndarray) -> np.ndarray:
        return self.misfit(v)

    def canonical_fit(self, v: np.ndarray) -> np.ndarray:
        return self.layout.canonical(v)

    def fit_noise(self, v: np.ndarray) -> np.ndarray:
        """Maximum-likelihood noise level sigma (W, M) at fit-space points v (W, dim_z)."""
        return np.sqrt(self.ssr(np.atleast_2d(v)) / self.n_bins)

    def theta_from_fit(self, v: np.ndarray) -> np.ndarray:
        """theta (W, dim) at fit-space points v: z with each measurement's profiled noise
        level (clipped inside its prior)."""
        v = np.atleast_2d(v)
        lo, hi = self.sigma_bounds
        sigma = np.clip(self.fit_noise(v), lo * 1.01, hi * 0.99)
        return self.layout.theta_from_z(v, np.log(sigma))

    def pointwise(self, theta: np.ndarray) -> np.ndarray:
        """Per-bin log-likelihood (W, M, L) of theta (W, dim)."""
        z, ln_sigma = self.layout.split_theta(theta)
        r = self.model(z) - self.data[None]
        s = np.exp(ln_sigma)[:, :, None]
        return -0.5 * (r / s) ** 2 - np.log(s) - 0.5 * LOG_2PI

    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood (W,) of theta (W, dim), prior ignored (smooth across its bounds)."""
        z, ln_sigma = self.layout.split_theta(np.atleast_2d(theta))
        ssr = self.ssr(z)
        ll = -0.5 * ssr * np.exp(-2 * ln_sigma) - self.n_bins * ln_sigma - 0.5 * self.n_bins * LOG_2PI
        return ll.sum(axis=1)
