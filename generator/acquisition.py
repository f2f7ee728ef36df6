"""The acquisition: how a drone's class vector becomes a measured profile (SPEC 3.2).

A measured range profile is the drone's vibration seen through an acquisition. One
:class:`Acquisition` object states it; the calibration's likelihood and every
augmenter's renderer share it, so synthetic and measured profiles come from the
same place. What it holds:

* ``ramps`` K: the frame's profile is the incoherent (magnitude) average of K
  ramps; between consecutive ramps every vibration phase advances by
  w x ramp period (2.88 ms);
* ``phases``: the phase treatment per frame (:data:`PHASE_TREATMENTS`, applied by
  :func:`frame_phases`, the toolkit's one phase rule): ``fixed`` keeps the class
  vector's phases, ``uniform`` draws every term's phase on [-pi, pi) per frame
  (a chirp starts at an arbitrary rotor phase);
* ``range_jitter_bins``: the target's sub-bin range position, uniform over this
  width (FFT bins) around the model range;
* ``carrier``: a return at the carrier (body, hub) that does not vibrate, of
  amplitude U(carrier) x sum of the engines' Gamma and a phase uniform relative to
  the engines (the same in every ramp of the frame);
* ``noise_db``: the receiver noise floor, U(noise_db) dB: the mean magnitude of
  one ramp's noise spectrum per bin relative to the carrier line of an
  unmodulated tone of amplitude sum(Gamma) (``None``: no noise);
* ``yaw_deg``: yaw U(-yaw, yaw) mixes the roll and pitch amplitudes (energy
  preserving, :func:`yaw_mix`);
* ``mti_depth`` N and ``drift_bins``: the chain's moving-target indication
  subtracts the mean of the N previous frames. Those frames have their own
  phases and, through the hover drift, their own carrier phase, so what survives
  is the current frame plus a random residual whose every spectral line carries an
  independent random gain (E|gain|^2 = 1 + 1/N). The fast path renders that
  residual as one more frame with its own phases (the current ones shifted by a
  random offset that stays the same in every ramp), a uniform carrier phase, a
  range offset N(0, drift_bins) and weight 1/sqrt(N): the same second moments as
  the mean of N frames. 0 (default) = no MTI.

The published path (one chirp at the fitted phases) is ``Acquisition()`` (K = 1,
fixed phases, nothing else): :func:`render` then gives exactly f(x).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..radar import RadarConfig, centred_slices, check_normalisation, normalise
from ..radar.seeds import rng as as_generator, seed_sequence
from .model import if_signal, magnitude_spectra, profiles as model_profiles, vibration_terms, wrap_phase
from .params import IDX, N_PARAMS, PHASES, validate_vectors

PHASE_TREATMENTS = ("fixed", "uniform")
NOISE_BLOCK = 256  # acquisitions per noise stream: results do not depend on the caller's batch size


def _pair(value, name: str, lo=-np.inf, hi=np.inf) -> tuple[float, float]:
    try:
        a, b = (float(value[0]), float(value[1])) if np.ndim(value) else (float(value), float(value))
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"Acquisition.{name} must be a number or a (low, high) pair, got {value!r}") from None
    if not (np.isfinite(a) and np.isfinite(b) and lo <= a <= b <= hi):
        raise ValueError(f"Acquisition.{name} must be a (low, high) pair with {lo} <= low <= high <= {hi}, "
                         f"got {value!r}")
    return (a, b)


@dataclass(frozen=True)
class Acquisition:
    """What a measurement randomises and averages beyond the class vector (module doc).

    Units: bins of the FFT (``range_jitter_bins``, ``drift_bins``), dB (``noise_db``),
    degrees (``yaw_deg``), ratios (``carrier``).
    """

    ramps: int = 1
    phases: str = "fixed"
    range_jitter_bins: float = 0.0
    carrier: tuple = (0.0, 0.0)
    noise_db: tuple | None = None
    yaw_deg: float = 0.0
    mti_depth: int = 0
    drift_bins: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.ramps, bool) or int(self.ramps) != self.ramps or self.ramps < 1:
            raise ValueError(f"Acquisition.ramps (K, ramps per frame) must be an integer >= 1, got {self.ramps!r}")
        object.__setattr__(self, "ramps", int(self.ramps))
        if self.phases not in PHASE_TREATMENTS:
            raise ValueError(f"Acquisition.phases must be one of {PHASE_TREATMENTS}, got {self.phases!r}")
        for name in ("range_jitter_bins", "yaw_deg", "drift_bins"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.number)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"Acquisition.{name} must be a finite number >= 0, got {v!r}")
        if self.yaw_deg > 90:
            raise ValueError(f"Acquisition.yaw_deg must be <= 90 degrees, got {self.yaw_deg}")
        object.__setattr__(self, "carrier", _pair(self.carrier, "carrier", 0.0, 100.0))
        if self.noise_db is not None:
            object.__setattr__(self, "noise_db", _pair(self.noise_db, "noise_db", -200.0, 40.0))
        if isinstance(self.mti_depth, bool) or int(self.mti_depth) != self.mti_depth or self.mti_depth < 0:
            raise ValueError(f"Acquisition.mti_depth must be an integer >= 0 (0 = no MTI), got {self.mti_depth!r}")
        object.__setattr__(self, "mti_depth", int(self.mti_depth))

    # ---- presets and conversions --------------------------------------------------
    @classmethod
    def published(cls) -> "Acquisition":
        """The published path: one chirp at the class vector's phases (f(x) itself)."""
        return cls()

    @classmethod
    def measured(cls, ramps: int = 1, **kw) -> "Acquisition":
        """A measured campaign through the published chain, as the embedded scene
        simulator makes it: random phases per frame, one bin of sub-bin range
        jitter, a body return of up to 0.3 sum(Gamma), noise near -45 dB, yaw +-15
        deg, MTI over 10 frames with the scene's hover drift. Any field can be
        overridden."""
        base = dict(ramps=ramps, phases="uniform", range_jitter_bins=1.0, carrier=(0.0, 0.3),
                    noise_db=(-48.0, -42.0), yaw_deg=15.0, mti_depth=10, drift_bins=1.5)
        base.update(kw)
        return cls(**base)

    @property
    def is_published(self) -> bool:
        return self == Acquisition()

    def replace(self, **kw) -> "Acquisition":
        return dataclasses.replace(self, **kw)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["carrier"] = list(self.carrier)
        d["noise_db"] = None if self.noise_db is None else list(self.noise_db)
        return d

    @classmethod
    def from_dict(cls, d: dict, source: str = "acquisition") -> "Acquisition":
        if not isinstance(d, dict):
            raise ValueError(f"{source}: expected a table of acquisition fields, got {type(d).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"{source}: unknown acquisition field(s) {unknown}; known: {sorted(known)}")
        try:
            return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})
        except (ValueError, TypeError, OverflowError) as exc:  # e.g. ramps = Infinity, null, "4"
            raise ValueError(f"{source}: {exc}") from None

    def describe(self) -> str:
        """One line for logs: K, phases and the scene terms."""
        parts = [f"K = {self.ramps} ramp(s) per frame", f"{self.phases} phases"]
        if self.range_jitter_bins:
            parts.append(f"sub-bin range jitter {self.range_jitter_bins:g} bin")
        if self.carrier[1] > 0:
            parts.append(f"carrier return {self.carrier[0]:g}-{self.carrier[1]:g} x sum(Gamma)")
        if self.noise_db is not None:
            parts.append(f"noise floor {self.noise_db[0]:g} to {self.noise_db[1]:g} dB")
        if self.yaw_deg:
            parts.append(f"yaw +-{self.yaw_deg:g} deg")
        if self.mti_depth:
            parts.append(f"MTI over {self.mti_depth} frames (drift {self.drift_bins:g} bin)")
        return ", ".join(parts)

    def draw(self, x: np.ndarray, rng: np.random.Generator, radar: RadarConfig = RadarConfig()) -> "AcquisitionDraws":
        """The random part of n acquisitions of vectors x (n, 13E): every draw up front."""
        return draw_acquisitions(x, self, rng, radar)


