"""The calibration's likelihood in closed form: the acquisition's phases marginalised exactly.

A measured profile is the K-ramp average of |X| at each bin, with the vibration
phases random from frame to frame and advancing by w x T_r from ramp to ramp. For a
class vector this module computes, with no simulation (so the likelihood is a
deterministic, smooth function of every parameter):

* the line spectrum of one ramp and the moments of |X| over the phases
  (:mod:`mdaug.generator.line_moments`: Jacobi-Anger with the growing modulation
  index, the exact second and fourth moments, a Rician matched to them);
* the mean and variance of the K-ramp average (the Fejer effective number of looks,
  and the MTI's per-frame line gains, which no K averages away);
* per measurement m its own nuisances: the offset of its centre bin from the
  carrier tone (bins), the steady line's amplitude s_m (x sum Gamma: the engines'
  carrier lines, the body return and the MTI residual of both add there with
  phases that no parameter of the drone holds, so their sum is one amplitude per
  frame), and the noise floor (dB); the steady line's phase relative to the
  engines' carrier-line taper is marginalised on ``n_alpha`` points.

The data are compared every ``stride`` bins from the centre (the 4096-point FFT of
504 samples oversamples 8 times, so bins 8 apart are nearly independent), as
Gaussians of the model's mean and variance. The peak normalisation is handled
explicitly: the measured profile is divided by its own centre bin, a random
quantity, so the model's profile is divided by the model's centre mean and the
centre's relative variance enters as a rank-one term common to all bins (exact
Gaussian algebra, Sherman-Morrison). ``floor`` (x the peak) is a model-error
floor added to every bin's standard deviation.

Approximations and their measured size (tests/benchmarks/inference.py, section
``closed_form``): the Rician mean is within ~0.006 of the peak of the exact mean
near the carrier; pairs of random lines are summed incoherently (``coherent=False``)
for the effective number of looks; lines weaker than ``amp_tol`` x sum(Gamma), and
sidelobes below ``reach_tol``, are left out; yaw is not modelled (it moves power
between roll and pitch by at most sin^2(yaw)).
"""
from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from ...generator import IDX, N_PARAMS, vibration_terms
from ...generator.acquisition import Acquisition, noise_sigma
from ...generator.line_moments import SUM_NAMES, line_sums
from ...generator.magnitude import magnitude_moments
from ...radar import RadarConfig
from .base import LOG_2PI, LogPosteriorBase, MarginalLikelihood
from ..space.layout import Layout

_S = {name: i for i, name in enumerate(SUM_NAMES)}


