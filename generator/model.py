"""The vibration model's IF signal and the generator f(x) (SPEC sections 1-2).

One chirp's real IF signal, t = n / fs, n = 0 .. N_s - 1::

    s(t) = sum_k Gamma_k cos(K [R0 + sum_j A_kj cos(w_kj t + phi_kj)] t),  K = 8 pi mu / c0

with w_p = C_p |w_a + w_b| and w_m = C_m |w_a - w_b|. The model is kept as published:
a model range R0 puts the tone at f = 4 mu R0 / c0, i.e. at chain range 2 R0 (see
:mod:`mdaug.radar.config`).

f(x) = |FFT_4096 s| over bins 0 .. 2047, then the 400-bin window with the strongest
bin at index 200, then the named normalisation.

Precision: the carrier phase K R0 t reaches ~1000 rad, so it is always formed in
float64 and reduced modulo 2 pi before anything is cast to float32; everything else
(vibration terms, cos, FFT) may run in float32 (``dtype="float32"``), which is
faster and stays within ~1e-5 of float64 (see tests/benchmarks/generator.py).

Input ranges (:func:`check_model_inputs`; outside them f(x) refuses with a
ValueError naming the parameter, its row and the range, instead of returning NaN
or silently inaccurate profiles):

* ``r0``: finite and > 0 (m);
* ``|Gamma| <= 1e30`` (:data:`GAMMA_MAX`): the float32 spectrum of a 504-sample
  chirp overflows (inf, then NaN bins) near 1e35;
* ``|A| <= 1 m`` (:data:`AMPLITUDE_MAX`, about 500x the references' millimetres):
  the phase excursion K A t then stays below ~330 rad, where float32 keeps it
  to ~2e-5 rad (at A = 1e300 m it overflows float32);
* ``|phi| <= 1e9 rad`` (:data:`PHASE_MAX`): phases are reduced modulo 2 pi in
  float64 before any float32 cast, which is exact to ~|phi| x 3e-16 rad; a
  float64 number near 1e16 is not even known to within 2 rad, so such a phase
  cannot be reduced meaningfully (reduce it yourself first);
* every term's frequency (w_a, w_b and the derived w_p = C_p |w_a + w_b|,
  w_m = C_m |w_a - w_b|) at most the Nyquist frequency pi fs (6.28e5 rad/s at
  200 kHz, :func:`nyquist_rad_s`): a faster vibration aliases in the sampled
  chirp and f(x) would show it at a wrong offset.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..radar import RadarConfig, centred_slices, check_normalisation, normalise
from .params import IDX, N_PARAMS, validate_vectors

TWO_PI = 2.0 * np.pi
EDGE_POLICIES = ("warn", "pad", "error")
CHUNK = 256  # rows per vectorised block
GAMMA_MAX = 1e30
AMPLITUDE_MAX = 1.0  # m
PHASE_MAX = 1e9  # rad
TERMS = ("a", "b", "p", "m")


def nyquist_rad_s(radar: RadarConfig = RadarConfig()) -> float:
    """Highest vibration frequency the sampled chirp shows without aliasing: pi fs (rad/s)."""
    return float(np.pi * radar.sample_rate_hz)


def check_r0(r0, n: int, what: str = "r0") -> np.ndarray:
    """Model ranges (n,) float64 from a scalar or (n,) array: finite and > 0 m."""
    arr = np.asarray(r0, dtype=np.float64)
    try:
        arr = np.broadcast_to(arr, (n,))
    except ValueError:
        raise ValueError(f"{what}: expected a scalar or {n} model ranges (one per vector), got shape "
                         f"{arr.shape}") from None
    bad = ~(np.isfinite(arr) & (arr > 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{what} = {float(arr[i])} (row {i}); expected a finite model range > 0 m")
    return arr


def check_model_inputs(x: np.ndarray, radar: RadarConfig = RadarConfig(), what: str = "parameter vector") -> None:
    """Refuse vectors (N, 13 E) outside the ranges f(x) computes faithfully (see the
    module doc): |Gamma| <= 1e30, |A| <= 1 m, |phi| <= 1e9 rad, every term frequency
    <= pi fs. Raises ValueError naming the parameter, its row and the range."""
    from .params import AMPLITUDES, PHASES, param_labels

    n_eng = x.shape[1] // N_PARAMS
    labels = param_labels(n_eng)
    for cols, limit, expect in (
            ((IDX["Gamma"],), GAMMA_MAX, f"expected |Gamma| <= {GAMMA_MAX:g} (float32 spectra overflow near 1e35)"),
            (AMPLITUDES, AMPLITUDE_MAX, f"expected |A| <= {AMPLITUDE_MAX:g} m (vibration amplitudes are mm; "
                                        "beyond 1 m the phase excursion K A t loses float32 precision)"),
            (PHASES, PHASE_MAX, f"expected |phi| <= {PHASE_MAX:g} rad (phases are reduced modulo 2 pi in float64; "
                                "beyond that the reduction loses more than 1e-6 rad, and near 1e16 rad a float64 "
                                "phase is not known to within 2 rad: reduce it modulo 2 pi first)")):
        idx = [k * N_PARAMS + c for k in range(n_eng) for c in cols]
        bad = np.abs(x[:, idx]) > limit
        if bad.any():
            row, j = np.argwhere(bad)[0]
            raise ValueError(f"{what}: {labels[idx[j]]} = {x[row, idx[j]]:.6g} in row {row}; {expect}")
    _, w, _ = vibration_terms(x)
    bad = ~(np.abs(w) <= nyquist_rad_s(radar))
    if bad.any():
        row, eng, term = np.argwhere(bad)[0]
        name = {"a": "w_a", "b": "w_b", "p": "w_p = C_p |w_a + w_b|", "m": "w_m = C_m |w_a - w_b|"}[TERMS[term]]
        raise ValueError(f"{what}: {name} of engine {eng} = {w[row, eng, term]:.6g} rad/s in row {row}; expected "
                         f"at most the Nyquist frequency pi fs = {nyquist_rad_s(radar):.6g} rad/s (a faster "
                         "vibration aliases in the sampled chirp)")


def wrap_phase(phase: np.ndarray) -> np.ndarray:
    """The toolkit's one phase wrap: float64 phases reduced to [-pi, pi] (error ~|phase|
    x 3e-16 rad: callers keep |phase| <= PHASE_MAX = 1e9 rad, see :func:`check_model_inputs`)."""
    return phase - TWO_PI * np.rint(phase * (1.0 / TWO_PI))


def circular_stats(phi: np.ndarray, q=(0.05, 0.95)) -> dict:
    """Circular mean, sd = sqrt(-2 ln R), mean resultant length R and a central
    interval (quantiles of the phases unwrapped around the mean) of draws (n,)."""
    c, s = np.mean(np.cos(phi)), np.mean(np.sin(phi))
    r = float(np.hypot(c, s))
    mu = float(np.arctan2(s, c))
    centred = wrap_phase(phi - mu)
    lo, hi = np.quantile(centred, q) + mu
    return {"mean": mu, "sd": float(np.sqrt(-2 * np.log(max(r, 1e-12)))), "R": r, "q05": float(lo), "q95": float(hi)}


def vibration_terms(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Amplitudes, angular frequencies and phases of the four terms of every engine.

    x: (N, 13 * E). Returns three (N, E, 4) float64 arrays, terms ordered a, b, p, m,
    with the mixing frequencies derived from w_a, w_b and the skews C_p, C_m.
    """
    e = x.reshape(x.shape[0], -1, N_PARAMS)
    wa, wb = e[..., IDX["w_a"]], e[..., IDX["w_b"]]
    amp = e[..., [IDX["A_a"], IDX["A_b"], IDX["A_p"], IDX["A_m"]]]
    w = np.stack([wa, wb, e[..., IDX["C_p"]] * np.abs(wa + wb), e[..., IDX["C_m"]] * np.abs(wa - wb)], axis=-1)
    phi = e[..., [IDX["phi_a"], IDX["phi_b"], IDX["phi_p"], IDX["phi_m"]]]
    return amp, w, phi


