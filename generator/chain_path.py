"""The chain path of the augmentation renderer: class vectors -> raw acquisitions -> radar chain.

:func:`render_through_chain` turns each row of ``x`` (n, 13 E) into one simulated raw
acquisition of the scene simulator (:mod:`mdaug.generator.scene`: yaw, body return,
range and azimuth, hover drift, clutter, noise, ADC, K ramps per frame, F frames)
processed by the published chain (:func:`mdaug.radar.chain.process_cube`) into one
``radar.slice_length``-bin profile: the strongest signature of the last MTI frame,
exactly what :func:`mdaug.generator.scene.simulate_campaign` keeps. The row IS the
specimen: no specimen spread is applied.

Two methods on the same draws (:func:`mdaug.generator.scene.draw_acquisitions`):

* ``"literal"``: render the raw cube (F, K, A, N_s) and run the whole chain.
* ``"reduced"``: compute only what the MTI and the angle integration keep. Notation:
  z_jk(t) = I - iQ = sum_e Gamma_e exp(i phi_jke(t)) (+ body) is the analytic target
  return of frame j, ramp k (the scene's I and Q are its real part and minus its
  imaginary part); antenna n sees Re(z e^{i psi_n}), psi_n = pi n sin(azimuth).

  1. Static clutter is dropped: it is identical in every frame and the MTI cancels it
     exactly (to float32 rounding, ~1e-7 of itself).
  2. Everything up to the magnitude is linear, so the MTI is applied to z before any
     FFT: z_k = z_{F-1,k} - mean of the mti_depth frames before. The phase of all
     frames and ramps is one small product per engine, coef (F K, 10) @ basis (10, S)
     (ramp k only advances the term phases by w k T_ramp; the tone of the true range
     bin is taken out, a whole-bin shift). Where a bound on the return's 8th derivative
     (Bell polynomial of the phase derivatives) keeps 8-point Lagrange interpolation
     within 3e-5 of its amplitude per sample, z is computed on every 4th (or 2nd)
     sample only and the K MTI'd ramps are interpolated (``interpolate=False``: every
     sample; measured difference ~1e-7 of the peak either way). One complex FFT per
     ramp, not one per frame and antenna.
  3. The rfft of antenna n is (Z(b) e^{i psi_n} + conj Z(-b) e^{-i psi_n}) / 2, so the
     range-angle image at angle bin m is (Z(b) G+(m) + conj Z(-b) G-(m)) / 2, G+-
     the angle FFT of the steering vectors e^{+-i psi_n}: exact, mirror term included.
     The image is formed only where the chain looks: the detection over the search
     window around the true range (``search_bins``), on the angle bins nearest the
     azimuth; theta_hat from all angle bins at the peak +- 2 bins; the profile on the
     +-3.5 deg angle bins over the 400-bin window.
  4. Receiver noise after the MTI is white, variance sum(a_j^2) sigma^2 per sample
     (a_j the MTI weights: 1 + 1/mti_depth), sigma^2 from the target power as in the
     scene (its small term at twice the beat frequency, ~1e-4, neglected). It is drawn
     directly as range spectra per antenna on the block's bins: circular complex
     Gaussian (Box-Muller) with the exact covariance of a zero-padded N_s-sample FFT (a
     Toeplitz matrix, factored once; rank ~ the block's share of the spectrum times
     N_s, plus a few; real up to a phase ramp without a range window), beamformed to
     the angle bins needed. Same distribution as the literal chain, not the same draws;
     the real signal's pseudo-covariance (<~1% correlation between bins b and -b in the
     windows used) is neglected.

  Approximations of the reduced path (measured in tests/test_chain_path.py and
  tests/benchmarks/radar.py):

  * the target is assumed to be the chain's strongest peak, and that peak to lie
    within ``search_bins`` of the true range bin (the literal chain searches all
    bins; on default scenes it picks the target: see ``ChainProfiles.on_target``); a
    peak on the window's edge gives a RuntimeWarning;
  * ``scene.quantise``: the 12-bit ADC's rounding is not simulated (the rounding of
    the clutter does not cancel in the MTI: a white floor ~1/sqrt(12) code per
    sample); reduced profiles are in the unquantised cube's units (the literal ones
    in ADC codes: compare after peak normalisation);
  * ``chain.edge`` must be ``"keep"``. The chain's detection thresholds do not change
    which signature is kept: the strongest peak is always significant, or taken anyway.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from math import comb, factorial

import numpy as np
import scipy.fft

from ..radar.seeds import rng as as_generator
from ..radar.seeds import seed_sequence
from ..radar import C0, RadarConfig
from ..radar.chain import ChainConfig, angle_fft, angle_grid_deg
from .model import TWO_PI, wrap_phase, vibration_terms
from .params import N_PARAMS, validate_vectors
from .scene import SceneConfig, draw_acquisitions, literal_chain, true_vectors

METHODS = ("literal", "reduced")
SEARCH_BINS = 64  # detection window: true range bin +- this many bins
WORK_ELEMENTS = 1 << 19  # phase samples per reduced chunk: a few MB of scratch, reused
NOISE_TOL = 1e-8  # noise basis: largest relative variance left out per bin
STEPS = (4, 2)  # coarser time samplings of the target return tried, largest first
TAPS = 8  # Lagrange interpolation points
INTERP_TOL = 3e-5  # bound on the interpolation error per sample, relative to the return's amplitude
# (a white error of 3e-5 per sample is ~4e-6 of a profile's peak after the 4096-point FFT)


@dataclass
class ChainProfiles:
    """What :func:`render_through_chain` returns for n acquisitions.

    profiles (n, L) float32 linear magnitude: the strongest signature of the last MTI
    frame (window centre at index L // 2, zero-filled past the spectrum's ends);
    true_params (n, 13 E) the vectors of the MTI frame's first ramp (yaw-mixed
    amplitudes, that frame's phases); range_true_m (n,) physical (= chain) range at
    the MTI frame, m; range_m (n,) the chain's range of the window centre, m;
    peak_bin (n,) that centre bin; direction_deg (n,) theta_hat, deg; azimuth_deg,
    yaw_deg (n,) the true direction and yaw, deg; n_missing (n,) zero-filled bins;
    method; settings (JSON-able).
    """

    profiles: np.ndarray
    true_params: np.ndarray
    range_true_m: np.ndarray
    range_m: np.ndarray
    peak_bin: np.ndarray
    direction_deg: np.ndarray
    azimuth_deg: np.ndarray
    yaw_deg: np.ndarray
    n_missing: np.ndarray
    method: str
    settings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.profiles)

    @property
    def on_target(self) -> np.ndarray:
        """(n,) bool: the profile's centre lies within 5 range bins of the true target."""
        bin_m = RadarConfig.from_dict(self.settings["radar"]).bin_m
        return np.abs(self.range_m - self.range_true_m) <= 5 * bin_m


# ---- inputs and randomness ----------------------------------------------------------
def _check_inputs(x, scene, chain, method, search_bins) -> np.ndarray:
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if not isinstance(scene, SceneConfig):
        raise ValueError(f"scene must be a SceneConfig, got {type(scene).__name__}")
    if method == "reduced" and chain.edge != "keep":
        raise ValueError(f"chain.edge must be 'keep' for method='reduced', got {chain.edge!r}")
    if isinstance(search_bins, bool) or int(search_bins) != search_bins or search_bins < 3:
        raise ValueError(f"search_bins must be an integer >= 3, got {search_bins!r}")
    arr = validate_vectors(x, what="x (class vectors, one acquisition per row)", physical=False)
    if arr.shape[0] == 0:
        raise ValueError("x (class vectors, one acquisition per row) has no rows")
    return arr


def render_through_chain(x, scene: SceneConfig = SceneConfig(), radar: RadarConfig = RadarConfig(),
                         chain: ChainConfig = ChainConfig(), random_state=None, method: str = "reduced", *,
                         search_bins: int = SEARCH_BINS, interpolate: bool = True,
                         chunk_size: int | None = None, progress=None) -> ChainProfiles:
    """Profiles of class vectors rendered through the scene simulator and the chain.

    x: (n, 13 E) or (13 E,) class vectors, one acquisition per row (the row is the
    specimen: no specimen spread); scene: everything an acquisition randomises
    (K = ``scene.n_ramps`` ramps, F frames, phases, yaw, range, azimuth, drift, body,
    clutter, ``snr_db``, ``quantise``); radar, chain: as for :func:`process_cube`;
    random_state: int, None, SeedSequence or Generator -> one SeedSequence whose
    children drive the scene draws and one noise stream per row, so the bytes do not
    depend on ``chunk_size`` (rows per block; default by memory); method:
    ``"reduced"`` (fast, module doc) or ``"literal"`` (raw cubes through the chain),
    both on the same draws; search_bins: the reduced path's detection window, +- FFT
    bins around the true range bin; interpolate: let the reduced path sample the
    target return every 2nd or 4th sample where a derivative bound keeps the 8-point
    interpolation error <= 3e-5 of its amplitude per sample (False: every sample);
    progress: None or a callable told how many rows each block finished (a bar).

    Returns a :class:`ChainProfiles`: profiles (n, slice_length) float32 linear
    magnitude and per-row truth and chain estimates.
    """
    x = _check_inputs(x, scene, chain, method, search_bins)
    n = x.shape[0]
    root = seed_sequence(random_state)
    ss_draw, ss_noise = root.spawn(2)
    d = draw_acquisitions(x, n, scene, radar, as_generator(ss_draw))  # row i -> acquisition i
    noise_seeds = ss_noise.spawn(n)
    if method == "literal":
        out = _literal(d, scene, radar, chain, noise_seeds, chunk_size)
        if progress is not None:
            progress(n)
    else:
        out = _reduced(d, scene, radar, chain, noise_seeds, int(search_bins), chunk_size, bool(interpolate),
                       progress)
    units = " (ADC codes)" if scene.quantise and method == "literal" else " (unquantised IF units)"
    settings = {"kind": "mdaug chain path", "method": method, "seed": root.entropy, "n": n,
                "scene": scene.to_dict(), "radar": radar.to_dict(), "chain": chain.to_dict(),
                "search_bins": int(search_bins), "interpolate": bool(interpolate),
                "profiles": "linear magnitude, strongest signature of the last MTI frame" + units}
    return ChainProfiles(
        profiles=out["profiles"], true_params=true_vectors(d, scene.frames(radar) - 1),
        range_true_m=d.range_m[:, -1].copy(), range_m=radar.frequency_to_range(out["peak_bin"] * radar.bin_hz),
        peak_bin=out["peak_bin"], direction_deg=out["direction_deg"], azimuth_deg=d.azimuth_deg,
        yaw_deg=d.yaw_deg, n_missing=out["n_missing"], method=method, settings=settings)


def _literal(d, scene, radar, chain, noise_seeds, chunk_size) -> dict:
    rngs = [as_generator(ss) for ss in noise_seeds]
    rows, _ = literal_chain(d, scene, radar, chain, rngs, chunk=chunk_size)
    pick = lambda key, dt: np.array([getattr(res, key)[j] for res, j in rows], dtype=dt)  # noqa: E731
    return {"profiles": pick("signatures", np.float32), "peak_bin": pick("peak_bin", np.int64),
            "direction_deg": pick("direction_deg", np.float64), "n_missing": pick("n_missing", np.int64)}


# ---- the reduced computation ------------------------------------------------------
class _Work(dict):
    """Scratch arrays reused across the blocks of one call (a fresh page costs a page
    fault: ~1 ms per K = 32 acquisition if every large temporary were new)."""

    def buf(self, name: str, shape, dtype) -> np.ndarray:
        a = self.get(name)
        if a is None or a.shape != tuple(shape) or a.dtype != np.dtype(dtype):
            a = self[name] = np.empty(shape, dtype)
        return a


@dataclass(frozen=True)
class _Plan:
    """What every block of one call shares: frames rendered (J,) and their MTI weights
    (J,); the block's rows, ``rel`` (rows,) FFT bins relative to the true range bin:
    the search window +- search plus the profile's reach on both sides; angle tables
    (:func:`_angle_tables`), the angle-from-antenna matrix steer (n_a, A) and the
    half-width ``near`` of the detection's angle bins; the noise basis transposed
    (r, rows) and the conjugate of its phase ramp (rows,) (:func:`_noise_basis`), or
    None; the range window (N_s,) or None; whether the target may be sampled coarser
    and interpolated (:func:`_choose_step`); real and complex dtypes."""

    frames: np.ndarray
    weights: np.ndarray
    search: int
    reach: int
    rel: np.ndarray
    angles: tuple
    steer: np.ndarray
    near: int
    basis: np.ndarray | None
    deramp: np.ndarray | None
    taper: np.ndarray | None
    decimate: bool
    rdt: np.dtype
    cdt: np.dtype


def _make_plan(scene, radar, chain, search, decimate=True) -> _Plan:
    f, depth, n_ant = scene.frames(radar), radar.mti_depth, scene.antennas(radar)
    frames = np.arange(f) if scene.snr_db is not None else np.arange(f - depth - 1, f)  # all F for the noise power
    reach = radar.slice_length // 2 + 3  # profile rows: peak - reach .. peak + reach
    rel = np.arange(-(search + reach), search + reach + 1)
    angles = _angle_tables(max(chain.n_angle, n_ant), n_ant, radar.integration_width_deg)
    rdt = np.dtype(scene.dtype)
    cdt = np.result_type(rdt, np.complex64)
    basis = deramp = None
    if scene.snr_db is not None:
        basis, ramp = _noise_basis(len(rel), radar.samples_per_chirp, radar.fft_points, chain.window, scene.dtype)
        basis, deramp = basis.T.copy(), np.conj(ramp).astype(cdt)
    # detection angle bins: nearest to the azimuth +- near; beyond, the array gain at the
    # target is >= ~6% lower (n_a = 64, A = 8: the 3rd-nearest bin is >= 1.5 bins away)
    near = max(1, int(np.ceil(len(angles[0]) / (8 * n_ant))))
    taper = None if chain.window is None else _taper(chain.window, radar.samples_per_chirp).astype(rdt)
    return _Plan(frames=frames, weights=_mti_weights(frames, f, depth), search=search, reach=reach, rel=rel,
                 angles=angles, steer=angles[1].T.astype(cdt), near=near, basis=basis, deramp=deramp,
                 taper=taper, decimate=decimate, rdt=rdt, cdt=cdt)


def _reduced(d, scene, radar, chain, noise_seeds, search, chunk_size, interpolate=True, progress=None) -> dict:
    n = d.x.shape[0]
    plan = _make_plan(scene, radar, chain, search, interpolate)
    if chunk_size is None:
        per_row = len(plan.frames) * scene.n_ramps * (d.x.shape[1] // N_PARAMS) * radar.samples_per_chirp
        chunk_size = int(np.clip(WORK_ELEMENTS // per_row, 1, 16))
    out = {"profiles": np.empty((n, radar.slice_length), np.float32), "peak_bin": np.empty(n, np.int64),
           "direction_deg": np.empty(n), "n_missing": np.empty(n, np.int64)}
    work, edge = _Work(), np.zeros(n, bool)
    steps = _choose_steps(d, plan, scene, radar)
    for step in np.unique(steps):  # rows of one sampling step together
        rows = np.flatnonzero(steps == step)
        for lo in range(0, len(rows), int(chunk_size)):
            sl = rows[lo: lo + int(chunk_size)]
            seeds = [noise_seeds[i] for i in sl]
            for key, val in _reduced_block(d, sl, plan, scene, radar, seeds, int(step), work).items():
                (edge if key == "at_edge" else out[key])[sl] = val
            if progress is not None:
                progress(len(sl))
    if edge.any():
        warnings.warn(f"{int(edge.sum())} of {n} profile(s) peak at the edge of the reduced path's search window "
                      f"(true range bin +-{search}): the chain's strongest peak may lie outside; raise search_bins "
                      "or use method='literal'", RuntimeWarning, stacklevel=3)
    return out


def _mti_weights(frames: np.ndarray, f: int, depth: int) -> np.ndarray:
    """Weights a_j (J,) of the last MTI frame over ``frames``: 1 for frame F-1, -1/depth
    for the depth frames before, 0 for earlier ones."""
    a = np.where(frames >= f - 1 - depth, -1.0 / depth, 0.0)
    a[frames == f - 1] = 1.0
    return a


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
    k = scene.n_ramps
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


def _choose_steps(d, plan, scene, radar) -> np.ndarray:
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


def _mti_spectra(d, sl, plan, scene, radar, base_bin, step, work):
    """Range spectra (n, K, N) of the MTI frame's analytic target return, shifted down by
    ``base_bin`` bins (MTI applied before the FFT, then the interpolation to all samples
    if the return was sampled coarser: both linear), and the target power (n,) or None."""
    zr, zi, body, step = _target_terms(d, sl, plan, scene, radar, base_bin, step, work)
    n, k, ns = zr.shape[0], scene.n_ramps, radar.samples_per_chirp
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


@lru_cache(maxsize=8)
def _noise_basis(n_rows: int, ns: int, n_fft: int, window, dtype: str):
    """Factor of the covariance of the range spectrum of unit white noise on n_rows
    consecutive bins: C[b, b'] = sum_t w_t^2 exp(-2 pi i t (b - b') / N) (Toeplitz: the
    same for any first bin). Returns (basis (n_rows, r), ramp): C = D B B^H D^H with
    D = diag(ramp) (n_rows,). Without a range window the kernel is real up to the ramp
    exp(-i pi (N_s - 1) b / N) (the samples are symmetric about their centre), so B is
    real (half the work per product); with a window, B is complex and ramp is ones.
    r is the smallest rank that leaves out at most NOISE_TOL of any bin's variance."""
    from scipy.linalg import eigh, toeplitz

    taper = np.ones(ns) if window is None else _taper(window, ns)
    t = np.arange(ns) - (0.5 * (ns - 1) if window is None else 0.0)
    kernel = np.exp(-2j * np.pi * np.arange(n_rows)[:, None] * t / n_fft) @ taper ** 2  # C[b + lag, b], lag >= 0
    cov = toeplitz(kernel, np.conj(kernel))  # Hermitian (rows, rows)
    m = min(n_rows, int(n_rows * ns / n_fft) + 48)  # the spectrum's degrees of freedom, and a margin
    lam, vec = eigh(cov.real if window is None else cov, subset_by_index=[n_rows - m, n_rows - 1])
    lam, vec = np.maximum(lam[::-1], 0.0), vec[:, ::-1]
    tail = np.cumsum((np.abs(vec) ** 2 * lam)[:, ::-1], axis=1)[:, ::-1].max(axis=0)  # left out from rank i on
    ok = np.flatnonzero(tail <= NOISE_TOL * np.sum(taper ** 2))
    r = int(ok[0]) if ok.size else len(lam)
    basis = vec[:, :r] * np.sqrt(lam[:r])
    ramp = np.exp(-1j * np.pi * (ns - 1) * np.arange(n_rows) / n_fft) if window is None else np.ones(n_rows)
    rdt = np.dtype(dtype)
    return basis.astype(rdt if window is None else np.result_type(rdt, np.complex64)), ramp


def _taper(window: str, ns: int) -> np.ndarray:
    from scipy.signal import get_window

    return get_window(window, ns)


@lru_cache(maxsize=8)
def _angle_tables(n_angle: int, n_ant: int, width_deg: float):
    """Angle grid (n_a,) deg, antenna-to-angle matrix V (A, n_a) of the chain's angle FFT,
    and the integration sets of every theta_hat bin: indices (n_a, P) and weights (n_a, P)
    (the rule of :func:`mdaug.radar.chain.integrate_direction`, padded with weight 0)."""
    v = angle_fft(np.eye(n_ant, dtype=np.complex128), n_angle, axis=-2)  # row n: antenna n
    n_a = v.shape[1]
    grid = angle_grid_deg(n_a)
    sets = []
    for m in range(n_a):
        sel = np.abs(grid - grid[m]) <= 0.5 * width_deg + 1e-9
        sel[int(np.argmin(np.abs(grid - grid[m])))] = True
        sets.append(np.flatnonzero(sel))
    p = max(len(s) for s in sets)
    idx = np.array([np.pad(s, (0, p - len(s)), mode="edge") for s in sets])
    wts = np.array([np.r_[np.full(len(s), 1.0 / len(s)), np.zeros(p - len(s))] for s in sets])
    return grid, v, idx, wts


class _Noise:
    """Receiver noise after the MTI as range spectra on the block's rows: antenna a, ramp k
    sees sigma B zeta[a, k] (times the basis' phase ramp, moved onto the target instead:
    magnitudes do not change), B (rows, r) the basis, zeta (n, A, K, r) circular
    standard normal; beamformed on demand. Outputs are complex (n, M, K, B) or, for a
    real basis, real and imaginary parts (n, 2, M, K, B)."""

    def __init__(self, seeds, sigma, plan: _Plan, n_ramps: int, work: _Work):
        r, n_ant = plan.basis.shape[0], plan.steer.shape[1]
        self.work = work
        rngs = (as_generator(ss) for ss in seeds)
        self.zeta = np.stack([_complex_normal(rng, (n_ant, n_ramps, r), plan.rdt) for rng in rngs])
        self.zeta *= sigma.astype(plan.rdt)[:, None, None, None]
        self.basis_t, self.vt, self.k = plan.basis, plan.steer, n_ramps  # (r, rows), (n_a, A)

    def _basis_rows(self, rows) -> np.ndarray:
        """Basis^T columns: rows a slice (the same for all) or (start (n,), length)."""
        if isinstance(rows, slice):
            return self.basis_t[:, rows]
        start, length = rows
        r, total = self.basis_t.shape
        view = np.lib.stride_tricks.as_strided(self.basis_t, (r, total - length + 1, length),
                                               self.basis_t.strides + self.basis_t.strides[-1:], writeable=False)
        return np.moveaxis(view[:, start], 1, 0)  # (n, r, length)

    def angles_first(self, rows, angles, name: str) -> np.ndarray:
        """At block rows ``rows`` (see _basis_rows), angle bins (n, M)."""
        n, n_ant, _, r = self.zeta.shape
        m, bt = angles.shape[1], self._basis_rows(rows)
        eta = np.matmul(self.vt[angles], self.zeta.reshape(n, n_ant, -1)).reshape(n, m * self.k, r)
        if np.iscomplexobj(self.basis_t):
            out = self.work.buf(name, (n, m * self.k, bt.shape[-1]), eta.dtype)
            return np.matmul(eta, bt, out=out).reshape(n, m, self.k, -1)
        parts = self.work.buf(name + "eta", (n, 2, m * self.k, r), bt.dtype)  # one real product for both parts
        parts[:, 0], parts[:, 1] = eta.real, eta.imag
        out = self.work.buf(name, (n, 2, m * self.k, bt.shape[-1]), bt.dtype)
        np.matmul(parts, bt if bt.ndim == 2 else bt[:, None], out=out)
        return out.reshape(n, 2, m, self.k, -1)

    def antennas_first(self, start, length) -> np.ndarray:
        """At block rows start .. start + length - 1 (start (n,)), all angle bins; complex."""
        n, n_ant, _, r = self.zeta.shape
        bt = self._basis_rows((start, length)).astype(self.zeta.dtype)
        ant = np.matmul(self.zeta.reshape(n, -1, r), bt)  # (n, A K, B)
        out = np.matmul(self.vt, ant.reshape(n, n_ant, -1))  # (n, n_a, K B)
        return out.reshape(n, self.vt.shape[0], self.k, -1)


def _complex_normal(rng: np.random.Generator, shape, dtype) -> np.ndarray:
    """Circular complex standard normals (E|z|^2 = 1) by Box-Muller: sqrt(-ln u1) e^{2 pi i u2}
    (|z|^2 ~ Exp(1), uniform phase); ~3x faster than two standard_normal draws. float32
    uniforms cap |z|^2 at 16.6 (P = 6e-8 beyond)."""
    radius = np.sqrt(-np.log1p(-rng.random(shape, dtype=np.float32)))  # u1 in [0, 1): 1 - u1 > 0
    angle = np.float32(TWO_PI) * rng.random(shape, dtype=np.float32)
    z = np.empty(shape, np.result_type(dtype, np.complex64))
    z.real = radius * np.cos(angle)
    z.imag = radius * np.sin(angle)
    return z


def _ramp_mean_mag(tp, tm, gp, gm, noise, work, name) -> np.ndarray:
    """Ramp-averaged |I_MTI| (n, M, B): tp, tm (n, K, B) spectra Z(b), conj Z(-b); gp, gm
    (n, M) angle responses of e^{+-i psi} / 2; noise (n, M, K, B) complex, or its real and
    imaginary parts (n, 2, M, K, B), or None."""
    shape = (tp.shape[0], gp.shape[1]) + tp.shape[1:]
    img, tmp = work.buf(name, shape, tp.dtype), work.buf(name + "+", shape, tp.dtype)
    np.multiply(tp[:, None], gp[:, :, None, None], out=img)
    img += np.multiply(tm[:, None], gm[:, :, None, None], out=tmp)
    if noise is not None and np.iscomplexobj(noise):
        img += noise
    elif noise is not None:
        img.real += noise[:, 0]
        img.imag += noise[:, 1]
    return np.abs(img, out=work.buf(name + "|", shape, tp.real.dtype)).mean(axis=2)


def _windows(arr: np.ndarray, start: np.ndarray, length: int) -> np.ndarray:
    """(n, K, length) copy of arr[i, :, start[i]: start[i] + length] for arr (n, K, R)."""
    n, k, r = arr.shape
    view = np.lib.stride_tricks.as_strided(arr, (n, k, r - length + 1, length), arr.strides + arr.strides[-1:],
                                           writeable=False)
    return view[np.arange(n), :, start]


@dataclass
class _Block:
    """One block's image ingredients: tp, tm (n, K, rows) Z(b) and conj Z(-b) on the block's
    rows; gp, gm (n, n_a) angle responses of e^{+-i psi_n} / 2; first (n,) absolute bin
    of row 0; s (n,) sin(azimuth); noise (:class:`_Noise`) or None."""

    tp: np.ndarray
    tm: np.ndarray
    gp: np.ndarray
    gm: np.ndarray
    first: np.ndarray
    s: np.ndarray
    noise: "_Noise | None"

    def mag(self, rows, angles, work, name) -> np.ndarray:
        """Ramp-averaged |I_MTI| (n, M, B): rows a slice or (start (n,), length); angles
        (n, M) bins, or None for all (the noise then goes through the antennas first)."""
        if isinstance(rows, slice):
            tp, tm = self.tp[..., rows], self.tm[..., rows]
        else:
            tp, tm = _windows(self.tp, *rows), _windows(self.tm, *rows)
        if angles is None:
            noise = None if self.noise is None else self.noise.antennas_first(*rows)
            return _ramp_mean_mag(tp, tm, self.gp, self.gm, noise, work, name)
        ii = np.arange(len(angles))[:, None]
        noise = None if self.noise is None else self.noise.angles_first(rows, angles, "noise " + name)
        return _ramp_mean_mag(tp, tm, self.gp[ii, angles], self.gm[ii, angles], noise, work, name)


def _make_block(d, sl, plan: _Plan, scene, radar, noise_seeds, step, work) -> _Block:
    base = np.rint(d.range_m[sl][:, -1] / radar.bin_m).astype(np.int64)  # true range bin (n,)
    n, n_fft = len(base), radar.fft_points
    spec, power = _mti_spectra(d, sl, plan, scene, radar, base, step, work)
    first = base + plan.rel[0]
    mirror = (-(first[:, None] + np.arange(len(plan.rel))) - base[:, None]) % n_fft  # -b, shifted down by base
    tm = work.buf("tm", (n, spec.shape[1], len(plan.rel)), spec.dtype)
    np.conjugate(spec[np.arange(n)[:, None, None], np.arange(spec.shape[1])[:, None], mirror[:, None]], out=tm)
    s = np.sin(np.radians(d.azimuth_deg[sl]))
    steer = np.exp(1j * np.pi * np.arange(plan.steer.shape[1]) * s[:, None])  # (n, A)
    noise = None
    if power is not None:
        sigma = np.sqrt(power / 10 ** (scene.snr_db / 10) * np.sum(plan.weights ** 2))  # MTI'd noise, per sample
        noise = _Noise(noise_seeds, sigma, plan, scene.n_ramps, work)
    tp = np.take(spec, plan.rel % n_fft, axis=2, out=work.buf("tp", tm.shape, tm.dtype))
    if noise is not None:  # the noise basis' phase ramp, moved onto the target (|.| unchanged)
        tp *= plan.deramp
        tm *= plan.deramp
    return _Block(tp=tp, tm=tm, gp=(0.5 * steer @ plan.steer.T).astype(plan.cdt),
                  gm=(0.5 * steer.conj() @ plan.steer.T).astype(plan.cdt), first=first, s=s, noise=noise)


def _detect(blk: _Block, plan: _Plan, nb: int, work) -> tuple[np.ndarray, np.ndarray]:
    """Block row (n,) of the detection peak: max over the angle bins nearest the azimuth
    of the ramp-averaged |I_MTI|, argmax over the search window (never bin 0 or nb - 1);
    and whether it sits on the window's edge (n,) bool (the true maximum may lie beyond)."""
    n_a = len(plan.angles[0])
    m0 = np.rint(blk.s * n_a / 2).astype(np.int64) + n_a // 2
    near = (m0[:, None] + np.arange(-plan.near, plan.near + 1)) % n_a
    rows = slice(plan.reach, plan.reach + 2 * plan.search + 1)
    det = blk.mag(rows, near, work, "det").max(axis=1)
    bins = blk.first[:, None] + np.arange(rows.start, rows.stop)
    det[(bins < 1) | (bins > nb - 2)] = -np.inf
    at = np.argmax(det, axis=1)
    at_edge = ((at == 0) & (bins[:, 0] >= 1)) | ((at == det.shape[1] - 1) & (bins[:, -1] <= nb - 2))
    return plan.reach + at, at_edge


def _direction(blk: _Block, pk: np.ndarray, nb: int, work) -> np.ndarray:
    """theta_hat's angle bin (n,): argmax over all angle bins of |I_MTI| summed over the
    peak +- 2 bins inside the spectrum (:func:`mdaug.radar.chain.estimate_direction`)."""
    mag = blk.mag((pk - 2, 5), None, work, "dir")  # (n, n_a, 5)
    bins = (blk.first + pk)[:, None] + np.arange(-2, 3)
    return np.argmax((mag * ((bins >= 0) & (bins < nb))[:, None]).sum(axis=2), axis=1)


def _profile(blk: _Block, plan: _Plan, pk, m_hat, radar, work) -> dict:
    """Integrated profile over theta_hat +- width/2 (angle sets of the chain's rule),
    centre refined to its maximum within peak +- 3 bins, then the zero-filled window."""
    length, nb, reach = radar.slice_length, radar.n_bins, plan.reach
    half, (sel_idx, sel_w) = length // 2, plan.angles[2:]
    mag = blk.mag((pk - reach, 2 * reach + 1), sel_idx[m_hat], work, "prof")  # (n, P, rows)
    prof = np.matmul(sel_w[m_hat][:, None].astype(mag.dtype), mag)[:, 0]  # weighted mean over the set
    bins = (blk.first + pk - reach)[:, None] + np.arange(2 * reach + 1)
    inside = (bins >= 0) & (bins < nb)
    c = half + np.argmax(np.where(inside[:, half:half + 7], prof[:, half:half + 7], -np.inf), axis=1)
    ii, widx = np.arange(len(c))[:, None], c[:, None] - half + np.arange(length)
    return {"profiles": np.where(inside, prof, 0)[ii, widx].astype(np.float32), "peak_bin": bins[ii[:, 0], c],
            "n_missing": length - inside[ii, widx].sum(axis=1)}


def _reduced_block(d, sl, plan: _Plan, scene, radar, noise_seeds, step, work) -> dict:
    """Profiles and chain estimates of acquisitions ``sl`` (a slice or row indices) by the
    reduced computation, the target sampled every ``step``-th sample."""
    blk = _make_block(d, sl, plan, scene, radar, noise_seeds, step, work)
    pk, at_edge = _detect(blk, plan, radar.n_bins, work)
    m_hat = _direction(blk, pk, radar.n_bins, work)
    out = _profile(blk, plan, pk, m_hat, radar, work)
    out["direction_deg"] = plan.angles[0][m_hat].astype(np.float64)
    out["at_edge"] = at_edge
    return out
