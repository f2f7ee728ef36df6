"""Measurement-scene simulator: raw FMCW MIMO acquisitions of drone specimens.

The toolkit's embedded default "measured" data. A campaign of one class is
``n_specimens`` drones, each drawing its own parameters around the class reference,
and ``n_acquisitions`` acquisitions (in total, specimens in equal contiguous blocks),
each F frames x K ramps x A antennas x N_s samples, pushed through the published
chain (:func:`mdaug.radar.chain.process_cube`); the strongest signature of the MTI
frame is the acquisition's profile.

Physics and conventions (units: m, rad, deg where named):

* Target: the vibration model (:func:`if_signal`) at model range R0 = R / 2, R the
  physical (= chain) range, so its tone shows at chain range R (SPEC range
  convention). On top, the carrier phase 4 pi f_c R / c0 of the whole return.
* Antennas: uniform linear array of A = ``scene.n_antennas`` (default radar.n_rx)
  elements at lambda/2; element n adds pi n sin(azimuth) to the carrier phase. The
  per-antenna signals are I cos(psi_n) + Q sin(psi_n) with I, Q the target return
  at carrier phase 0 and pi/2, so the vibration model runs twice, not A times.
* Vibration phases: ``phases="uniform"`` draws all 4 E term phases uniformly per
  frame (a chirp starts at an arbitrary rotor phase); ramps within a frame advance
  them by w * ramp period (as :func:`mdaug.generator.spectra`). ``"fixed"`` keeps the
  specimen's phases in every frame.
* Yaw psi ~ U(-yaw_deg, yaw_deg) mixes the roll and pitch amplitudes, energy
  preserving (the two are incoherent components of one tilt vector seen through a
  rotated axis): A_a' = sqrt((A_a cos psi)^2 + (A_b sin psi)^2),
  A_b' = sqrt((A_a sin psi)^2 + (A_b cos psi)^2); frequencies and mixing terms stay.
* Hover drift: a random walk of the physical range between frames (step
  N(0, drift_step_m)), constant within a frame; it sets the carrier phase of the
  whole target return (what lets a hovering drone survive the MTI) and, with
  ``drift_shifts_range``, its beat frequency too (without: the beat frequency stays
  at the last frame's range in every frame).
* Body: a non-vibrating tone at the target's range (moves with the drift), Gamma
  ``U(body_ratio) * sum(Gamma_k)``, random phase relative to the engines.
* Clutter: ``n_clutter`` static point scatterers (fixed across frames), uniform in
  range and azimuth, amplitude U(clutter_db) dB relative to the target's rms
  amplitude sqrt(2 P_s).
* Receiver noise: white Gaussian, variance P_s / 10^(snr_db / 10) per sample, P_s
  the target's mean power per IF sample (``snr_db=None``: none).
* ADC: gain control per acquisition puts the largest |sample| at ``agc_fill`` of
  full scale, then rounding to ``radar.adc_bits``-bit codes (int16).
* Specimens: a common motor-speed factor N(1, speed_spread) scales every w_a, w_b
  (and so w_p, w_m); each w_a, w_b also gets (1 + N(0, frequency_spread)),
  amplitudes (1 + N(0, amplitude_spread)), Gamma (1 + N(0, gamma_spread)), C_p, C_m
  (1 + N(0, skew_spread)), all magnitudes taken; ``specimen_spread`` multiplies all
  spreads (0: every specimen is the class reference exactly).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..radar import C0, DataFileError, ProfileSet, RadarConfig, atomic_savez, read_arrays
from ..radar.chain import ChainConfig, process_cube
from ..radar.seeds import rng as as_generator
from ..radar.seeds import seed_sequence
from .model import wrap_phase, if_signal, vibration_terms
from .acquisition import PHASE_TREATMENTS, frame_phases, yaw_mix
from .params import IDX, N_PARAMS, PHASES, ClassParams, load_reference
from .specimens import SpecimenSpread

SCENE_PHASES = PHASE_TREATMENTS
CHUNK_ACQ = 8  # acquisitions rendered together


def _pair(v, name):
    lo, hi = (float(v[0]), float(v[1]))
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"SceneConfig.{name} must be a (low, high) pair with low <= high, got {v!r}")
    return (lo, hi)


@dataclass(frozen=True)
class SceneConfig:
    """Everything a simulated acquisition randomises, with the default scene's values.

    Ranges are physical (= chain) metres, angles degrees, levels dB.
    """

    n_frames: int | None = None  # None: radar.mti_depth + 1 (one MTI frame)
    n_ramps: int = 4
    n_antennas: int | None = None  # None: radar.n_rx
    snr_db: float | None = 10.0
    phases: str = "uniform"
    range_m: tuple = (3.0, 8.0)
    azimuth_deg: tuple = (-30.0, 30.0)
    yaw_deg: float = 15.0
    drift_step_m: float = 3e-3
    drift_shifts_range: bool = True
    body_ratio: tuple = (0.0, 0.3)
    n_clutter: int = 6
    clutter_db: tuple = (-10.0, 10.0)
    clutter_range_m: tuple = (0.5, 9.0)
    clutter_azimuth_deg: tuple = (-60.0, 60.0)
    quantise: bool = True
    agc_fill: float = 0.7
    speed_spread: float = 0.05
    frequency_spread: float = 0.02
    amplitude_spread: float = 0.15
    gamma_spread: float = 0.15
    skew_spread: float = 0.01
    specimen_spread: float = 1.0
    dtype: str = "float32"

    def __post_init__(self) -> None:
        for name in ("range_m", "azimuth_deg", "body_ratio", "clutter_db", "clutter_range_m", "clutter_azimuth_deg"):
            object.__setattr__(self, name, _pair(getattr(self, name), name))
        if self.phases not in SCENE_PHASES:
            raise ValueError(f"SceneConfig.phases must be one of {SCENE_PHASES}, got {self.phases!r}")
        ints = {"n_ramps": (self.n_ramps, 1), "n_clutter": (self.n_clutter, 0)}
        if self.n_frames is not None:
            ints["n_frames"] = (self.n_frames, 2)
        if self.n_antennas is not None:
            ints["n_antennas"] = (self.n_antennas, 1)
        for name, (v, lo) in ints.items():
            if int(v) != v or v < lo:
                raise ValueError(f"SceneConfig.{name} must be an integer >= {lo}, got {v!r}")
        nonneg = ("yaw_deg", "drift_step_m", "speed_spread", "frequency_spread", "amplitude_spread",
                  "gamma_spread", "skew_spread", "specimen_spread")
        for name in nonneg:
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"SceneConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 < self.agc_fill <= 1:
            raise ValueError(f"SceneConfig.agc_fill must be in (0, 1], got {self.agc_fill}")
        if self.range_m[0] <= 0 or self.body_ratio[0] < 0:
            raise ValueError("SceneConfig.range_m and body_ratio must be positive")

    def frames(self, radar: RadarConfig) -> int:
        return radar.mti_depth + 1 if self.n_frames is None else int(self.n_frames)

    def antennas(self, radar: RadarConfig) -> int:
        return radar.n_rx if self.n_antennas is None else int(self.n_antennas)

    def replace(self, **changes) -> "SceneConfig":
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def clean(cls, **changes) -> "SceneConfig":
        """A noise-, clutter-, body-, yaw- and quantisation-free scene (for checks)."""
        base = dict(snr_db=None, n_clutter=0, body_ratio=(0.0, 0.0), yaw_deg=0.0, quantise=False)
        return cls(**{**base, **changes})


# ---- specimens and acquisitions --------------------------------------------------
def specimen_spread(scene: SceneConfig) -> SpecimenSpread:
    """The scene's specimen model (:class:`.specimens.SpecimenSpread`)."""
    return SpecimenSpread(speed=scene.speed_spread, frequency=scene.frequency_spread,
                          amplitude=scene.amplitude_spread, gamma=scene.gamma_spread, skew=scene.skew_spread,
                          width=scene.specimen_spread)