class ClosedFormLikelihood(MarginalLikelihood):
    """log p(theta | data) with the acquisition's phases marginalised in closed form.

    data: (M, L) peak-normalised measured profiles, peak at L // 2; layout: a marginal
    :class:`Layout` (per measurement: steady amplitude and offset in z, noise floor in
    dB in the tail); acquisition: how they were measured (K, MTI depth). Vectorised
    over walkers: theta (W, dim) -> (W,).
    """

    kind = "closed form (phases marginalised)"
    noise_model = ("closed form: the phases marginalised exactly (line moments), the K-ramp average and the MTI's "
                   "line gains as a Gaussian per compared bin, the peak normaliser's error as a rank-one term; "
                   "steady-line amplitude, offset and noise floor per measurement")

    def __init__(self, data: np.ndarray, layout: Layout, acquisition: Acquisition,
                 radar: RadarConfig = RadarConfig(), *, stride: int = 8, floor: float = 0.0, n_alpha: int = 8,
                 amp_tol: float = 1e-3, pair_tol: float = 0.05, reach_tol: float = 3e-4, coherent: bool = False):
        self._take_data(data, layout, acquisition, radar, stride)
        if int(n_alpha) < 1:
            raise ValueError(f"n_alpha must be >= 1, got {n_alpha}")
        self.floor, self.n_alpha = float(floor), int(n_alpha)
        self.tol = dict(amp_tol=float(amp_tol), pair_tol=float(pair_tol), reach_tol=float(reach_tol),
                        coherent=bool(coherent))
        half = radar.slice_length // 2
        self.offsets = np.arange(-(half // self.stride) * self.stride, half, self.stride)
        self._centre = int(np.flatnonzero(self.offsets == 0)[0])
        self._keep = self.offsets != 0
        self.y = self.data[:, half + self.offsets[self._keep]]  # (M, B)
        self.carrier_bin = float(radar.model_range_to_bin(radar.model_range_m))
        self.centre_bin = float(round(self.carrier_bin))
        n = acquisition.mti_depth
        self.g1, self.g2 = (1.0 + 1.0 / n, 2.0 / n) if n else (1.0, 0.0)
        alpha = 2 * np.pi * np.arange(self.n_alpha) / self.n_alpha
        self._rot = np.exp(1j * alpha)  # (Q,)
        # the fit searches role space (a box where every point is a valid drone) and the
        # sampler line space; with a role-space layout both are the same
        self._role = layout.role_layout() if not layout.labelled else None

    def settings(self) -> dict:
        return {"likelihood": self.kind, "acquisition": self.acquisition.to_dict(), "stride": self.stride,
                "floor": self.floor, "n_alpha": self.n_alpha, **self.tol, "bins_compared": int(self.n_bins)}

    # ---- the model --------------------------------------------------------------------------
    def _sums(self, z: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Line sums (W, M, B, N_SUMS) at the given bin offsets and sum(Gamma) (W,)."""
        x = self.layout.shared_physics(z)
        _, off = self.layout.physics(z)
        w_n = len(x)
        amp, freq, _ = vibration_terms(x)
        gam = x.reshape(w_n, self.layout.E, N_PARAMS)[..., IDX["Gamma"]]
        sums = line_sums(gam, amp, freq, np.full(w_n, self.carrier_bin), self.centre_bin + off, offsets,
                         ramps=self.acquisition.ramps, g1=self.g1, radar=self.radar, **self.tol)
        self.n_calls += w_n
        return sums, gam.sum(axis=1)

    def moments(self, theta: np.ndarray, offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance (W, M, Q, B) of the K-ramp magnitude average at each
        measurement's bins (unnormalised), for each of the Q steady-line phases."""
        theta = np.atleast_2d(theta)
        z, noise_db = self.layout.split_theta(theta)
        offsets = self.offsets if offsets is None else np.asarray(offsets)
        sums, gsum = self._sums(z, offsets)
        steady = self.layout.carriers(z)  # (W, M) x sum Gamma
        s = sums[:, :, None]  # (W, M, 1, B, N)
        rot = self._rot[None, None, :, None]
        nu = steady[:, :, None, None] * (rot * s[..., _S["Tp"]] + np.conj(rot) * s[..., _S["Tm"]]) + s[..., _S["Dl"]]
        sigma = noise_sigma(noise_db, gsum[:, None], self.radar)  # (W, M) per IF sample
        noise_power = (self.radar.samples_per_chirp * sigma ** 2)[:, :, None, None]
        return magnitude_moments(s, nu, noise_power, ramps=self.acquisition.ramps, g1=self.g1, g2=self.g2)

    def _loglik(self, theta: np.ndarray) -> np.ndarray:
        """(W, M, Q): log-likelihood of each measurement for each steady-line phase."""
        mean, var = self.moments(theta)
        mc, vc = mean[..., self._centre], var[..., self._centre]
        mu = mean[..., self._keep] / mc[..., None]
        d = var[..., self._keep] / (mc * mc)[..., None] + self.floor ** 2
        u = mu * (np.sqrt(vc) / mc)[..., None]  # rank one: the normaliser's relative error
        r = self.y[None, :, None, :] - mu
        rd, ud = r / d, u / d
        a = 1.0 + np.sum(u * ud, axis=-1)
        quad = np.sum(r * rd, axis=-1) - np.sum(r * ud, axis=-1) ** 2 / a
        logdet = np.sum(np.log(d), axis=-1) + np.log(a)
        return -0.5 * (quad + logdet + self.n_bins * LOG_2PI)

    def pointwise(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood of each measurement (W, M) at theta (W, dim)."""
        ll = self._loglik(np.atleast_2d(theta))
        return logsumexp(ll, axis=-1) - np.log(self.n_alpha)

    def mean_profiles(self, theta: np.ndarray) -> np.ndarray:
        """Model mean profiles (W, M, L) at every bin (for figures), normalised at L // 2,
        averaged over the steady line's phase."""
        half = self.radar.slice_length // 2
        offsets = np.arange(-half, half)
        mean, _ = self.moments(np.atleast_2d(theta), offsets)
        prof = mean / mean[..., half][..., None]
        return prof.mean(axis=2)

    def zscores(self, theta: np.ndarray) -> np.ndarray:
        """Per-bin z-scores (W, M, B) of the data at theta, at each measurement's most
        likely steady-line phase (marginal variance of each bin, normaliser included)."""
        theta = np.atleast_2d(theta)
        mean, var = self.moments(theta)
        ll = self._loglik(theta)
        best = np.argmax(ll, axis=-1)[..., None, None]
        mean = np.take_along_axis(mean, best, axis=2)[:, :, 0]
        var = np.take_along_axis(var, best, axis=2)[:, :, 0]
        mc, vc = mean[..., self._centre], var[..., self._centre]
        mu = mean[..., self._keep] / mc[..., None]
        total = var[..., self._keep] / (mc * mc)[..., None] + self.floor ** 2 + mu * mu * (vc / (mc * mc))[..., None]
        return (self.y[None] - mu) / np.sqrt(total)

    # ---- the fit space: role space (a box that the fit can search) ---------------------------
    def _lines(self, v: np.ndarray) -> np.ndarray:
        v = np.atleast_2d(v)
        z = self.layout.from_roles(v[:, : self.layout.dim_z], self._role)
        return np.concatenate([z, v[:, self.layout.dim_z:]], axis=1)

    def fit_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return (self._role or self.layout).theta_bounds()

    def canonical_fit(self, v: np.ndarray) -> np.ndarray:
        if self._role is None:
            return super().canonical_fit(v)
        v = np.atleast_2d(v)
        return np.concatenate([self._role.canonical(v[:, : self.layout.dim_z]), v[:, self.layout.dim_z:]], axis=1)

    def fit_objective(self, v: np.ndarray) -> np.ndarray:
        """Negative log-likelihood at role-space points (their mirror image meeting the
        role ordering), +inf outside the line-space prior."""
        if self._role is None:
            return super().fit_objective(v)
        return LogPosteriorBase.fit_objective(self, self._lines(self.canonical_fit(v)))

    def theta_from_fit(self, v: np.ndarray) -> np.ndarray:
        return self._lines(v) if self._role is not None else super().theta_from_fit(v)

    def fit_start(self, x: np.ndarray) -> np.ndarray:
        if self._role is None:
            return super().fit_start(x)
        start = self._role.z_from_physics(x)
        start = self._role.theta_from_z(start[None], np.full((1, self.layout.M), np.mean(self.layout.tail_bounds)))
        return self.canonical_fit(start)[0]