def acquisition_from_file(extra: dict, source: str) -> Acquisition | None:
    """The acquisition a data file states (NPZ key ``acquisition``: a JSON table of
    :class:`Acquisition` fields, or ``ramps_per_frame``: K alone, meaning a measured
    campaign through the published chain, :meth:`Acquisition.measured`); None when
    the file says nothing. Errors name the file and the field."""
    acq = None
    if "acquisition" in extra:
        try:
            table = json.loads(str(np.asarray(extra["acquisition"])))
        except ValueError:
            raise ValueError(f"{source}: field 'acquisition' is not a JSON table of acquisition fields") from None
        acq = Acquisition.from_dict(table, f"{source}: field 'acquisition'")
    if "ramps_per_frame" in extra:
        raw = np.asarray(extra["ramps_per_frame"])
        if raw.size != 1 or raw.dtype.kind not in "iuf" or not float(raw.ravel()[0]).is_integer() or raw < 1:
            raise ValueError(f"{source}: field 'ramps_per_frame' must be one integer >= 1 (ramps averaged per "
                             f"profile), got {raw.tolist()!r}")
        k = int(raw)
        if acq is not None and acq.ramps != k:
            raise ValueError(f"{source}: field 'ramps_per_frame' = {k} disagrees with field 'acquisition' "
                             f"(ramps = {acq.ramps})")
        acq = acq or Acquisition.measured(k)
    return acq