def draw_specimens(reference: np.ndarray, n: int, scene: SceneConfig, rng: np.random.Generator) -> np.ndarray:
    """Specimen vectors (n, 13 E) around a class reference (13 E,): the scene's specimen model."""
    return specimen_spread(scene).apply(np.repeat(np.asarray(reference, float)[None], n, axis=0), rng)


@dataclass
class Draws:
    """Per-acquisition random draws of a campaign (N acquisitions, F frames, C clutter)."""

    specimen: np.ndarray  # (N,)
    x: np.ndarray  # (N, 13E) specimen after yaw mixing
    phases: np.ndarray  # (N, F, E, 4) term phases per frame, rad
    yaw_deg: np.ndarray
    range_m: np.ndarray  # (N, F) physical range per frame
    azimuth_deg: np.ndarray
    body_gamma: np.ndarray
    body_phase: np.ndarray
    clutter_range_m: np.ndarray  # (N, C)
    clutter_azimuth_deg: np.ndarray
    clutter_db: np.ndarray
    clutter_phase: np.ndarray


def draw_acquisitions(specimens: np.ndarray, n: int, scene: SceneConfig, radar: RadarConfig,
                      rng: np.random.Generator) -> Draws:
    s = specimens.shape[0]
    spec = (np.arange(n) * s) // n
    f, c = scene.frames(radar), scene.n_clutter
    e = specimens.shape[1] // N_PARAMS
    yaw = rng.uniform(-scene.yaw_deg, scene.yaw_deg, n)
    x = yaw_mix(specimens[spec], np.radians(yaw))
    phases = frame_phases(x, f, scene.phases, rng)
    steps = rng.normal(0.0, scene.drift_step_m, (n, f))
    steps[:, 0] = 0.0
    r = rng.uniform(*scene.range_m, n)[:, None] + np.cumsum(steps, axis=1)
    gam = x.reshape(n, e, N_PARAMS)[..., IDX["Gamma"]].sum(axis=1)
    return Draws(
        specimen=spec, x=x, phases=phases, yaw_deg=yaw, range_m=r,
        azimuth_deg=rng.uniform(*scene.azimuth_deg, n),
        body_gamma=rng.uniform(*scene.body_ratio, n) * gam, body_phase=rng.uniform(-np.pi, np.pi, n),
        clutter_range_m=rng.uniform(*scene.clutter_range_m, (n, c)),
        clutter_azimuth_deg=rng.uniform(*scene.clutter_azimuth_deg, (n, c)),
        clutter_db=rng.uniform(*scene.clutter_db, (n, c)), clutter_phase=rng.uniform(-np.pi, np.pi, (n, c)),
    )


