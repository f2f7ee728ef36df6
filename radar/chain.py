"""The published acquisition chain (SPEC section 4) as pure functions on arrays.

Raw acquisition ``cube``: (frames, antennas, samples) or, with K ramps per frame,
(frames, ramps, antennas, samples) of real IF samples (ADC codes or volts).

1. :func:`range_fft` per antenna, ``fft_points`` points, bins 0 .. fft_points/2 - 1;
   bin b is the beat frequency b * fs / fft_points, chain range R = c0 f / (2 mu).
2. :func:`angle_fft` across the antennas, assumed a uniform linear array at lambda/2
   spacing (the n_rx receivers, or n_rx * n_tx virtual elements if the cube holds
   them), element n seeing a target at azimuth theta with phase +pi n sin(theta).
   Zero-padded to ``n_angle`` points (default 64): angle bin k (after fftshift,
   k = -n_angle/2 .. n_angle/2 - 1) is at sin(theta_k) = 2 k / n_angle. The grid is
   uniform in sin(theta): its spacing is 2/n_angle (1.79 deg at broadside for 64,
   coarser towards +-90 deg); the array's own (Rayleigh) resolution is 2/n_ant in
   sin(theta) (14.5 deg at broadside for 8 elements).
3. :func:`mti`: I_MTI[j] = I[j] - mean(I[j - N .. j - 1]) over frames, complex, for
   every frame j >= N (N = ``radar.mti_depth``). With ramps, per ramp index; the
   magnitudes are then averaged over the ramps (incoherent, SPEC 3.1).
4. :func:`integrate_direction`: mean of |I_MTI| over theta_hat +- width/2
   (``radar.integration_width_deg`` = 7 deg, i.e. +-3.5 deg).
5. :func:`extract_signatures`: a ``slice_length``-bin window around each significant
   peak (rule in :class:`ChainConfig`).

Range FFT, angle FFT and MTI are all linear, so their order does not change the
result; :func:`process_cube` with ``order="fast"`` (default) applies the MTI to the
raw samples first and transforms only the MTI frames, ``order="image"`` does it on
the complex range-angle image literally (same numbers to rounding; tested).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import scipy.fft

from .config import RadarConfig
from .profiles import centred_slices

ORDERS = ("fast", "image")
EDGE_POLICIES = ("keep", "drop")


@dataclass(frozen=True)
class ChainConfig:
    """Settings of the chain beyond the radar's own (units in the names).

    Significant peak (of the detection profile: max over angle of |I_MTI|, ramp
    averaged): a local maximum (scipy.signal.find_peaks) that is at least
    ``rel_threshold_db`` relative to the strongest peak (default -12 dB) AND at least
    ``floor_db`` above the noise floor (the median of the detection profile; default
    12 dB), and at least ``min_separation_bins`` from any stronger peak (default
    slice_length/2 = 200 bins: a drone's micro-Doppler sidebands, within ~+-60 bins,
    are not separate targets). At most ``max_targets`` (strongest first; None = all).
    If nothing passes, the strongest bin is taken anyway (flagged by ``peak_db``).

    Near the ends: the window is never shifted; its centre bin is at index L // 2 and
    bins past either end are zero-filled (:func:`centred_slices`), reported as
    ``n_missing``; ``edge="drop"`` discards such signatures instead. Peaks at bin 0
    or the last bin are not local maxima and are never detected.
    """

    n_angle: int = 64
    window: str | None = None
    rel_threshold_db: float = -12.0
    floor_db: float = 12.0
    min_separation_bins: int | None = None
    max_targets: int | None = None
    edge: str = "keep"
    order: str = "fast"

    def __post_init__(self) -> None:
        if self.n_angle < 1:
            raise ValueError(f"ChainConfig.n_angle must be >= 1, got {self.n_angle}")
        if self.order not in ORDERS:
            raise ValueError(f"ChainConfig.order must be one of {ORDERS}, got {self.order!r}")
        if self.edge not in EDGE_POLICIES:
            raise ValueError(f"ChainConfig.edge must be one of {EDGE_POLICIES}, got {self.edge!r}")
        if self.rel_threshold_db > 0:
            raise ValueError(f"ChainConfig.rel_threshold_db must be <= 0 dB, got {self.rel_threshold_db}")
        if self.max_targets is not None and self.max_targets < 1:
            raise ValueError(f"ChainConfig.max_targets must be >= 1 or None, got {self.max_targets}")

    def separation(self, radar: RadarConfig) -> int:
        return radar.slice_length // 2 if self.min_separation_bins is None else int(self.min_separation_bins)

    def to_dict(self) -> dict:
        return asdict(self)


# ---- 1. range FFT ---------------------------------------------------------------
def range_fft(samples: np.ndarray, radar: RadarConfig = RadarConfig(), window: str | None = None) -> np.ndarray:
    """Complex range spectra of real IF samples along the last axis.

    samples: (..., N_s) real, N_s <= fft_points. Returns (..., fft_points/2) complex64
    (complex128 for float64 input); bin b sits at chain range b * ``radar.bin_m``.
    ``window``: None (rectangular, as the generator's f(x)) or a scipy window name.
    """
    x = np.asarray(samples)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float32)
    if window is not None:
        from scipy.signal import get_window

        x = x * get_window(window, x.shape[-1]).astype(x.dtype)
    return scipy.fft.rfft(x, n=radar.fft_points, axis=-1)[..., : radar.n_bins]


def range_axis_m(radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """Chain range of every kept bin, (fft_points/2,) m."""
    return radar.frequency_to_range(np.arange(radar.n_bins) * radar.bin_hz)


# ---- 2. angle FFT ---------------------------------------------------------------
def angle_grid_deg(n_angle: int = 64) -> np.ndarray:
    """Azimuths (n_angle,) in deg of the fftshifted angle bins: sin(theta_k) = 2 k / n_angle."""
    k = np.arange(n_angle) - n_angle // 2
    return np.degrees(np.arcsin(np.clip(2.0 * k / n_angle, -1.0, 1.0)))


def angle_spacing_deg(theta_deg, n_angle: int = 64) -> np.ndarray:
    """Local spacing of the angle grid at ``theta_deg`` (deg): d(theta) for d(sin) = 2/n_angle."""
    c = np.cos(np.radians(theta_deg))
    return np.degrees((2.0 / n_angle) / np.maximum(c, 1e-3))


def angle_fft(spectra: np.ndarray, n_angle: int = 64, axis: int = -2) -> np.ndarray:
    """Range-angle image from per-antenna range spectra.

    spectra: complex (..., antennas, bins) with the antennas on ``axis``. Returns
    (..., bins, n_angle) complex, angle axis last and fftshifted (angles from
    :func:`angle_grid_deg`). n_angle below the antenna count is raised to it.
    """
    x = np.moveaxis(np.asarray(spectra), axis, -1)
    a = x.shape[-1]
    n = max(int(n_angle), a)
    if n % 2 == 0:  # fftshift of the output = (-1)^m on the input: cheaper on A elements than on n
        x = x * np.where(np.arange(a) % 2, -1, 1).astype(np.float32)
        return scipy.fft.fft(x, n=n, axis=-1)
    return scipy.fft.fftshift(scipy.fft.fft(x, n=n, axis=-1), axes=-1)


# ---- 3. MTI -----------------------------------------------------------------------
def mti(frames: np.ndarray, depth: int = 10) -> np.ndarray:
    """Moving-target indication along axis 0 (frames).

    frames: (F, ...) complex (or real) images, F >= depth + 1. Returns (F - depth, ...):
    row i is frame depth + i minus the mean of the ``depth`` frames before it, in the
    input's precision (at least float32: a static return cancels to ~1e-7 of itself,
    -140 dB, far below 12-bit quantisation).
    """
    x = np.asarray(frames)
    f = x.shape[0]
    if depth < 1 or f < depth + 1:
        raise ValueError(f"MTI needs at least depth + 1 = {depth + 1} frames, got {f}")
    out = np.empty(x.shape[:0] + (f - depth,) + x.shape[1:], dtype=np.result_type(x.dtype, np.float32))
    for i in range(f - depth):  # M = F - depth outputs, usually 1: a loop beats a cumsum
        out[i] = x[depth + i] - x[i: depth + i].mean(axis=0, dtype=out.dtype)
    return out


# ---- 4. direction and integration ---------------------------------------------
def estimate_direction(magnitude: np.ndarray, peak_bin: int, angles_deg: np.ndarray, halfwidth_bins: int = 2) -> float:
    """theta_hat (deg): the angle bin of largest |I_MTI| summed over peak_bin +- halfwidth_bins.

    magnitude: (bins, n_angle) |I_MTI| (ramp averaged).
    """
    lo, hi = max(0, peak_bin - halfwidth_bins), peak_bin + halfwidth_bins + 1
    return float(angles_deg[int(np.argmax(magnitude[lo:hi].sum(axis=0)))])


def integrate_direction(magnitude: np.ndarray, angles_deg: np.ndarray, theta_hat_deg: float,
                        width_deg: float = 7.0) -> np.ndarray:
    """Range profile (bins,): mean of |I_MTI| (bins, n_angle) over |theta - theta_hat| <= width/2.

    The bin at theta_hat is always included (so a grid coarser than the width still works).
    """
    sel = np.abs(angles_deg - theta_hat_deg) <= 0.5 * width_deg + 1e-9
    sel[int(np.argmin(np.abs(angles_deg - theta_hat_deg)))] = True
    return magnitude[:, sel].mean(axis=1)


# ---- 5. signatures ----------------------------------------------------------------
def significant_peaks(detection: np.ndarray, chain: ChainConfig = ChainConfig(),
                      radar: RadarConfig = RadarConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Bins of the significant peaks of a detection profile (bins,), strongest first,
    and their height above the noise floor (median) in dB. Rule: :class:`ChainConfig`."""
    from scipy.signal import find_peaks

    p = np.asarray(detection, dtype=np.float64)
    floor = float(np.median(p))
    top = float(p.max()) if p.size else 0.0
    if top <= 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    height = max(top * 10 ** (chain.rel_threshold_db / 20), floor * 10 ** (chain.floor_db / 20))
    peaks, _ = find_peaks(p, height=height, distance=max(1, chain.separation(radar)))
    if peaks.size == 0:  # nothing significant: keep the strongest bin, flagged by its low peak_db
        peaks = np.array([int(np.argmax(p))])
    peaks = peaks[np.argsort(-p[peaks], kind="stable")]
    if chain.max_targets is not None:
        peaks = peaks[: chain.max_targets]
    with np.errstate(divide="ignore"):
        snr_db = 20 * np.log10(p[peaks] / floor) if floor > 0 else np.full(peaks.size, np.inf)
    return peaks.astype(np.int64), snr_db


