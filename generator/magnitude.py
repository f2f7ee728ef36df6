"""From a bin's line sums to the K-ramp magnitude average: mean and variance.

:func:`mdaug.generator.line_moments.line_sums` gives, per bin, the sums over one
ramp's lines that the moments need; :func:`magnitude_moments` turns them, with the
steady line and the noise, into the mean and variance of the average of |X| over K
ramps (a Rician matched to the exact second and fourth moments, the Fejer effective
number of looks, the MTI's per-frame line gains). :func:`carrier_line_factor` is the
share of the steady line that the drone's own carrier lines hold.
"""
from __future__ import annotations

import numpy as np

from ..radar import RadarConfig

def rice_mean(nu2, diffuse):
    """E|X| of X = nu + a circular complex Gaussian of power ``diffuse`` (E|Z|^2), with
    nu2 = |nu|^2: sqrt(pi P) / 2 L_{1/2}(-nu2 / P), through the scaled Bessel functions
    (stable for any K-factor; -> |nu| + P / (4 |nu|) for a dominant steady part)."""
    from scipy.special import i0e, i1e

    nu2 = np.asarray(nu2, float)
    p = np.maximum(np.asarray(diffuse, float), 1e-300)
    x = nu2 / p
    big = x > 1e4
    xs = np.where(big, 1.0, x)
    lag = (1.0 + xs) * i0e(0.5 * xs) + xs * i1e(0.5 * xs)
    small = 0.5 * np.sqrt(np.pi * p) * lag
    nu = np.sqrt(np.maximum(nu2, 1e-300))
    return np.where(big, nu + p / (4.0 * nu), small)


def magnitude_moments(sums: np.ndarray, nu: np.ndarray, noise_power, *, ramps: int = 1, g1: float = 1.0,
                      g2: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the K-ramp magnitude average at each bin.

    sums (..., N_SUMS) from :func:`line_sums`; nu (...) the steady line (complex, the
    engines' carrier lines and the body return); noise_power (...) the receiver
    noise's E|N|^2 per bin and ramp. One ramp's |X| is taken as a Rician matched to
    the exact second and fourth moments (the steady part carries the sidebands'
    shared phases); the K-ramp average keeps ``(sum_D F_D |S_D|^2 + noise / K) /
    (sum_D |S_D|^2 + noise)`` of one ramp's variance (the Fejer effective number of
    looks: the phases advance deterministically from ramp to ramp); the MTI gives each
    random line a power gain per frame of mean g1 and variance g2 (1 + 1/N and
    2 / N for an N-frame MTI), which no K averages away. Returns (mean, var) (...).
    """
    s = sums
    nu2 = np.abs(nu) ** 2
    pw = s[..., 3].real
    cross = 2.0 * np.real(np.conj(nu) ** 2 * s[..., 6]) + 2.0 * np.real(np.conj(nu) * s[..., 10] + nu * s[..., 8])
    cross_w = 2.0 * np.real(np.conj(nu) ** 2 * s[..., 7]) + 2.0 * np.real(np.conj(nu) * s[..., 11] + nu * s[..., 9])
    var_l = np.maximum(s[..., 12].real + 2.0 * nu2 * pw + cross, 0.0)  # Var |L|^2 over one ramp's phases
    var_lw = np.maximum(s[..., 13].real + 2.0 * nu2 * s[..., 5].real + cross_w, 0.0)
    m2_l = nu2 + pw
    sig2 = np.asarray(noise_power, float)
    m2 = m2_l + sig2
    var_n = sig2 * sig2 + 2.0 * m2_l * sig2
    m4 = m2_l * m2_l + var_l + 4.0 * m2_l * sig2 + 2.0 * sig2 * sig2
    root = np.sqrt(np.maximum(2.0 * m2 * m2 - m4, 0.0))
    diffuse = np.clip(m2 - root, 0.0, m2)
    mean = rice_mean(m2 - diffuse, diffuse)
    var1 = np.maximum(m2 - mean * mean, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(var_l + var_n > 0, (var_lw + var_n / ramps) / (var_l + var_n), 1.0 / ramps)
    var = var1 * np.clip(share, 1e-6, 1.0)
    if g2 > 0:
        var = var + (mean / (2.0 * np.maximum(m2, 1e-300))) ** 2 * (g2 / g1 ** 2) * s[..., 4].real
    return mean, var


def carrier_line_factor(x: np.ndarray, radar: RadarConfig = RadarConfig(), n_points: int = 64) -> np.ndarray:
    """kappa' of class vectors x (n, 13E): the engines' carrier lines (n = 0) relative to
    an unmodulated tone of amplitude sum(Gamma), sum_k Gamma_k mean_u prod_j J_0(K A_kj T u)
    / sum(Gamma), u over the chirp (the steady line's share that the drone itself holds)."""
    from scipy.special import j0

    from .model import vibration_terms

    x = np.atleast_2d(np.asarray(x, float))
    amp, _, _ = vibration_terms(x)  # (n, E, 4)
    u = (np.arange(n_points) + 0.5) / n_points
    beta = radar.model_k * radar.chirp_duration_s * np.abs(amp)
    env = np.prod(j0(beta[..., None] * u), axis=2).mean(axis=-1)  # (n, E)
    gam = x.reshape(len(x), -1, 13)[..., 0]
    return (gam * env).sum(axis=1) / gam.sum(axis=1)