def true_vectors(d: Draws, frame: int) -> np.ndarray:
    """The parameter vectors (N, 13E) of frame ``frame``'s first ramp (phases included)."""
    n = d.x.shape[0]
    e = d.x.reshape(n, -1, N_PARAMS).copy()
    e[..., list(PHASES)] = d.phases[:, frame]
    return e.reshape(n, -1)


# ---- rendering --------------------------------------------------------------------
def _target_iq(d: Draws, sl: slice, scene: SceneConfig, radar: RadarConfig):
    """I and Q target returns (n, F, K, N_s) of acquisitions ``sl`` (body included)."""
    x, ph, r = d.x[sl], d.phases[sl], d.range_m[sl]
    n, f = r.shape
    k, e = scene.n_ramps, x.shape[1] // N_PARAMS
    rows = np.repeat(x, f * k, axis=0).reshape(n, f, k, e, N_PARAMS)
    rows[..., list(PHASES)] = ph[:, :, None]
    rows = rows.reshape(-1, e * N_PARAMS)
    _, w, _ = vibration_terms(rows)
    ramp = np.tile(np.arange(k), n * f)
    offsets = w * (ramp * radar.ramp_period_s)[:, None, None]
    r_beat = r if scene.drift_shifts_range else np.repeat(r[:, -1:], f, axis=1)  # last = MTI frame
    r0 = np.repeat((0.5 * r_beat).ravel(), k)  # model range R0 = R / 2
    carrier = np.repeat((4 * np.pi * radar.centre_frequency_hz / C0 * r).ravel(), k)
    both = if_signal(np.concatenate([rows, rows]), radar, r0=np.concatenate([r0, r0]),
                     phase_offsets=np.concatenate([offsets, offsets]),
                     carrier_phase=np.concatenate([carrier, carrier + 0.5 * np.pi]), dtype=scene.dtype)
    i_sig, q_sig = both[: len(rows)], both[len(rows):]
    if np.any(d.body_gamma[sl] > 0):
        t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
        bphase = wrap_phase(radar.model_k * r0[:, None] * t + (carrier + np.repeat(d.body_phase[sl], f * k))[:, None])
        g = np.repeat(d.body_gamma[sl], f * k)[:, None]
        i_sig += (g * np.cos(bphase)).astype(scene.dtype)
        q_sig -= (g * np.sin(bphase)).astype(scene.dtype)
    shape = (n, f, k, radar.samples_per_chirp)
    return i_sig.reshape(shape), q_sig.reshape(shape)