def extract_signatures(profile: np.ndarray, centres, length: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """``length``-bin windows (n, length) of one profile (bins,) or of one profile per
    centre (n, bins), centre at index length // 2, zero-filled past the ends (never
    shifted); returns (windows, n_missing (n,))."""
    centres = np.atleast_1d(np.asarray(centres, dtype=np.int64))
    prof = np.asarray(profile)
    rows = np.broadcast_to(prof, (centres.size, prof.shape[-1])) if prof.ndim == 1 else prof
    return centred_slices(rows, centres, length)


@dataclass
class ChainResult:
    """What :func:`process_cube` gives for one acquisition (n signatures).

    signatures (n, L) linear magnitude; profiles (n, bins) the full integrated MTI
    range profile behind each signature; detection (M, bins) max over angle of the
    ramp-averaged |I_MTI| for each of the M = F - mti_depth MTI frames; frame (n,)
    the cube frame of each signature; peak_bin (n,); range_m (n,) chain range of the
    peak; direction_deg (n,) theta_hat; peak_db (n,) peak above the noise floor (dB);
    n_missing (n,) zero-filled bins; angles_deg (n_angle,) the angle grid.
    """

    signatures: np.ndarray
    profiles: np.ndarray
    detection: np.ndarray
    frame: np.ndarray
    peak_bin: np.ndarray
    range_m: np.ndarray
    direction_deg: np.ndarray
    peak_db: np.ndarray
    n_missing: np.ndarray
    angles_deg: np.ndarray

    def __len__(self) -> int:
        return len(self.peak_bin)


def mti_magnitude(cube: np.ndarray, radar: RadarConfig = RadarConfig(),
                  chain: ChainConfig = ChainConfig()) -> np.ndarray:
    """Ramp-averaged |I_MTI|: (M, bins, n_angle) float32 for a cube (F, [K,] A, S)."""
    x = np.asarray(cube)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float32)
    if x.ndim == 3:
        x = x[:, None]
    if x.ndim != 4:
        raise ValueError("cube must be (frames, antennas, samples) or (frames, ramps, antennas, samples), "
                         f"got shape {x.shape}")
    if chain.order == "fast":  # all three steps are linear: MTI first, transform only its frames
        img = angle_fft(range_fft(mti(x, radar.mti_depth), radar, chain.window), chain.n_angle)
    else:
        img = mti(angle_fft(range_fft(x, radar, chain.window), chain.n_angle), radar.mti_depth)
    return np.abs(img).mean(axis=1)  # (M, bins, n_angle): incoherent over ramps


