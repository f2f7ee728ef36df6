"""The reduced chain path's target return: the analytic return z = I - iQ of every
frame and ramp on (every or every 2nd or 4th) sample as one small product per
engine, the MTI applied before the FFT, the interpolation onto all samples, and the
target power that sets the receiver noise (steps 2 and 4 of :mod:`.path`)."""
from __future__ import annotations

from functools import lru_cache
from math import comb, factorial

import numpy as np
import scipy.fft

from ...radar import C0
from ..model import TWO_PI, vibration_terms, wrap_phase
from ..params import N_PARAMS

STEPS = (4, 2)  # coarser time samplings of the target return tried, largest first

TAPS = 8  # Lagrange interpolation points

INTERP_TOL = 3e-5  # bound on the interpolation error per sample, relative to the return's amplitude
# (a white error of 3e-5 per sample is ~4e-6 of a profile's peak after the 4096-point FFT)


def _phase_coefficients(d, sl, plan, scene, radar, base_bin):
    """Phase of every engine, frame and ramp as coef (n, E, J K, 10) @ basis (n, E, 10, S)
    (:func:`_phase_basis`, on S sample times).

    phi_e = K t d_e(t) + K R0_j t + carrier_j - 2 pi base_bin n / N, with
    d_e = sum_q A_q cos(w_q t + theta_q), theta_q = phi_jq + w_q k T_ramp; basis rows
    [K t cos(w t); -K t sin(w t); t; 1]. The common tone of ``base_bin`` (n,) is taken
    out (it only moves the spectrum by whole bins), which keeps the float32 phases small.
    Also returns amplitudes and frequencies (n, E, 4) and the per-frame linear phase
    (slope (n, J) rad/s, offset (n, J) rad).
    """
    x, ph = d.x[sl], d.phases[sl][:, plan.frames]
    slope, offset = _linear_phase(d, sl, plan, scene, radar, base_bin)
    n, j = slope.shape
    k = scene.acquisition.ramps
    amp, w, _ = vibration_terms(x)  # (n, E, 4)
    e = amp.shape[1]
    # A e^{i theta}, theta = phi_j + w k T_ramp: a product of per-frame and per-ramp rotations
    frame_rot = amp[:, :, None] * np.exp(1j * np.moveaxis(ph, 1, 2))  # (n, E, J, 4)
    ramp_rot = np.exp(1j * w[:, :, None] * (np.arange(k) * radar.ramp_period_s)[:, None])  # (n, E, K, 4)
    rot = frame_rot[:, :, :, None] * ramp_rot[:, :, None]  # (n, E, J, K, 4)
    coef = np.empty((n, e, j, k, 10), plan.rdt)
    coef[..., :4], coef[..., 4:8] = rot.real, rot.imag
    coef[..., 8], coef[..., 9] = slope[:, None, :, None], offset[:, None, :, None]
    return coef.reshape(n, e, j * k, 10), amp, w, slope, offset


def _linear_phase(d, sl, plan, scene, radar, base_bin):
    """Per-frame linear phase of the return, K R0_j t + carrier_j minus the tone of
    ``base_bin`` (n,): slope (n, J) rad/s and offset (n, J) rad (wrapped)."""
    r_all = d.range_m[sl]
    r = r_all[:, plan.frames]
    r_beat = r if scene.drift_shifts_range else np.repeat(r_all[:, -1:], len(plan.frames), axis=1)
    slope = radar.model_k * 0.5 * r_beat - TWO_PI * base_bin[:, None] * radar.sample_rate_hz / radar.fft_points
    return slope, wrap_phase(4 * np.pi * radar.centre_frequency_hz / C0 * r)


def _phase_basis(w, t, radar, dtype) -> np.ndarray:
    """Basis (n, E, 10, S) of :func:`_phase_coefficients` at times t (S,) s; w (n, E, 4) rad/s."""
    n, e = w.shape[:2]
    basis = np.empty((n, e, 10, t.size), dtype)
    wt = (w[..., None] * t).astype(dtype)  # (n, E, 4, S), < ~30 rad: float32 keeps ~2e-6 rad
    kt = (radar.model_k * t).astype(dtype)
    np.multiply(np.cos(wt), kt, out=basis[:, :, :4])
    np.multiply(np.sin(wt), -kt, out=basis[:, :, 4:8])
    basis[:, :, 8], basis[:, :, 9] = t, 1.0
    return basis