def render_cubes(d: Draws, sl: slice, scene: SceneConfig, radar: RadarConfig, noise_rngs) -> np.ndarray:
    """Raw cubes (n, F, K, A, N_s) of acquisitions ``sl``: int16 codes (quantised) or float."""
    i_sig, q_sig = _target_iq(d, sl, scene, radar)
    a = scene.antennas(radar)
    psi = np.pi * np.arange(a)[None, :] * np.sin(np.radians(d.azimuth_deg[sl]))[:, None]  # (n, A)
    cos_p = np.cos(psi).astype(scene.dtype)[:, None, None, :, None]
    sin_p = np.sin(psi).astype(scene.dtype)[:, None, None, :, None]
    cube = i_sig[:, :, :, None] * cos_p + q_sig[:, :, :, None] * sin_p
    p_s = np.mean(np.square(cube, dtype=np.float64), axis=(1, 2, 3, 4))  # (n,)
    if scene.n_clutter:
        t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
        amp = np.sqrt(2 * p_s)[:, None] * 10 ** (d.clutter_db[sl] / 20)  # (n, C)
        fb = radar.range_to_frequency(d.clutter_range_m[sl])
        spatial = np.pi * np.arange(a)[None, None, :] * np.sin(np.radians(d.clutter_azimuth_deg[sl]))[..., None]
        coef = amp[..., None] * np.exp(1j * (d.clutter_phase[sl][..., None] + spatial))  # (n, C, A)
        tones = np.exp(2j * np.pi * fb[..., None] * t)  # (n, C, N_s)
        clutter = np.einsum("nca,nct->nat", coef, tones).real.astype(scene.dtype)
        cube += clutter[:, None, None]
    for j, rng in enumerate(noise_rngs):
        if scene.snr_db is not None:
            sigma = np.sqrt(p_s[j] / 10 ** (scene.snr_db / 10))
            cube[j] += (sigma * rng.standard_normal(cube.shape[1:], dtype=np.float32)).astype(scene.dtype)
    if not scene.quantise:
        return cube
    full = 2 ** (radar.adc_bits - 1)
    peak = np.max(np.abs(cube), axis=(1, 2, 3, 4), keepdims=True)
    gain = scene.agc_fill * (full - 1) / np.where(peak > 0, peak, 1)
    return np.clip(np.rint(cube * gain), -full, full - 1).astype(np.int16)


def literal_chain(d: Draws, scene: SceneConfig, radar: RadarConfig, chain: ChainConfig, noise_rngs,
                  keep_cubes: bool = False, chunk: int | None = None):
    """Render every acquisition of ``d`` as a raw cube and run the whole chain on it.

    noise_rngs: one Generator per acquisition. Returns ``(rows, cubes)``: rows a list of
    (ChainResult, j) with j the index of the strongest signature of the last MTI frame;
    cubes (N, F, K, A, N_s) or None. Raises ValueError if an acquisition has no signature.
    """
    n, step = d.x.shape[0], CHUNK_ACQ if chunk is None else int(chunk)
    cubes, rows = [], []
    for lo in range(0, n, step):
        sl = slice(lo, min(n, lo + step))
        block = render_cubes(d, sl, scene, radar, noise_rngs[sl])
        if keep_cubes:
            cubes.append(block)
        for cube in block:
            res = process_cube(cube, radar, chain)
            last = res.frame == res.frame.max()  # strongest signature of the last MTI frame
            j = int(np.flatnonzero(last)[0]) if last.any() else None
            rows.append((res, j))
    if any(j is None for _, j in rows):
        raise ValueError("the chain found no signature in some acquisition (edge='drop' with targets near the ends?)")
    return rows, (np.concatenate(cubes) if keep_cubes else None)