def resolve_acquisition(from_file: Acquisition | None, given: Acquisition | None, file_name: str,
                        given_name: str) -> Acquisition:
    """The one file-against-setting rule: the acquisition when a data file and a setting (flag,
    config) may both state one; either alone wins, both must agree on K (an error names both)."""
    if from_file is not None and given is not None and from_file.ramps != given.ramps:
        raise ValueError(f"{file_name} says {from_file.ramps} ramp(s) per frame but {given_name} says "
                         f"{given.ramps}; make them agree (or drop one)")
    return given if given is not None else (from_file if from_file is not None else Acquisition())


# ---- the one phase rule ------------------------------------------------------------------
def phase_columns(n_engines: int) -> np.ndarray:
    """Columns of the 4 E term phases in a flat class vector, engine-major (a, b, p, m)."""
    return np.array([k * N_PARAMS + c for k in range(n_engines) for c in PHASES])


def frame_phases(x: np.ndarray, n_frames: int, treatment: str, rng: np.random.Generator | None) -> np.ndarray:
    """Term phases (n, F, E, 4) in rad at the first ramp of each of F frames of n
    acquisitions of vectors x (n, 13E): ``fixed`` repeats the vectors' phases,
    ``uniform`` draws them on [-pi, pi) independently per frame and term."""
    if treatment not in PHASE_TREATMENTS:
        raise ValueError(f"phase treatment must be one of {PHASE_TREATMENTS}, got {treatment!r}")
    n, e = x.shape[0], x.shape[1] // N_PARAMS
    if treatment == "uniform":
        return rng.uniform(-np.pi, np.pi, size=(n, n_frames, e, 4))
    ph = x.reshape(n, e, N_PARAMS)[..., list(PHASES)]
    return np.repeat(ph[:, None], n_frames, axis=1)


def residual_offsets(shape, treatment: str, rng: np.random.Generator) -> np.ndarray:
    """Phase offsets (n, E, 4) of the MTI residual frame from the current frame, kept
    over the ramps: uniform on [-pi, pi) under ``uniform`` phases, none under ``fixed``."""
    return rng.uniform(-np.pi, np.pi, size=shape) if treatment == "uniform" else np.zeros(shape)