def process_cube(cube: np.ndarray, radar: RadarConfig = RadarConfig(),
                 chain: ChainConfig = ChainConfig()) -> ChainResult:
    """Run the whole chain on one acquisition (frames, [ramps,] antennas, samples).

    For each MTI frame: detection profile (max over angle), significant peaks, per
    peak theta_hat and the +-width/2 integrated profile, centre refined to that
    profile's maximum within +-3 bins, then the ``slice_length`` window.
    """
    mag = mti_magnitude(cube, radar, chain)
    angles = angle_grid_deg(mag.shape[-1])
    detection = mag.max(axis=-1)
    out = {k: [] for k in ("signatures", "profiles", "frame", "peak_bin", "direction_deg", "peak_db", "n_missing")}
    for m in range(mag.shape[0]):
        peaks, snr_db = significant_peaks(detection[m], chain, radar)
        for pk, db in zip(peaks, snr_db):
            theta = estimate_direction(mag[m], int(pk), angles)
            prof = integrate_direction(mag[m], angles, theta, radar.integration_width_deg)
            lo = max(0, pk - 3)
            centre = lo + int(np.argmax(prof[lo: pk + 4]))
            sig, miss = centred_slices(prof[None], np.array([centre]), radar.slice_length)
            if miss[0] and chain.edge == "drop":
                continue
            for key, val in (("signatures", sig[0]), ("profiles", prof), ("frame", m + radar.mti_depth),
                             ("peak_bin", centre), ("direction_deg", theta), ("peak_db", db), ("n_missing", miss[0])):
                out[key].append(val)
    n_bins, length = mag.shape[1], radar.slice_length
    peak_bin = np.array(out["peak_bin"], dtype=np.int64)
    return ChainResult(
        signatures=np.array(out["signatures"], dtype=np.float32).reshape(-1, length),
        profiles=np.array(out["profiles"], dtype=np.float32).reshape(-1, n_bins),
        detection=detection.astype(np.float32),
        frame=np.array(out["frame"], dtype=np.int64),
        peak_bin=peak_bin,
        range_m=radar.frequency_to_range(peak_bin * radar.bin_hz),
        direction_deg=np.array(out["direction_deg"], dtype=np.float64),
        peak_db=np.array(out["peak_db"], dtype=np.float64),
        n_missing=np.array(out["n_missing"], dtype=np.int64),
        angles_deg=angles,
    )