# ---- campaigns --------------------------------------------------------------------
@dataclass
class Campaign:
    """A simulated measurement campaign of one class (N acquisitions, S specimens).

    profiles (N, L) float32 linear magnitude: the strongest signature of each
    acquisition's MTI frame; labels (N,); true_params (N, 13E) the vectors of the MTI
    frame's first ramp (yaw-mixed amplitudes, that frame's phases); specimen (N,);
    specimen_params (S, 13E); range_true_m (N,) physical range at the MTI frame;
    azimuth_deg, yaw_deg (N,); range_m, direction_deg, peak_db, n_missing (N,) the
    chain's estimates; mti_profiles (N, bins) the integrated MTI profile; settings
    (JSON-able, ``simulated: true``); cubes (N, F, K, A, N_s) or None.
    """

    profiles: np.ndarray
    labels: np.ndarray
    true_params: np.ndarray
    specimen: np.ndarray
    specimen_params: np.ndarray
    range_true_m: np.ndarray
    azimuth_deg: np.ndarray
    yaw_deg: np.ndarray
    range_m: np.ndarray
    direction_deg: np.ndarray
    peak_db: np.ndarray
    n_missing: np.ndarray
    mti_profiles: np.ndarray
    settings: dict = field(default_factory=dict)
    cubes: np.ndarray | None = None

    ARRAYS = ("profiles", "labels", "true_params", "specimen", "specimen_params", "range_true_m", "azimuth_deg",
              "yaw_deg", "range_m", "direction_deg", "peak_db", "n_missing", "mti_profiles")

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def on_target(self) -> np.ndarray:
        """(N,) bool: the chain's signature lies within 5 range bins of the true target."""
        bin_m = RadarConfig.from_dict(self.settings["radar"]).bin_m if "radar" in self.settings else RadarConfig().bin_m
        return np.abs(self.range_m - self.range_true_m) <= 5 * bin_m

    @property
    def acquisition(self):
        """The acquisition of the campaign's profiles (:func:`scene_acquisition`)."""
        scene = SceneConfig(**{k: (tuple(v) if isinstance(v, list) else v)
                               for k, v in self.settings.get("scene", {}).items()})
        radar = RadarConfig.from_dict(self.settings["radar"]) if "radar" in self.settings else RadarConfig()
        return scene_acquisition(scene, radar)

    def save(self, path) -> None:
        """NPZ readable by :func:`mdaug.radar.load_profiles` (and :func:`load_campaign`), with
        ``ramps_per_frame`` and ``acquisition`` (JSON) stating how the profiles were made."""
        arrays = {k: getattr(self, k) for k in self.ARRAYS}
        if self.cubes is not None:
            arrays["cubes"] = self.cubes
        acq = self.acquisition
        atomic_savez(path, settings=np.array(json.dumps(self.settings)), ramps_per_frame=np.array(acq.ramps),
                     acquisition=np.array(json.dumps(acq.to_dict())), **arrays)


PER_CLASS = ("true_params", "specimen_params")
"""Campaign arrays whose width depends on the class (13 x engines): stored per class
(``true_params_HELI``, ...) in a file of several classes."""


def save_campaigns(path, campaigns: list[Campaign]) -> None:
    """One NPZ of one or several campaigns of different classes (the same scene): the
    profile-file fields of every campaign concatenated (readable by
    :func:`mdaug.radar.load_profiles`), the class-width arrays per class
    (:data:`PER_CLASS`), and settings ``{"classes", "per_class": {class: settings}}``."""
    if len(campaigns) == 1:
        return campaigns[0].save(path)
    names = [c.settings.get("class") for c in campaigns]
    if len(set(names)) != len(names):
        raise ValueError(f"save_campaigns: one campaign per class, got classes {names}")
    acqs = {json.dumps(c.acquisition.to_dict(), sort_keys=True) for c in campaigns}
    if len(acqs) != 1:
        raise ValueError("save_campaigns: the campaigns were simulated under different acquisitions")
    acq = campaigns[0].acquisition
    arrays = {k: np.concatenate([getattr(c, k) for c in campaigns]) for k in Campaign.ARRAYS if k not in PER_CLASS}
    for c, name in zip(campaigns, names):
        for k in PER_CLASS:
            arrays[f"{k}_{name}"] = getattr(c, k)
    if all(c.cubes is not None for c in campaigns):
        arrays["cubes"] = np.concatenate([c.cubes for c in campaigns])
    settings = {"simulated": True, "kind": "mdaug scene simulation", "classes": names,
                "per_class": {n: c.settings for n, c in zip(names, campaigns)}}
    atomic_savez(path, settings=np.array(json.dumps(settings)), ramps_per_frame=np.array(acq.ramps),
                 acquisition=np.array(json.dumps(acq.to_dict())), **arrays)


def scene_acquisition(scene: SceneConfig, radar: RadarConfig = RadarConfig()):
    """The :class:`~.acquisition.Acquisition` a scene's profiles are measured under: its
    ramps, phase treatment, yaw and body return, through the published chain (MTI over
    radar.mti_depth frames, the measured preset's jitter, noise and drift)."""
    from .acquisition import Acquisition

    return Acquisition.measured(scene.n_ramps, phases=scene.phases, yaw_deg=scene.yaw_deg, carrier=scene.body_ratio,
                                mti_depth=radar.mti_depth)


