"""The stacked route: the mixture w p_smc + (1 - w) q_amortized of the file's two routes.

w is the file's stacking weight (meta field ``stacking``), chosen by the log score of
the truth on held-out drones (:mod:`mdaug.inference.diagnostics.stacking`, which also
derives the route's SBC from the two routes' runs). Here: the mixture's draws and its
density, the one definition a calibration and a route table share.
"""
from __future__ import annotations

import numpy as np


def mix_draws(draws_a: np.ndarray, draws_b: np.ndarray, weight: float, n: int, rng) -> tuple[np.ndarray, float]:
    """n i.i.d. draws (n, D) of the mixture ``weight`` a + (1 - weight) b, given draws of a
    (N_a, D) and of b (N_b, D): each draw's component by a Bernoulli(weight), then a draw
    of that component picked uniformly (with replacement). Returns (draws, the share from a)."""
    a, b = np.asarray(draws_a), np.asarray(draws_b)
    if not 0.0 < weight < 1.0:
        raise ValueError(f"weight must be in (0, 1), got {weight!r}")
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or not len(a) or not len(b):
        raise ValueError(f"need two non-empty draw arrays of the same width, got {a.shape} and {b.shape}")
    from_a = rng.uniform(size=n) < weight
    out = np.empty((n, a.shape[1]), dtype=np.result_type(a, b))
    out[from_a] = a[rng.integers(len(a), size=int(from_a.sum()))]
    out[~from_a] = b[rng.integers(len(b), size=int((~from_a).sum()))]
    return out, float(from_a.mean()) if n else 0.0


def mixture_log_density(log_p_a: np.ndarray, log_p_b: np.ndarray, weight: float) -> np.ndarray:
    """log(weight p_a + (1 - weight) p_b), elementwise, from the two log densities."""
    with np.errstate(divide="ignore"):
        return np.logaddexp(np.log(weight) + np.asarray(log_p_a, float), np.log1p(-weight) + np.asarray(log_p_b, float))