def _derivative_bound(amp, w, slope, radar, order: int) -> np.ndarray:
    """Bound (n,) on |d^L/dt^L exp(i phi_e)| over the chirp, largest over the engines:
    the complete Bell polynomial B_L(|phi'|, ..., |phi^(L)|) with |phi'| <= |slope| +
    K sum|A| + K T sum|A| w and |phi^(m)| <= K (m sum|A| w^(m-1) + T sum|A| w^m)."""
    a, w = np.abs(amp), np.abs(w)  # (n, E, 4)
    k, t_end = radar.model_k, radar.chirp_duration_s
    m = [np.abs(slope).max(axis=1)[:, None] + k * a.sum(-1) + k * t_end * (a * w).sum(-1)]
    m += [k * (i * (a * w ** (i - 1)).sum(-1) + t_end * (a * w ** i).sum(-1)) for i in range(2, order + 1)]
    bell = [np.ones_like(m[0])]
    for i in range(order):  # B_{i+1} = sum_j C(i, j) M_{j+1} B_{i-j}
        bell.append(sum(comb(i, jj) * m[jj] * bell[i - jj] for jj in range(i + 1)))
    return bell[order].max(axis=1)


@lru_cache(maxsize=16)
def _sample_grid(ns: int, step: int, taps: int):
    """Coarse sample indices (S,) (every ``step``-th sample, all of the first and last
    2 step), the sparse
    Lagrange interpolation matrix (N_s, S) float32 onto all samples (``taps`` nearest
    coarse samples each, exact on the coarse ones), its error constant: max over
    samples of |prod_k (n - n_k)| / taps! (in samples^taps), and the quadrature weights
    (S,) of a mean over all samples (column sums / N_s)."""
    from scipy.sparse import csr_matrix

    edge = min(ns, 2 * step)  # every sample near the ends: centred stencils there too
    coarse = np.unique(np.r_[np.arange(0, ns, step), np.arange(edge), np.arange(ns - edge, ns)])
    rows, cols, vals, worst = [], [], [], 0.0
    for i in range(ns):
        at = np.searchsorted(coarse, i)
        if at < len(coarse) and coarse[at] == i:
            rows.append(i), cols.append(at), vals.append(1.0)
            continue
        lo = int(np.clip(at - taps // 2, 0, len(coarse) - taps))
        idx = np.arange(lo, lo + taps)
        nodes = coarse[idx].astype(float)
        weights = [np.prod([(i - nodes[q]) / (nodes[p] - nodes[q]) for q in range(taps) if q != p])
                   for p in range(taps)]
        worst = max(worst, abs(np.prod(i - nodes)) / factorial(taps))
        rows += [i] * taps
        cols += idx.tolist()
        vals += weights
    matrix = csr_matrix((np.array(vals, np.float32), (rows, cols)), shape=(ns, len(coarse)))
    weights = np.asarray(matrix.sum(axis=0), dtype=np.float64).ravel() / ns  # mean over all samples
    return coarse, matrix, worst, weights


def choose_steps(d, plan, scene, radar) -> np.ndarray:
    """Sampling step (n,) of every row: the largest of STEPS whose interpolation error
    bound, relative to the return's amplitude, is <= INTERP_TOL; 1 (every sample) if
    none or ``plan.decimate`` is off. Per row, so blocks do not change a row's bytes."""
    n = d.x.shape[0]
    steps = np.ones(n, np.int64)
    if not plan.decimate:
        return steps
    rows = slice(0, n)
    amp, w, _ = vibration_terms(d.x)
    base = np.rint(d.range_m[:, -1] / radar.bin_m).astype(np.int64)
    bound = 2 * _derivative_bound(amp, w, _linear_phase(d, rows, plan, scene, radar, base)[0], radar, TAPS)
    for step in sorted(STEPS):  # 2: real and imaginary parts
        worst = _sample_grid(radar.samples_per_chirp, step, TAPS)[2]
        steps[bound * worst / radar.sample_rate_hz ** TAPS <= INTERP_TOL] = step
    return steps


def _target_terms(d, sl, plan, scene, radar, base_bin, step, work):
    """Analytic target return z = I - iQ = sum_e Gamma_e exp(i phi_e) of frames ``plan.frames``
    (shifted down by ``base_bin`` bins) on S sample times: zr, zi (n, J, K S) real and
    imaginary parts, the body return (n, J, S) complex (None without one), and the
    sampling step (1: all N_s samples; else every step-th and the last, to interpolate)."""
    coef, _, w, slope, offset = _phase_coefficients(d, sl, plan, scene, radar, base_bin)
    idx = _sample_grid(radar.samples_per_chirp, step, TAPS)[0] if step > 1 else np.arange(radar.samples_per_chirp)
    t = idx / radar.sample_rate_hz
    basis = _phase_basis(w, t, radar, plan.rdt)
    n, e, jk, _ = coef.shape
    shape = (n, e, jk, t.size)
    cos, sin = work.buf("cos", shape, plan.rdt), work.buf("sin", shape, plan.rdt)
    phase = work.buf("phase", shape[:1] + shape[2:], plan.rdt)
    for i in range(e):  # per engine: J K S phase samples
        np.matmul(coef[:, i], basis[:, i], out=phase)  # rad
        np.cos(phase, out=cos[:, i])
        np.sin(phase, out=sin[:, i])
    gamma = d.x[sl].reshape(n, e, N_PARAMS)[..., :1].astype(plan.rdt).transpose(0, 2, 1)  # (n, 1, E)
    zr = np.matmul(gamma, cos.reshape(n, e, -1), out=work.buf("zr", (n, 1, jk * t.size), plan.rdt))
    zi = np.matmul(gamma, sin.reshape(n, e, -1), out=work.buf("zi", (n, 1, jk * t.size), plan.rdt))
    body = None
    if np.any(d.body_gamma[sl] > 0):
        bphase = (slope[..., None] * t + wrap_phase(offset + d.body_phase[sl][:, None])[..., None]).astype(plan.rdt)
        body = np.empty(bphase.shape, plan.cdt)  # (n, J, S): g e^{i bphase}
        g = d.body_gamma[sl][:, None, None].astype(plan.rdt)
        body.real, body.imag = g * np.cos(bphase), g * np.sin(bphase)
    j = len(plan.frames)
    return zr.reshape(n, j, -1), zi.reshape(n, j, -1), body, step


def _target_power(zr, zi, body, n_ramps: int, weights: np.ndarray) -> np.ndarray:
    """Mean power per IF sample (n,) of the antennas' signals Re(y e^{i psi_n}), y = z + body,
    over all frames, ramps, antennas and samples: mean |y|^2 / 2 (the term Re(y^2) at twice
    the beat frequency, ~1e-3 of it, is neglected). zr, zi (n, J, K S), body (n, J, S) on
    the S sample times; weights (S,) their share of the mean over all samples (sum 1)."""
    n, j = zr.shape[:2]
    ns = weights.size
    wts = weights.astype(zr.dtype)
    sq = np.square(zr).reshape(n, -1, ns) + np.square(zi).reshape(n, -1, ns)  # (n, J K, S)
    total = np.matmul(sq, wts).sum(axis=1, dtype=np.float64)
    if body is not None:  # cross terms Re(z conj(body)) and |body|^2, per frame
        bw = body * wts
        zsum_r = zr.reshape(n, j, n_ramps, ns).sum(axis=2)
        zsum_i = zi.reshape(n, j, n_ramps, ns).sum(axis=2)
        total += 2 * np.sum(zsum_r * bw.real + zsum_i * bw.imag, axis=(1, 2), dtype=np.float64)
        total += n_ramps * np.sum(np.abs(body) ** 2 * weights, axis=(1, 2))
    return total / (2 * j * n_ramps)


def mti_spectra(d, sl, plan, scene, radar, base_bin, step, work):
    """Range spectra (n, K, N) of the MTI frame's analytic target return, shifted down by
    ``base_bin`` bins (MTI applied before the FFT, then the interpolation to all samples
    if the return was sampled coarser: both linear), and the target power (n,) or None."""
    zr, zi, body, step = _target_terms(d, sl, plan, scene, radar, base_bin, step, work)
    n, k, ns = zr.shape[0], scene.acquisition.ramps, radar.samples_per_chirp
    a = plan.weights.astype(plan.rdt)[None, None]
    u = np.empty((n, k, zr.shape[-1] // k), plan.cdt)
    u.real = np.matmul(a, zr).reshape(u.shape)
    u.imag = np.matmul(a, zi).reshape(u.shape)
    if body is not None:
        u += np.einsum("j,njs->ns", plan.weights, body).astype(plan.cdt)[:, None]
    pad = work.buf("pad", (n, k, radar.fft_points), plan.cdt)
    pad[..., ns:] = 0
    if step > 1:  # Lagrange interpolation of the K MTI'd ramps onto every sample
        matrix = _sample_grid(ns, step, TAPS)[1]
        pad[..., :ns] = (matrix @ u.reshape(n * k, -1).T).T.reshape(n, k, ns)
    else:
        pad[..., :ns] = u
    if plan.taper is not None:
        pad[..., :ns] *= plan.taper
    if scene.snr_db is None:
        return scipy.fft.fft(pad, axis=-1, overwrite_x=True), None
    weights = _sample_grid(ns, step, TAPS)[3] if step > 1 else np.full(ns, 1.0 / ns)
    power = _target_power(zr, zi, body, k, weights)
    return scipy.fft.fft(pad, axis=-1, overwrite_x=True), power
