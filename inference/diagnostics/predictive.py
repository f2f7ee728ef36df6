"""The posterior predictive check: do drones of the posterior make profiles like the measured ones?

SBC judges a route on simulated drones; it cannot see measurements that the simulator
does not make (another radar, another scene, a drone unlike the class). This check looks
at the measurements themselves. ``n_draws`` posterior draws are each measured as many
times as the data were (:func:`mdaug.inference.amortized.simulate.measure`: the scene
simulator, the chain, peak normalisation, under the estimator's acquisition and radar),
and a few statistics of the folded log-profile (:func:`mdaug.inference.emulator.summary.folded_log_profile`,
the summary the likelihood compares) are computed on each replicate set and on the data:

* **bands**: the mean over the measurements of the folded log-profile's mean in bands of
  offsets from the peak, BANDS (1-2, 3-10, 11-30, 31-80 and 81-199 bins: the carrier's
  lobe, the first lines' sidebands, the far lines', the floor);
* **spreads** (M >= 2): the cube root of the variance over the measurements of each band's
  mean (what the acquisition's nuisances do from one measurement to the next; the cube root
  makes a variance of few measurements nearly Gaussian, Wilson and Hilferty's transform,
  where its log has a left tail 6 times too heavy for the limit below at M = 5);
* **lines**: the mean at each of the brightest engine's four lines (the posterior's
  label-free medians, ``lines`` in rad/s), over offsets within half a resolution cell of
  where the line's first sideband sits (w / (2 pi bin_hz) bins), where that lies inside
  the profile.

Each statistic's replicates give its predictive mean and sd; z = (data - mean) / sd and
the share of replicates below the data (its predictive quantile). The data are **unlike
the posterior's drones** (``misfit``) when some |z| exceeds z_limit(d) for the d
statistics checked: the two-sided Gaussian limit of family-wise level ALPHA (Bonferroni),
3.4 for 14 statistics. A posterior predictive check reuses the data that made the
posterior, so under a correct model it flags less often than ALPHA
(``tests/benchmarks/predictive_check.py`` measures how often on simulated drones, and how
often on drones of a scene the estimator was not trained on).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from ...radar.seeds import rng as seeded_rng
from ..emulator.summary import folded_log_profile
from ..result.status import FITS, MISFIT

BANDS = ((1, 2), (3, 10), (11, 30), (31, 80), (81, 199))
"""Bands of offsets from the peak (bins, inclusive) of the band statistics."""
ALPHA = 0.01
"""Family-wise level of the check: the chance a correct model's data are flagged, at most where the
statistics are Gaussian (docs/calibration.md measures it on simulated drones)."""
N_DRAWS = 200
"""Posterior draws measured for the check by default."""
MIN_DRAWS = 20
"""Fewest draws the check measures (a predictive sd from fewer is too noisy to judge by)."""


def z_limit(n_statistics: int, alpha: float = ALPHA) -> float:
    """|z| above which one of n statistics is flagged: two-sided, Bonferroni at ``alpha``."""
    from scipy.stats import norm

    if n_statistics < 1:
        raise ValueError(f"need >= 1 statistic, got {n_statistics}")
    return float(norm.isf(alpha / (2 * n_statistics)))


def statistics(profiles: np.ndarray, radar: RadarConfig, lines=None) -> tuple[list[str], np.ndarray]:
    """(names, values (..., d)) of measurement sets ``profiles`` (..., M, L), peak-normalised,
    peak at L // 2, M >= 2 for the spreads (module doc). lines: the brightest engine's
    lines in rad/s (the line statistics), or None."""
    p = np.asarray(profiles, float)
    if p.ndim < 2:
        raise ValueError(f"need profiles of shape (..., measurements, bins), got {p.shape}")
    n_off = min(p.shape[-1] // 2, p.shape[-1] - 1 - p.shape[-1] // 2)
    f = folded_log_profile(p, n_off)  # (..., M, n_off); offset k at index k - 1
    names, cols = [], []
    band = []
    for lo, hi in BANDS:
        hi = min(hi, n_off)
        if lo <= hi:
            band.append((f"{lo}-{hi}", f[..., lo - 1:hi].mean(-1)))  # (..., M)
    for name, b in band:
        names.append(f"band {name} bins: mean")
        cols.append(b.mean(-1))
    if p.shape[-2] >= 2:
        for name, b in band:
            names.append(f"band {name} bins: spread")
            cols.append(np.cbrt(b.var(-1, ddof=1)))
    half = 0.5 * radar.fft_points / radar.samples_per_chirp
    for j, w in enumerate([] if lines is None else np.asarray(lines, float)):
        at = w / (2 * np.pi * radar.bin_hz)
        lo, hi = max(1, int(np.ceil(at - half))), min(n_off, int(np.floor(at + half)))
        if np.isfinite(at) and lo <= hi:
            names.append(f"line {j + 1} ({at:.0f} bins)")
            cols.append(f[..., lo - 1:hi].mean((-1, -2)))
    return names, np.stack(cols, axis=-1)


@dataclass(frozen=True)
class PredictiveCheck:
    """The check's result (module doc): per statistic its name, the data's value, the
    replicates' mean and sd, z and the data's predictive quantile; the limit and the word."""

    names: list
    observed: list
    mean: list
    sd: list
    z: list
    quantile: list
    z_limit: float
    n_draws: int
    n_measurements: int

    @property
    def flagged(self) -> list[str]:
        """The statistics beyond the limit, worst first."""
        order = np.argsort(-np.abs(self.z))
        return [self.names[i] for i in order if abs(self.z[i]) > self.z_limit]

    @property
    def word(self) -> str:
        return MISFIT if self.flagged else FITS

    @property
    def why(self) -> str:
        """The flagged statistics with their z, in one clause ('' when the data fit)."""
        z = dict(zip(self.names, self.z))
        return ", ".join(f"{n} at z = {z[n]:+.1f}" for n in self.flagged)

    def to_dict(self) -> dict:
        return {**asdict(self), "word": self.word, "flagged": self.flagged, "why": self.why}

    @classmethod
    def from_dict(cls, d: dict) -> "PredictiveCheck":
        return cls(**{k: d[k] for k in cls.__dataclass_fields__})


def predictive_check(draws: np.ndarray, data: np.ndarray, acquisition: Acquisition, radar: RadarConfig = RadarConfig(),
                     lines=None, n_draws: int = N_DRAWS, random_state=None, scene=None) -> PredictiveCheck:
    """Check measurements ``data`` (M, L) (peak-normalised, as calibrated) against
    ``n_draws`` of the posterior's class vectors ``draws`` (n, 13E), each measured M
    times under ``acquisition`` and ``radar`` (module doc). lines: the brightest engine's
    four lines in rad/s (the posterior's label-free medians), or None."""
    from ..amortized.simulate import measure

    draws = np.atleast_2d(np.asarray(draws, float))
    data = np.asarray(data, float)
    if data.ndim != 2 or len(data) < 1:
        raise ValueError(f"the predictive check needs measurements of shape (M, L), got {data.shape}")
    if int(n_draws) < MIN_DRAWS:
        raise ValueError(f"the predictive check needs >= {MIN_DRAWS} draws, got {n_draws}")
    rng = seeded_rng(random_state)
    pick = draws[rng.choice(len(draws), size=int(n_draws), replace=len(draws) < n_draws)]
    reps = measure(pick, len(data), acquisition, radar, rng, scene=scene)  # (n_draws, M, L)
    names, obs = statistics(data, radar, lines)
    _, rep = statistics(reps, radar, lines)
    mean, sd = rep.mean(0), rep.std(0, ddof=1)
    z = (obs - mean) / np.maximum(sd, 1e-12)
    quantile = (rep < obs).mean(0) + 0.5 * (rep == obs).mean(0)
    return PredictiveCheck(names=names, observed=obs.tolist(), mean=mean.tolist(), sd=sd.tolist(), z=z.tolist(),
                           quantile=quantile.tolist(), z_limit=z_limit(len(names)), n_draws=int(n_draws),
                           n_measurements=int(len(data)))


def timed_check(draws: np.ndarray, data: np.ndarray, acquisition: Acquisition, radar: RadarConfig, lines,
                n_draws: int, random_state) -> dict:
    """:func:`predictive_check` as plain data with its seconds (``seconds``): the record a
    calibration keeps under ``diagnostics['predictive']``, whichever route drew ``draws``."""
    t0 = time.perf_counter()
    out = predictive_check(draws, data, acquisition, radar, lines=lines, n_draws=n_draws,
                           random_state=random_state).to_dict()
    return {**out, "seconds": time.perf_counter() - t0}
