"""The chain path of the augmentation renderer: class vectors -> raw acquisitions -> radar chain.

:func:`render_through_chain` turns each row of ``x`` (n, 13 E) into one simulated raw
acquisition of the scene simulator (:mod:`.scene`: yaw, body return,
range and azimuth, hover drift, clutter, noise, ADC, K ramps per frame, F frames)
processed by the published chain (:func:`mdaug.radar.chain.process_cube`) into one
``radar.slice_length``-bin profile: the strongest signature of the last MTI frame,
exactly what :func:`.campaign.simulate_campaign` keeps. The row IS the
specimen: no specimen spread is applied.

Two methods on the same draws (:func:`.scene.draw_acquisitions`):

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

import numpy as np

from ...radar import RadarConfig
from ...radar.chain import ChainConfig
from ...radar.seeds import rng as as_generator
from ...radar.seeds import seed_sequence
from ..params import N_PARAMS, validate_vectors
from .config import SceneConfig
from .image import reduced_block
from .plan import Work, make_plan
from .scene import draw_acquisitions, literal_chain, true_vectors
from .target import choose_steps

METHODS = ("literal", "reduced")

SEARCH_BINS = 64  # detection window: true range bin +- this many bins

WORK_ELEMENTS = 1 << 19  # phase samples per reduced chunk: a few MB of scratch, reused


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
    (K = ``scene.acquisition.ramps`` ramps, F frames, phases, yaw, range, azimuth, drift, body,
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


def _reduced(d, scene, radar, chain, noise_seeds, search, chunk_size, interpolate=True, progress=None) -> dict:
    n = d.x.shape[0]
    plan = make_plan(scene, radar, chain, search, interpolate)
    if chunk_size is None:
        per_row = len(plan.frames) * scene.acquisition.ramps * (d.x.shape[1] // N_PARAMS) * radar.samples_per_chirp
        chunk_size = int(np.clip(WORK_ELEMENTS // per_row, 1, 16))
    out = {"profiles": np.empty((n, radar.slice_length), np.float32), "peak_bin": np.empty(n, np.int64),
           "direction_deg": np.empty(n), "n_missing": np.empty(n, np.int64)}
    work, edge = Work(), np.zeros(n, bool)
    steps = choose_steps(d, plan, scene, radar)
    for step in np.unique(steps):  # rows of one sampling step together
        rows = np.flatnonzero(steps == step)
        for lo in range(0, len(rows), int(chunk_size)):
            sl = rows[lo: lo + int(chunk_size)]
            seeds = [noise_seeds[i] for i in sl]
            for key, val in reduced_block(d, sl, plan, scene, radar, seeds, int(step), work).items():
                (edge if key == "at_edge" else out[key])[sl] = val
            if progress is not None:
                progress(len(sl))
    if edge.any():
        warnings.warn(f"{int(edge.sum())} of {n} profile(s) peak at the edge of the reduced path's search window "
                      f"(true range bin +-{search}): the chain's strongest peak may lie outside; raise search_bins "
                      "or use method='literal'", RuntimeWarning, stacklevel=3)
    return out