def if_signal(x, radar: RadarConfig = RadarConfig(), *, r0=None, phase_offsets=None,
              bracket_time=None, dtype="float64", carrier_phase=None) -> np.ndarray:
    """IF samples of a batch of parameter vectors.

    x: (N, 13 E) or (13 E,) parameter vectors (within the ranges of the module doc,
    else ValueError); r0: model range in m, scalar or (N,), finite and > 0 (default
    ``radar.model_range_m``); phase_offsets: (N, E, 4) rad added to the
    term phases (used for ramp-to-ramp advance); bracket_time: None for the model as
    published (the range bracket is multiplied by t), or a constant time in s that
    freezes it (the Jacobi-Anger case, used in tests); carrier_phase: None, or rad,
    scalar or (N,), added to every engine's carrier phase K R0 t (the scene
    simulator's hover drift, 4 pi f_c R / c0, and per-antenna phases).

    Returns (N, N_s) real samples in ``dtype``.
    """
    x = validate_vectors(x, physical=False)
    check_model_inputs(x, radar)
    n = x.shape[0]
    dt = np.dtype(dtype)
    t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
    k = radar.model_k
    r0 = check_r0(radar.model_range_m if r0 is None else r0, n)
    carrier = k * r0[:, None] * t[None, :]
    if carrier_phase is not None:
        cp = np.broadcast_to(np.asarray(carrier_phase, dtype=np.float64), (n,))
        if not np.all(np.abs(cp) <= PHASE_MAX):
            raise ValueError(f"carrier_phase: expected finite phases with |phase| <= {PHASE_MAX:g} rad, got "
                             f"{cp[~(np.abs(cp) <= PHASE_MAX)][0]!r}")
        carrier = carrier + cp[:, None]
    carrier = wrap_phase(carrier).astype(dt)  # (N, Ns), reduced in float64
    amp, w, phi = vibration_terms(x)
    if phase_offsets is not None:
        phi = phi + phase_offsets
        if not np.all(np.abs(phi) <= PHASE_MAX):
            raise ValueError(f"phase_offsets: expected finite offsets keeping |phase| <= {PHASE_MAX:g} rad")
    bracket_t = t if bracket_time is None else np.full_like(t, float(bracket_time))
    # w t + phi for every term as one (N*E*4, 2) @ (2, Ns) product: far faster than
    # a broadcast; phases wrapped first so float32 keeps its resolution.
    coef = np.stack([w.ravel(), wrap_phase(phi).ravel()], axis=1).astype(dt)
    arg = (coef @ np.stack([t, np.ones_like(t)]).astype(dt)).reshape(*w.shape, -1)
    # displacement d(t) = sum_j A_j cos(w_j t + phi_j): (N, E, Ns)
    disp = np.einsum("nej,nejs->nes", amp.astype(dt), np.cos(arg, out=arg))
    phase = carrier[:, None, :] + (k * bracket_t).astype(dt) * disp
    gamma = x.reshape(n, -1, N_PARAMS)[..., IDX["Gamma"]].astype(dt)
    return np.einsum("ne,nes->ns", gamma, np.cos(phase, out=phase))


