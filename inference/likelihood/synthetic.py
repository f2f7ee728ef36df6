"""The likelihood of measured profiles under their acquisition, phases marginalised.

When a measured profile averages K ramps whose vibration phases are random from
frame to frame (and the chain's MTI leaves a random residual of earlier frames),
the phases are nuisances to marginalise, not parameters to fit. This module does it
by simulation (a Gaussian synthetic likelihood, Wood 2010; Price et al. 2018):

* for a class vector, :class:`mdaug.generator.synthetic.SyntheticDraws` renders O
  acquisitions of I ramps each through the acquisition (always the same random
  draws: common random numbers, so the likelihood is a smooth function of the
  vector), with each measurement's carrier return and noise floor;
* measurement m's profile is modelled as Gaussian with the mean mu_m of those O
  profiles and their covariance, shrunk towards its diagonal with the
  Ledoit-Wolf / Schaefer-Strimmer intensity (O is far smaller than the number of
  bins), times (1 + M / O): the simulated mean carries Monte Carlo error of about
  the covariance / O, and that error is shared by all M measurements (common
  random numbers), so for what the M measurements say together it weighs like
  M / O of one measurement's spread; a floor of ``floor`` (fraction of the peak)
  keeps the covariance regular;
* the profile is compared every ``stride``-th bin from its centre (default 8 =
  fft_points / samples_per_chirp: the zero-padded FFT oversamples the spectrum 8
  times, so neighbouring bins are strongly correlated and 8 bins apart they are
  nearly independent); model and data are both normalised to 1 at the centre bin,
  which is left out; each measurement's offset (where its centre bin sits
  relative to the carrier tone, continuous, in bins) is a parameter, so the
  likelihood has no cliffs where an argmax would jump.

Approximations (measured in tests/benchmarks/inference.py, section "likelihood"):
Gaussian per-measurement errors; the data's K-ramp averages are modelled by
I = min(K, ramps_drawn)-ramp averages (a little more spread when I < K); O and I
trade the likelihood's Monte Carlo error against its cost. Only the ``peak``
normalisation is supported.
"""
from __future__ import annotations

import numpy as np

from ...generator.acquisition import Acquisition
from ...generator.synthetic import SyntheticDraws
from ...radar import RadarConfig
from .base import LOG_2PI, MarginalLikelihood
from ..space.layout import Layout


def shrinkage_intensity(dev: np.ndarray) -> np.ndarray:
    """Ledoit-Wolf intensity towards the diagonal (Schaefer & Strimmer 2005, target D)
    of the sample covariance of deviations dev (..., O, B) (rows centred):
    sum_{i != j} Var(s_ij) / sum_{i != j} s_ij^2, computed through the O x O Gram
    matrix (no O x B x B tensor). Returns (...,) in [0, 1]."""
    o = dev.shape[-2]
    sq = dev * dev  # (..., O, B)
    row = sq.sum(axis=-1)  # ||d_k||^2
    gram = np.einsum("...kb,...lb->...kl", dev, dev)  # (..., O, O)
    wbar_f2 = (gram * gram).sum(axis=(-2, -1)) / o**2  # sum_ij wbar_ij^2, wbar = D^T D / O
    wbar_diag2 = (sq.sum(axis=-2) ** 2).sum(axis=-1) / o**2  # sum_i wbar_ii^2
    sum_w2 = (row * row).sum(axis=-1)  # sum_k sum_ij w_kij^2
    sum_w2_diag = (sq * sq).sum(axis=(-2, -1))  # sum_k sum_i w_kii^2
    num = (o / (o - 1) ** 3) * ((sum_w2 - sum_w2_diag) - o * (wbar_f2 - wbar_diag2))
    den = (o / (o - 1)) ** 2 * (wbar_f2 - wbar_diag2)
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.where(den > 0, num / den, 1.0)
    return np.clip(lam, 0.0, 1.0)


def gaussian_loglik(r: np.ndarray, dev: np.ndarray, inflate: float, floor: float) -> np.ndarray:
    """log N(r | 0, Sigma) for residuals r (..., B) with Sigma = inflate x [lam diag(S) +
    (1 - lam) S] + floor^2 I, S the sample covariance of deviations dev (..., O, B)
    and lam its shrinkage intensity; by the Woodbury identity (O x O systems)."""
    o, b = dev.shape[-2], dev.shape[-1]
    lam = shrinkage_intensity(dev)[..., None]
    s_diag = (dev * dev).sum(axis=-2) / (o - 1)  # (..., B)
    delta = inflate * lam * s_diag + floor * floor  # (..., B)
    g = dev * np.sqrt(inflate * (1.0 - lam[..., None]) / (o - 1))  # (..., O, B): Sigma = diag(delta) + g^T g
    gd = g / delta[..., None, :]
    cap = np.eye(o) + np.einsum("...ib,...jb->...ij", gd, g)  # I + G^T Delta^-1 G (G = g^T)
    chol = np.linalg.cholesky(cap)
    v = np.einsum("...ib,...b->...i", gd, r)
    sol = np.linalg.solve(chol, v[..., None])[..., 0]
    quad = np.sum(r * r / delta, axis=-1) - np.sum(sol * sol, axis=-1)
    logdet = np.sum(np.log(delta), axis=-1) + 2 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * (quad + logdet + b * LOG_2PI)