PER_ROW = ("specimen", "range_true_m", "azimuth_deg", "yaw_deg", "range_m", "direction_deg", "peak_db", "n_missing",
           "mti_profiles")


def as_profile_set(*campaigns: Campaign) -> ProfileSet:
    """Campaigns (e.g. one HELI and one QUAD) as one labelled :class:`ProfileSet`:
    profiles (N, L) float64, labels (N,), extra = the per-acquisition fields
    concatenated plus ``campaign`` (N,) the index of each row's campaign and
    ``settings`` (JSON list of the campaigns' settings)."""
    if not campaigns:
        raise ValueError("as_profile_set needs at least one campaign")
    cat = lambda key: np.concatenate([getattr(c, key) for c in campaigns])  # noqa: E731
    extra = {k: cat(k) for k in PER_ROW}
    extra["campaign"] = np.concatenate([np.full(len(c), i) for i, c in enumerate(campaigns)])
    extra["settings"] = np.array(json.dumps([c.settings for c in campaigns]))
    return ProfileSet(profiles=cat("profiles").astype(np.float64), labels=cat("labels").astype(str), extra=extra,
                      source="simulated campaign(s) " + ", ".join(c.settings.get("class", "?") for c in campaigns))


def load_campaign(path) -> Campaign:
    """Read a campaign NPZ written by :meth:`Campaign.save` (errors name file and field)."""
    arrays = read_arrays(path)
    missing = [k for k in Campaign.ARRAYS + ("settings",) if k not in arrays]
    if missing:
        raise DataFileError(f"{path}: not a simulated campaign, missing field(s) {missing}")
    settings = json.loads(str(arrays["settings"]))
    return Campaign(**{k: arrays[k] for k in Campaign.ARRAYS}, settings=settings, cubes=arrays.get("cubes"))


def simulate_campaign(reference: ClassParams | str, n_specimens: int, n_acquisitions: int, seed=0,
                      scene: SceneConfig = SceneConfig(), radar: RadarConfig = RadarConfig(),
                      keep_cubes: bool = False, chain: ChainConfig = ChainConfig()) -> Campaign:
    """Simulate and process a campaign of one class (see the module doc for the physics).

    ``n_acquisitions`` is the total, spread over the specimens in equal contiguous
    blocks. Randomness: one SeedSequence(seed) -> specimens, scene draws, and one
    noise stream per acquisition, so results do not depend on chunking.
    """
    ref = load_reference(reference) if isinstance(reference, str) else reference
    for name, v in (("n_specimens", n_specimens), ("n_acquisitions", n_acquisitions)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    n = int(n_acquisitions)
    root = seed_sequence(seed)  # seed=None: fresh entropy, recorded in settings
    ss_spec, ss_draw, ss_noise = root.spawn(3)
    specimens = draw_specimens(ref.to_array(), int(n_specimens), scene, as_generator(ss_spec))
    d = draw_acquisitions(specimens, n, scene, radar, as_generator(ss_draw))
    noise_rngs = [as_generator(s) for s in ss_noise.spawn(n)]
    f = scene.frames(radar)
    rows, cubes = literal_chain(d, scene, radar, chain, noise_rngs, keep_cubes=keep_cubes)
    pick = lambda key: np.array([getattr(res, key)[j] for res, j in rows])  # noqa: E731
    settings = {
        "simulated": True, "kind": "mdaug scene simulation", "class": ref.name,
        "seed": seed if seed is not None else root.entropy,
        "n_specimens": int(n_specimens), "n_acquisitions": n, "reference": ref.to_array().tolist(),
        "scene": scene.to_dict(), "radar": radar.to_dict(), "chain": chain.to_dict(),
        "profiles": "linear magnitude, strongest signature of the last MTI frame",
    }
    return Campaign(
        profiles=pick("signatures").astype(np.float32), labels=np.full(n, ref.name),
        true_params=true_vectors(d, f - 1), specimen=d.specimen, specimen_params=specimens,
        range_true_m=d.range_m[:, -1], azimuth_deg=d.azimuth_deg, yaw_deg=d.yaw_deg,
        range_m=pick("range_m"), direction_deg=pick("direction_deg"), peak_db=pick("peak_db"),
        n_missing=pick("n_missing"), mti_profiles=pick("profiles").astype(np.float32),
        settings=settings, cubes=cubes,
    )
