"""Measurement-scene simulator: raw FMCW MIMO acquisitions of drone specimens.

The toolkit's embedded default "measured" data. A campaign of one class is
``n_specimens`` drones, each drawing its own parameters around the class reference,
and ``n_acquisitions`` acquisitions (in total, specimens in equal contiguous blocks),
each F frames x K ramps x A antennas x N_s samples, pushed through the published
chain (:func:`mdaug.radar.chain.process_cube`); the strongest signature of the MTI
frame is the acquisition's profile (campaigns: :mod:`.campaign`; the chain path of
the augmentation renderer on the same draws: :mod:`.path`).

Physics and conventions (units: m, rad, deg where named):

* Target: the vibration model (:func:`if_signal`) at model range R0 = R / 2, R the
  physical (= chain) range, so its tone shows at chain range R (SPEC range
  convention). On top, the carrier phase 4 pi f_c R / c0 of the whole return.
* Settings: :class:`~.config.SceneConfig`, one acquisition (ramps, phases, yaw,
  body return) and one specimen model plus the scene's own fields.
* Antennas: uniform linear array of A = ``scene.n_antennas`` (default radar.n_rx)
  elements at lambda/2; element n adds pi n sin(azimuth) to the carrier phase. The
  per-antenna signals are I cos(psi_n) + Q sin(psi_n) with I, Q the target return
  at carrier phase 0 and pi/2, so the vibration model runs twice, not A times.
* Vibration phases: the acquisition's phase rule (:func:`~..acquisition.frame_phases`):
  ``"uniform"`` draws all 4 E term phases uniformly per frame (a chirp starts at an
  arbitrary rotor phase); ramps within a frame advance them by w * ramp period (as
  :func:`mdaug.generator.spectra`). ``"fixed"`` keeps the specimen's phases in every frame.
* Yaw psi ~ U(-yaw_deg, yaw_deg) of the acquisition mixes the roll and pitch
  amplitudes, energy preserving (:func:`~..acquisition.yaw_mix`); frequencies and
  mixing terms stay.
* Hover drift: a random walk of the physical range between frames (step
  N(0, drift_step_m)), constant within a frame; it sets the carrier phase of the
  whole target return (what lets a hovering drone survive the MTI) and, with
  ``drift_shifts_range``, its beat frequency too (without: the beat frequency stays
  at the last frame's range in every frame).
* Body: a non-vibrating tone at the target's range (moves with the drift), Gamma
  ``U(acquisition.carrier) * sum(Gamma_k)``, random phase relative to the engines.
* Clutter: ``n_clutter`` static point scatterers (fixed across frames), uniform in
  range and azimuth, amplitude U(clutter_db) dB relative to the target's rms
  amplitude sqrt(2 P_s).
* Receiver noise: white Gaussian, variance P_s / 10^(snr_db / 10) per sample, P_s
  the target's mean power per IF sample (``snr_db=None``: none).
* ADC: gain control per acquisition puts the largest |sample| at ``agc_fill`` of
  full scale, then rounding to ``radar.adc_bits``-bit codes (int16).
* Specimens: the scene's specimen model (:class:`~..specimens.SpecimenSpread`: a
  common motor-speed factor, frequency, amplitude, Gamma and skew spreads, all
  scaled by ``width``; 0: every specimen is the class reference exactly).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...radar import C0, RadarConfig
from ...radar.chain import ChainConfig, process_cube
from ..acquisition import frame_phases, yaw_mix
from ..model import if_signal, vibration_terms, wrap_phase
from ..params import IDX, N_PARAMS, PHASES
from .config import SceneConfig

CHUNK_ACQ = 8  # acquisitions rendered together

# ---- specimens and acquisitions --------------------------------------------------
def draw_specimens(reference: np.ndarray, n: int, scene: SceneConfig, rng: np.random.Generator) -> np.ndarray:
    """Specimen vectors (n, 13 E) around a class reference (13 E,): the scene's specimen model."""
    return scene.specimens.apply(np.repeat(np.asarray(reference, float)[None], n, axis=0), rng)


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
    radar.check_ramps(scene.acquisition.ramps, "SceneConfig.acquisition.ramps")
    s = specimens.shape[0]
    spec = (np.arange(n) * s) // n
    f, c = scene.frames(radar), scene.n_clutter
    e = specimens.shape[1] // N_PARAMS
    acq = scene.acquisition
    yaw = rng.uniform(-acq.yaw_deg, acq.yaw_deg, n)
    x = yaw_mix(specimens[spec], np.radians(yaw))
    phases = frame_phases(x, f, acq.phases, rng)
    steps = rng.normal(0.0, scene.drift_step_m, (n, f))
    steps[:, 0] = 0.0
    r = rng.uniform(*scene.range_m, n)[:, None] + np.cumsum(steps, axis=1)
    gam = x.reshape(n, e, N_PARAMS)[..., IDX["Gamma"]].sum(axis=1)
    return Draws(
        specimen=spec, x=x, phases=phases, yaw_deg=yaw, range_m=r,
        azimuth_deg=rng.uniform(*scene.azimuth_deg, n),
        body_gamma=rng.uniform(*acq.carrier, n) * gam, body_phase=rng.uniform(-np.pi, np.pi, n),
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
    k, e = scene.acquisition.ramps, x.shape[1] // N_PARAMS
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