def with_phases(x: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """Copy of x (n, 13E) with its term phases replaced by phases (n, E, 4)."""
    out = np.array(x, dtype=np.float64, copy=True)
    out[:, phase_columns(x.shape[1] // N_PARAMS)] = phases.reshape(len(x), -1)
    return out


def yaw_mix(x: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """Roll and pitch amplitudes seen at yaw psi (n,) rad: the two are incoherent
    components of one tilt vector seen through a rotated axis, so
    A_a' = sqrt((A_a cos psi)^2 + (A_b sin psi)^2), A_b' = sqrt((A_a sin psi)^2 + (A_b cos psi)^2);
    frequencies and mixing terms stay. x (n, 13E) -> (n, 13E)."""
    e = np.array(x, dtype=np.float64).reshape(x.shape[0], -1, N_PARAMS)
    a, b = e[..., IDX["A_a"]].copy(), e[..., IDX["A_b"]].copy()
    c, s = np.cos(yaw_rad)[:, None], np.sin(yaw_rad)[:, None]
    e[..., IDX["A_a"]] = np.hypot(a * c, b * s)
    e[..., IDX["A_b"]] = np.hypot(a * s, b * c)
    return e.reshape(x.shape)


# ---- draws ---------------------------------------------------------------------------------
@dataclass
class AcquisitionDraws:
    """The random part of n acquisitions (all in float64).

    x (n, 13E): the vectors as seen (yaw mixed, phases of the current frame's first
    ramp); r0 (n,) model range, m; carrier (n,) carrier-return amplitude (absolute,
    same units as Gamma) and carrier_phase (n,) rad; noise_sigma (n,) the white
    noise sd per IF sample (0 = none); yaw_deg (n,); residual_x (n, 13E),
    residual_r0 (n,), residual_phase (n,): the MTI residual frame (None without MTI).
    """

    x: np.ndarray
    r0: np.ndarray
    carrier: np.ndarray
    carrier_phase: np.ndarray
    noise_sigma: np.ndarray
    yaw_deg: np.ndarray
    residual_x: np.ndarray | None = None
    residual_r0: np.ndarray | None = None
    residual_phase: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.r0)

    def take(self, sl) -> "AcquisitionDraws":
        return AcquisitionDraws(**{f.name: (None if getattr(self, f.name) is None else getattr(self, f.name)[sl])
                                   for f in dataclasses.fields(self)})


def noise_sigma(level_db, gamma_sum, radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """White-noise sd per IF sample whose one-ramp spectrum has a mean magnitude per bin
    (Rayleigh mean sqrt(pi N_s / 4) sigma) of ``level_db`` relative to the carrier line
    sum(Gamma) N_s / 2 of an unmodulated tone."""
    n_s = radar.samples_per_chirp
    line = np.asarray(gamma_sum, float) * n_s / 2.0
    return 10.0 ** (np.asarray(level_db, float) / 20.0) * line / np.sqrt(np.pi * n_s / 4.0)


def draw_acquisitions(x, acq: Acquisition, rng: np.random.Generator,
                      radar: RadarConfig = RadarConfig()) -> AcquisitionDraws:
    """Every random quantity of n acquisitions of vectors x (n, 13E), in a fixed order
    (so the same seed gives the same draws whatever is rendered afterwards)."""
    x = validate_vectors(x, physical=False)
    radar.check_ramps(acq.ramps)
    n, e = x.shape[0], x.shape[1] // N_PARAMS
    yaw = rng.uniform(-acq.yaw_deg, acq.yaw_deg, n) if acq.yaw_deg else np.zeros(n)
    seen = yaw_mix(x, np.radians(yaw)) if acq.yaw_deg else x.copy()
    phases = frame_phases(seen, 1, acq.phases, rng)[:, 0]
    seen = with_phases(seen, phases)
    j = acq.range_jitter_bins
    r0 = np.full(n, radar.model_range_m)
    if j > 0:
        r0 = r0 + rng.uniform(-0.5 * j, 0.5 * j, n) * radar.model_range_per_bin()
    gamma_sum = x.reshape(n, e, N_PARAMS)[..., IDX["Gamma"]].sum(axis=1)
    lo, hi = acq.carrier
    carrier = (rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo)) * gamma_sum
    carrier_phase = rng.uniform(-np.pi, np.pi, n)
    if acq.noise_db is None:
        sigma = np.zeros(n)
    else:
        lo, hi = acq.noise_db
        sigma = noise_sigma(rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo), gamma_sum, radar)
    out = AcquisitionDraws(x=seen, r0=r0, carrier=carrier, carrier_phase=carrier_phase, noise_sigma=sigma,
                           yaw_deg=yaw)
    if acq.mti_depth:
        out.residual_x = with_phases(seen, phases + residual_offsets(phases.shape, acq.phases, rng))
        out.residual_r0 = r0 + acq.drift_bins * rng.standard_normal(n) * radar.model_range_per_bin()
        out.residual_phase = rng.uniform(-np.pi, np.pi, n)
    return out


# ---- rendering (the fast path) ------------------------------------------------------------
def ramp_signals(d: AcquisitionDraws, acq: Acquisition, radar: RadarConfig, ramps, dtype="float32") -> np.ndarray:
    """IF samples of the given ramps of every acquisition: (n, len(ramps), N_s) in dtype,
    noise-free: the target (vibrating engines), minus the MTI residual, plus the carrier
    return."""
    ramps = np.asarray(ramps)
    n, k = len(d), len(ramps)
    _, w, _ = vibration_terms(d.x)
    offsets = (w[:, None] * (ramps * radar.ramp_period_s)[None, :, None, None]).reshape(n * k, *w.shape[1:])
    rows = np.repeat(d.x, k, axis=0)
    r0 = np.repeat(d.r0, k)
    sig = if_signal(rows, radar, r0=r0, phase_offsets=offsets, dtype=dtype)
    if d.residual_x is not None:
        res = if_signal(np.repeat(d.residual_x, k, axis=0), radar, r0=np.repeat(d.residual_r0, k),
                        phase_offsets=offsets, carrier_phase=np.repeat(d.residual_phase, k), dtype=dtype)
        sig -= res * np.asarray(1.0 / np.sqrt(acq.mti_depth), dtype=sig.dtype)
    if np.any(d.carrier > 0):
        t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
        phase = radar.model_k * d.r0[:, None] * t + d.carrier_phase[:, None]
        phase = wrap_phase(phase)
        tone = (d.carrier[:, None] * np.cos(phase)).astype(sig.dtype)
        sig += np.repeat(tone, k, axis=0)
    return sig.reshape(n, k, -1)


def render_spectra(d: AcquisitionDraws, acq: Acquisition, radar: RadarConfig = RadarConfig(), *,
                   dtype="float32", noise_rng: np.random.Generator | None = None,
                   ramp_chunk: int = 8) -> np.ndarray:
    """K-ramp averaged magnitude spectra (n, fft_points/2) of drawn acquisitions.

    Ramps are rendered ``ramp_chunk`` at a time (bounded memory); receiver noise (white,
    Gaussian, per ramp and sample) comes from ``noise_rng`` in ramp order."""
    total = None
    for lo in range(0, acq.ramps, ramp_chunk):
        ramps = np.arange(lo, min(acq.ramps, lo + ramp_chunk))
        sig = ramp_signals(d, acq, radar, ramps, dtype)
        if np.any(d.noise_sigma > 0):
            z = noise_rng.standard_normal(sig.shape, dtype=np.float32)
            sig += (d.noise_sigma[:, None, None] * z).astype(sig.dtype)
        mag = magnitude_spectra(sig.reshape(-1, sig.shape[-1]), radar).reshape(len(d), len(ramps), -1).sum(axis=1)
        total = mag if total is None else total + mag
    return total / acq.ramps


def render(x, acq: Acquisition, rng, radar: RadarConfig = RadarConfig(), *, normalisation: str = "peak",
           dtype: str = "float32", draws: AcquisitionDraws | None = None, progress=None) -> np.ndarray:
    """Profiles (n, L) of vectors x (n, 13E) under ``acq`` (the fast path).

    Each profile: the K-ramp averaged magnitude spectrum, the L-bin window with its
    strongest bin at L // 2 (zero-filled past the ends, as f(x)), normalised. The
    published acquisition gives exactly f(x) (:func:`mdaug.generator.profiles`).
    ``draws``: reuse draws made by :meth:`Acquisition.draw` (else drawn here from rng).
    Every draw happens up front and the receiver noise comes from one stream per block
    of NOISE_BLOCK acquisitions, so memory stays bounded and the result depends on
    the seed only. ``progress``: None, or a callable told how many profiles each block
    added."""
    check_normalisation(normalisation)
    x = validate_vectors(x, physical=False)
    if acq.is_published and draws is None:
        return model_profiles(x, radar, normalisation=normalisation, dtype=dtype, on_edge="pad")
    rng = as_generator(rng)
    d = draws if draws is not None else acq.draw(x, rng, radar)
    n = len(d)
    noise_seed = seed_sequence(rng)
    streams = noise_seed.spawn(-(-n // NOISE_BLOCK))
    out = np.empty((n, radar.slice_length), dtype=dtype)
    for b, lo in enumerate(range(0, n, NOISE_BLOCK)):
        sl = slice(lo, min(n, lo + NOISE_BLOCK))
        mag = render_spectra(d.take(sl), acq, radar, dtype=dtype, noise_rng=as_generator(streams[b]))
        win, _ = centred_slices(mag, np.argmax(mag, axis=1), radar.slice_length)
        out[sl] = normalise(win, normalisation)
        if progress is not None:
            progress(sl.stop - sl.start)
    return out


def carrier_spectrum(r0, amplitude, phase, radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """Complex spectrum (n, fft_points/2) of the carrier return a cos(K r0 t + phase) (rfft)."""
    t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
    ph = radar.model_k * np.asarray(r0, float)[:, None] * t + np.asarray(phase, float)[:, None]
    sig = np.asarray(amplitude, float)[:, None] * np.cos(ph)
    return scipy.fft.rfft(sig, n=radar.fft_points, axis=-1)[:, : radar.n_bins]
