"""The summary the emulated likelihood compares: what a set of profiles carries about the lines.

A peak-normalised profile (L bins, peak at L // 2) is turned into its *folded
log-profile*: log10 of the profile at offsets 1..``n_offsets`` bins from the peak,
the two sides averaged (the sidebands of a vibration line sit at +-w, so folding keeps
where they are and halves the noise). A set of M measurements of one drone is
summarised by the mean of its M folded log-profiles.

:class:`Whitening` maps a folded log-profile (n_offsets,) to D components in which the
spread that the acquisition's nuisances give one drone (the pooled within-drone
covariance of simulated drones) is the identity, ordered by how much drones differ
along them (the generalised eigenproblem of the between-drone against the
within-drone covariance, as in a discriminant analysis). The emulator predicts these
components; the likelihood compares them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FLOOR = 1e-6
"""Profiles are floored here (x the peak) before the log10."""


def folded_log_profile(profiles: np.ndarray, n_offsets: int = 128) -> np.ndarray:
    """Folded log-profiles (..., n_offsets) of peak-normalised profiles (..., L), peak at L // 2."""
    p = np.asarray(profiles, dtype=np.float64)
    L = p.shape[-1]
    c = L // 2
    if not 1 <= n_offsets <= min(c, L - 1 - c):
        raise ValueError(f"n_offsets must be in 1..{min(c, L - 1 - c)} for profiles of {L} bins, got {n_offsets}")
    lg = np.log10(np.maximum(p, FLOOR))
    k = np.arange(1, n_offsets + 1)
    return 0.5 * (lg[..., c + k] + lg[..., c - k])


@dataclass
class Whitening:
    """Folded log-profile (F,) -> components (D,): z = basis @ (s - centre) (module doc).

    centre (F,), basis (D, F); ``between`` (D,) the between-drone variance of each
    component in units of the within-drone variance (the components' order)."""

    centre: np.ndarray
    basis: np.ndarray
    between: np.ndarray

    @classmethod
    def fit(cls, summaries: np.ndarray, n_components: int, ridge: float = 1e-6) -> "Whitening":
        """summaries (N drones, M measurements, F): the folded log-profiles of simulated drones."""
        s = np.asarray(summaries, float)
        if s.ndim != 3 or s.shape[1] < 2:
            raise ValueError(f"need summaries of shape (drones, measurements >= 2, offsets), got {s.shape}")
        n, m, f = s.shape
        if not 1 <= n_components <= f:
            raise ValueError(f"n_components must be in 1..{f}, got {n_components}")
        drone_mean = s.mean(axis=1)
        dev = (s - drone_mean[:, None]).reshape(-1, f)
        within = dev.T @ dev / (n * (m - 1))
        within += ridge * np.trace(within) / f * np.eye(f)
        between = np.cov(drone_mean, rowvar=False)
        from scipy.linalg import eigh

        val, vec = eigh(between, within)  # vec' within vec = I
        order = np.argsort(val)[::-1][:n_components]
        return cls(centre=s.reshape(-1, f).mean(0), basis=vec[:, order].T.copy(), between=val[order])

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return (np.asarray(s, float) - self.centre) @ self.basis.T

    @property
    def n_components(self) -> int:
        return self.basis.shape[0]

    @property
    def n_offsets(self) -> int:
        return self.basis.shape[1]
