"""A physics sketch of the folded profile: where a drone's lines put power, in closed form.

The network of :mod:`.net` would have to learn from scratch where the sidebands of a
line at w rad/s sit; the sketch tells it. For each engine (its Gamma relative to the
brightest, its four label-free lines w_j and amplitudes A_j) one ramp's spectrum is
the carrier and its Jacobi-Anger sidebands: line j alone at n w_j (n = 1, 2) with
weight a_n(beta_j) prod_{i != j} a_0(beta_i), and the pairs at |w_i +- w_j| with
a_1(beta_i) a_1(beta_j) prod a_0; a_n(beta) is J_n averaged over the chirp (the
modulation index K A t grows linearly over it, so beta_j = K A_j T at the chirp's end,
K = 8 pi mu / c0). Each line's power is spread by the rectangular window's lobe
sinc^2(delta / o) (o = fft_points / samples_per_chirp bins per resolution cell), both
sides folded, normalised at the peak, floored and taken as 0.5 log10 (a magnitude).

It is a sketch, not the likelihood's mean: no K-ramp statistics, no body return, no
yaw, no chain. The emulator learns what it leaves out (its held-out error is part of
the likelihood's covariance).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ...radar import RadarConfig

C0 = 299_792_458.0
_GL_T, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_T, _GL_W = 0.5 * (_GL_T + 1.0), 0.5 * _GL_W
SKETCH_FLOOR = 1e-5
"""Power floor of the sketch, x the peak's power (-50 dB)."""


def envelope_bessel_exact(beta: np.ndarray, n_max: int = 2) -> np.ndarray:
    """(..., n_max + 1): J_n(beta t) averaged over t in [0, 1], n = 0..n_max (Gauss-Legendre)."""
    from scipy.special import jv

    bt = np.asarray(beta, float)[..., None] * _GL_T  # (..., G)
    return np.stack([(jv(n, bt) * _GL_W).sum(-1) for n in range(n_max + 1)], axis=-1)


_TABLE_BETA = np.linspace(0.0, 20.0, 4001)
_TABLE = envelope_bessel_exact(_TABLE_BETA)


def envelope_bessel(beta: np.ndarray) -> np.ndarray:
    """:func:`envelope_bessel_exact` for n = 0, 1, 2 from a table (beta step 0.005,
    linear interpolation: error below 1e-5; beta beyond 20 rad is held at 20)."""
    b = np.clip(np.asarray(beta, float), 0.0, _TABLE_BETA[-1])
    pos = b / (_TABLE_BETA[1] - _TABLE_BETA[0])
    i = np.minimum(pos.astype(int), len(_TABLE_BETA) - 2)
    f = (pos - i)[..., None]
    return _TABLE[i] * (1 - f) + _TABLE[i + 1] * f


@njit(cache=True)
def _lobe_sum(k, off, amp2, cell, out):  # pragma: no cover - compiled
    """out[i, f] += 1/2 sum_l amp2[i, l] (sinc^2((k_f - off_il) / cell) + sinc^2((k_f + off_il) / cell)),
    sin(a -+ b) from the sines and cosines of a = pi k / cell and b = pi off / cell."""
    n, lines = off.shape
    a = np.pi * k / cell
    sa, ca = np.sin(a), np.cos(a)
    for i in range(n):
        for line in range(lines):
            a2 = 0.5 * amp2[i, line]
            if a2 < 1e-14:
                continue
            b = np.pi * off[i, line] / cell
            sb, cb = np.sin(b), np.cos(b)
            for f in range(k.shape[0]):
                acc = 0.0
                x = a[f] - b
                s = sa[f] * cb - ca[f] * sb
                acc += 1.0 if abs(x) < 1e-8 else s * s / (x * x)
                x = a[f] + b
                s = sa[f] * cb + ca[f] * sb
                acc += 1.0 if abs(x) < 1e-8 else s * s / (x * x)
                out[i, f] += a2 * acc


def sketch(q: np.ndarray, n_engines: int, n_offsets: int, radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """Folded log-magnitude sketch (n, n_offsets) of label-free quantities q (n, 8E + E - 1)
    (:class:`mdaug.inference.amortized.target.LabelFree` order: per engine four lines
    in rad/s, four amplitudes in m, then lnG for engines >= 1)."""
    q = np.atleast_2d(np.asarray(q, float))
    n = len(q)
    bins_per_rad = radar.fft_points / (2 * np.pi * radar.sample_rate_hz)
    cell = radar.fft_points / radar.samples_per_chirp
    t_end = radar.samples_per_chirp / radar.sample_rate_hz
    kc = 8 * np.pi * radar.slope_hz_per_s / C0
    k = np.arange(1, n_offsets + 1, dtype=float)
    power = np.zeros((n, n_offsets))
    peak = np.zeros(n)
    j = 0
    for e in range(n_engines):
        w, a = q[:, j: j + 4], q[:, j + 4: j + 8]
        j += 8
        g2 = 1.0
        if e:
            g2 = np.exp(2 * q[:, j])[:, None]
            j += 1
        env = envelope_bessel(kc * a * t_end)  # (n, 4, 3)
        a0 = env[..., 0]
        prod0 = np.prod(a0, axis=1, keepdims=True)  # (n, 1)
        safe0 = np.where(np.abs(a0) > 1e-12, a0, 1e-12)
        rest = prod0 / safe0  # prod over the other lines, (n, 4)
        offs, amps = [], []
        b = w * bins_per_rad
        for order in (1, 2):
            offs.append(order * b)
            amps.append(env[..., order] * rest)
        for i1 in range(4):
            for i2 in range(i1 + 1, 4):
                other = rest[:, i1] / safe0[:, i2]
                amp = env[:, i1, 1] * env[:, i2, 1] * other
                offs += [(b[:, i1] + b[:, i2])[:, None], np.abs(b[:, i1] - b[:, i2])[:, None]]
                amps += [amp[:, None], amp[:, None]]
        off = np.concatenate(offs, axis=1)  # (n, lines)
        amp2 = np.concatenate(amps, axis=1) ** 2
        engine = np.zeros((n, n_offsets))
        _lobe_sum(k, np.ascontiguousarray(off), np.ascontiguousarray(amp2), float(cell), engine)
        power += g2 * (engine + prod0 ** 2 * np.sinc(k / cell)[None] ** 2)
        peak += np.squeeze(g2 * (prod0 ** 2 + (amp2 * np.sinc(off / cell) ** 2).sum(1, keepdims=True)), -1) if np.ndim(g2) else (prod0[:, 0] ** 2 + (amp2 * np.sinc(off / cell) ** 2).sum(1))
    return 0.5 * np.log10(power / peak[:, None] + SKETCH_FLOOR)