class SyntheticLikelihood(MarginalLikelihood):
    """log p(theta | data) with the acquisition's random terms marginalised (module doc).

    data: (M, L) peak-normalised measured profiles, peak at L // 2; layout: a
    marginal :class:`Layout` (per measurement: carrier return in z, noise floor in
    the tail). Vectorised over walkers: theta (W, dim) -> (W,).
    """

    noise_model = ("Gaussian synthetic likelihood: the acquisition's phases, MTI residual, carrier-return phase, "
                   "sub-bin range and yaw marginalised by simulation; carrier return and noise floor per measurement")

    def __init__(self, data: np.ndarray, layout: Layout, acquisition: Acquisition,
                 radar: RadarConfig = RadarConfig(), *, n_acquisitions: int = 16, ramps_drawn: int = 8,
                 stride: int = 8, seed=0, dtype: str = "float32", floor: float = 1e-3, batch: int = 16):
        self._take_data(data, layout, acquisition, radar, stride)
        self.floor, self.batch, self.seed = float(floor), int(batch), seed
        self.draws = SyntheticDraws(acquisition, layout.E, radar, n_acquisitions=n_acquisitions,
                                    ramps_drawn=ramps_drawn, seed=seed, dtype=dtype)
        offsets = self.draws.window_offsets(self.stride)
        self._keep = offsets != 0
        self.offsets = offsets[self._keep]
        self.y = self.data[:, radar.slice_length // 2 + self.offsets]  # (M, B)
        self.inflate = 1.0 + layout.M / self.draws.O

    def settings(self) -> dict:
        return {"likelihood": "synthetic (phases marginalised)", "acquisition": self.acquisition.to_dict(),
                "n_acquisitions": self.draws.O, "ramps_drawn": self.draws.I, "stride": self.stride,
                "floor": self.floor, "inflate": self.inflate, "bins_compared": int(self.n_bins)}

    def _profiles(self, theta: np.ndarray, stride: int | None = None) -> np.ndarray:
        """Per-acquisition profiles (W, M, O, B) at theta (W, dim)."""
        z, noise_db = self.layout.split_theta(theta)
        x = self.layout.shared_physics(z)
        _, offset = self.layout.physics(z)
        carrier = self.layout.carriers(z)
        out = []
        for lo in range(0, len(x), self.batch):  # bounded memory: (batch, O, I, N_s) signals at a time
            sl = slice(lo, lo + self.batch)
            p = self.draws.profiles(x[sl], carrier[sl], noise_db[sl], offset[sl], stride=stride or self.stride)
            out.append(p if stride else p[..., self._keep])
        self.n_calls += len(x) * self.draws.O * self.draws.I
        return np.concatenate(out).astype(np.float64)

    def pointwise(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood of each measurement (W, M) at theta (W, dim)."""
        p = self._profiles(np.atleast_2d(theta))
        mu = p.mean(axis=2)  # (W, M, B)
        dev = p - mu[:, :, None]
        return gaussian_loglik(self.y[None] - mu, dev, self.inflate, self.floor)

    def coarse(self, n_acquisitions: int = 4, ramps_drawn: int = 2) -> "SyntheticLikelihood":
        """A cheaper copy (fewer simulated acquisitions and ramps) for the fit's global stage."""
        return SyntheticLikelihood(self.data, self.layout, self.acquisition, self.radar,
                                   n_acquisitions=min(n_acquisitions, self.draws.O),
                                   ramps_drawn=min(ramps_drawn, self.draws.I), stride=self.stride,
                                   seed=self.seed, dtype=self.draws.dtype.name, floor=self.floor, batch=self.batch)

    def mean_profiles(self, theta: np.ndarray) -> np.ndarray:
        """Model mean profiles (W, M, L) at every bin (for figures), peak at L // 2."""
        p = self._profiles(np.atleast_2d(theta), stride=1)
        mu = p.mean(axis=2)
        half = self.radar.slice_length // 2
        out = np.zeros(mu.shape[:2] + (self.radar.slice_length,))
        out[..., half + self.draws.window_offsets(1)] = mu
        return out