def magnitude_spectra(signals: np.ndarray, radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """|FFT_{fft_points}| of real IF signals (N, N_s), bins 0 .. fft_points/2 - 1."""
    spec = scipy.fft.rfft(signals, n=radar.fft_points, axis=-1)[:, : radar.n_bins]
    return np.abs(spec)


@dataclass(frozen=True)
class ProfileInfo:
    """Where each profile's window sits: peak bin (N,) and zero-filled bins (N,)."""

    peak_bin: np.ndarray
    n_missing: np.ndarray


def _ramp_offsets(x: np.ndarray, ramp: int, radar: RadarConfig) -> np.ndarray | None:
    if ramp == 0:
        return None
    _, w, _ = vibration_terms(x)
    return w * (ramp * radar.ramp_period_s)


def spectra(x, radar: RadarConfig = RadarConfig(), *, r0=None, n_ramps: int = 1,
            bracket_time=None, dtype="float64") -> np.ndarray:
    """Magnitude spectra (N, fft_points/2), incoherently averaged over ``n_ramps`` ramps.

    Between consecutive ramps every vibration phase advances by w * ramp_period.
    """
    x = validate_vectors(x, physical=False)
    if int(n_ramps) < 1:
        raise ValueError(f"n_ramps must be >= 1, got {n_ramps}")
    total = None
    for ramp in range(int(n_ramps)):
        sig = if_signal(x, radar, r0=r0, phase_offsets=_ramp_offsets(x, ramp, radar),
                        bracket_time=bracket_time, dtype=dtype)
        mag = magnitude_spectra(sig, radar)
        total = mag if total is None else total + mag
    return total / n_ramps if n_ramps > 1 else total


def profiles(x, radar: RadarConfig = RadarConfig(), *, r0=None, n_ramps: int = 1,
             normalisation: str = "peak", dtype="float64", bracket_time=None,
             on_edge: str = "warn", return_info: bool = False):
    """f(x): the peak-centred ``radar.slice_length``-bin profiles of a batch.

    x: (N, 13 E) or (13 E,). Returns (N, L) in ``dtype`` (and a :class:`ProfileInfo`
    with ``return_info``). The strongest bin always sits at index L // 2; when the
    window reaches past an end of the spectrum the missing bins are zero-filled,
    never shifted, and ``on_edge`` says what else happens: ``warn`` (default),
    ``pad`` (silently) or ``error``. An all-zero spectrum gives an all-zero profile.
    """
    check_normalisation(normalisation)
    if on_edge not in EDGE_POLICIES:
        raise ValueError(f"on_edge must be one of {EDGE_POLICIES}, got {on_edge!r}")
    x = validate_vectors(x, physical=False)
    n = x.shape[0]
    r0 = check_r0(radar.model_range_m if r0 is None else r0, n)
    windows = np.empty((n, radar.slice_length), dtype=dtype)
    peak = np.empty(n, dtype=np.int64)
    n_missing = np.empty(n, dtype=np.int64)
    for lo in range(0, n, CHUNK):  # chunks keep the (N, E, 4, N_s) temporaries in cache
        sl = slice(lo, lo + CHUNK)
        mag = spectra(x[sl], radar, r0=r0[sl], n_ramps=n_ramps, bracket_time=bracket_time, dtype=dtype)
        peak[sl] = np.argmax(mag, axis=1)
        windows[sl], n_missing[sl] = centred_slices(mag, peak[sl], radar.slice_length)
        n_missing[sl][mag.max(axis=1) == 0] = 0  # an all-zero spectrum has no peak to be near an end
    if n_missing.any() and on_edge != "pad":
        msg = (f"{int(np.count_nonzero(n_missing))} of {len(peak)} profile(s) peak within "
               f"{radar.slice_length // 2} bins of the spectrum's end (peak bins "
               f"{np.unique(peak[n_missing > 0])[:5].tolist()}...); their missing bins are zero-filled")
        if on_edge == "error":
            raise ValueError(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    out = normalise(windows, normalisation).astype(dtype, copy=False)
    return (out, ProfileInfo(peak, n_missing)) if return_info else out
