"""The scene's settings: one :class:`~..acquisition.Acquisition`, one
:class:`~..specimens.SpecimenSpread`, and what is the scene's own.

The acquisition states what the scene shares with the fast path: K ramps per frame
(``ramps``), the phase treatment (``phases``), the yaw (``yaw_deg``) and the body
return (``carrier``, x sum(Gamma)). The specimen model states how the drones of one
class differ. Everything else (range, azimuth, hover drift, clutter, receiver noise
as an SNR, ADC, antennas, frames, dtype) is the scene's own.

A scene is built and changed through its parts and its own fields only: K is
``scene.acquisition.ramps``, one spelling. The flat table is the file format:
:meth:`SceneConfig.to_dict` writes it (the ``scene`` of a campaign's or a chain path's
settings, as campaign files store it, with K as ``n_ramps``) and
:meth:`SceneConfig.from_dict` reads it; :data:`FLAT_ACQUISITION` and
:data:`FLAT_SPECIMENS` say which field of which part each of its keys names.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...radar import RadarConfig
from ..acquisition import PHASE_TREATMENTS, Acquisition
from ..specimens import SpecimenSpread

SCENE_PHASES = PHASE_TREATMENTS
SCENE_ACQUISITION = Acquisition.measured(4)
"""The default scene's acquisition: K = 4, uniform phases, yaw +-15 deg, body return
up to 0.3 sum(Gamma) (its fast-path fields, jitter, noise floor, MTI and drift, are
the measured preset's: they describe this scene to the fast path)."""

FLAT_ACQUISITION = {"n_ramps": "ramps", "phases": "phases", "yaw_deg": "yaw_deg", "body_ratio": "carrier"}
"""File-table key -> field of the scene's :class:`Acquisition`."""
FLAT_SPECIMENS = {"speed_spread": "speed", "frequency_spread": "frequency", "amplitude_spread": "amplitude",
                  "gamma_spread": "gamma", "skew_spread": "skew", "specimen_spread": "width"}
"""File-table key -> field of the scene's :class:`SpecimenSpread`."""
FLAT_KEYS = ("n_frames", "n_ramps", "n_antennas", "snr_db", "phases", "range_m", "azimuth_deg", "yaw_deg",
             "drift_step_m", "drift_shifts_range", "body_ratio", "n_clutter", "clutter_db", "clutter_range_m",
             "clutter_azimuth_deg", "quantise", "agc_fill", "speed_spread", "frequency_spread", "amplitude_spread",
             "gamma_spread", "skew_spread", "specimen_spread", "dtype")
"""The flat table's keys, in its order (:meth:`SceneConfig.to_dict`)."""
PAIRS = ("range_m", "azimuth_deg", "body_ratio", "clutter_db", "clutter_range_m", "clutter_azimuth_deg")


def _pair(v, name):
    lo, hi = (float(v[0]), float(v[1]))
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"SceneConfig.{name} must be a (low, high) pair with low <= high, got {v!r}")
    return (lo, hi)


def _check_flat(flat: dict) -> dict:
    """The flat settings checked (errors name the flat keyword); pairs as float tuples."""
    for name in PAIRS:
        flat[name] = _pair(flat[name], name)
    if flat["phases"] not in SCENE_PHASES:
        raise ValueError(f"SceneConfig.phases must be one of {SCENE_PHASES}, got {flat['phases']!r}")
    ints = {"n_ramps": 1, "n_clutter": 0}
    ints.update({k: lo for k, lo in (("n_frames", 2), ("n_antennas", 1)) if flat[k] is not None})
    for name, lo in ints.items():
        v = flat[name]
        if int(v) != v or v < lo:
            raise ValueError(f"SceneConfig.{name} must be an integer >= {lo}, got {v!r}")
    for name in ("yaw_deg", "drift_step_m", *FLAT_SPECIMENS):
        if not (np.isfinite(flat[name]) and flat[name] >= 0):
            raise ValueError(f"SceneConfig.{name} must be >= 0, got {flat[name]!r}")
    if not 0 < flat["agc_fill"] <= 1:
        raise ValueError(f"SceneConfig.agc_fill must be in (0, 1], got {flat['agc_fill']}")
    if flat["range_m"][0] <= 0 or flat["body_ratio"][0] < 0:
        raise ValueError("SceneConfig.range_m and body_ratio must be positive")
    return flat


@dataclass(frozen=True, init=False)
class SceneConfig:
    """Everything a simulated acquisition randomises, with the default scene's values.

    ``acquisition`` (ramps, phases, yaw, body return) and ``specimens`` (the specimen
    model) plus the scene's own fields below. Ranges are physical (= chain) metres,
    angles degrees, levels dB. A file's flat table builds one with :meth:`from_dict`.
    """

    acquisition: Acquisition = SCENE_ACQUISITION
    specimens: SpecimenSpread = SpecimenSpread()
    n_frames: int | None = None  # None: radar.mti_depth + 1 (one MTI frame)
    n_antennas: int | None = None  # None: radar.n_rx
    snr_db: float | None = 10.0
    range_m: tuple = (3.0, 8.0)
    azimuth_deg: tuple = (-30.0, 30.0)
    drift_step_m: float = 3e-3
    drift_shifts_range: bool = True
    n_clutter: int = 6
    clutter_db: tuple = (-10.0, 10.0)
    clutter_range_m: tuple = (0.5, 9.0)
    clutter_azimuth_deg: tuple = (-60.0, 60.0)
    quantise: bool = True
    agc_fill: float = 0.7
    dtype: str = "float32"

    def __init__(self, acquisition: Acquisition = SCENE_ACQUISITION, specimens: SpecimenSpread = SpecimenSpread(),
                 **kw):
        own = {f.name: f.default for f in dataclasses.fields(self)[2:]}
        unknown = sorted(set(kw) - set(own))
        if unknown:
            raise TypeError(f"SceneConfig() got unexpected keyword argument(s) {unknown} (K and the phases, yaw "
                            "and body return are the acquisition's fields, the spreads the specimens')")
        if not isinstance(acquisition, Acquisition):
            raise ValueError(f"SceneConfig.acquisition must be an Acquisition, got {type(acquisition).__name__}")
        if not isinstance(specimens, SpecimenSpread):
            raise ValueError(f"SceneConfig.specimens must be a SpecimenSpread, got {type(specimens).__name__}")
        parts = {**{k: getattr(acquisition, v) for k, v in FLAT_ACQUISITION.items()},
                 **{k: getattr(specimens, v) for k, v in FLAT_SPECIMENS.items()}}
        flat = _check_flat({**own, **parts, **kw})  # errors name the file table's keys
        object.__setattr__(self, "acquisition", acquisition)
        object.__setattr__(self, "specimens", specimens)
        for name in own:
            object.__setattr__(self, name, flat[name])

    def frames(self, radar: RadarConfig) -> int:
        return radar.mti_depth + 1 if self.n_frames is None else int(self.n_frames)

    def antennas(self, radar: RadarConfig) -> int:
        return radar.n_rx if self.n_antennas is None else int(self.n_antennas)

    def acquisition_for(self, radar: RadarConfig = RadarConfig()) -> Acquisition:
        """The acquisition the scene's profiles are measured under (what a campaign file
        states): the scene's, its MTI over ``radar.mti_depth`` frames."""
        return self.acquisition.replace(mti_depth=radar.mti_depth)

    def replace(self, **changes) -> "SceneConfig":
        """A copy with fields changed: the parts or the scene's own fields."""
        own = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return SceneConfig(**{**own, **changes})

    def with_acquisition(self, **changes) -> "SceneConfig":
        """A copy with fields of its acquisition changed (e.g. ``ramps=K``)."""
        return self.replace(acquisition=self.acquisition.replace(**changes))

    def with_specimens(self, **changes) -> "SceneConfig":
        """A copy with fields of its specimen model changed (e.g. ``width=0.0``)."""
        return self.replace(specimens=self.specimens.replace(**changes))

    def to_dict(self) -> dict:
        """The flat table of files (:data:`FLAT_KEYS`, module doc)."""
        parts = {**{k: getattr(self.acquisition, v) for k, v in FLAT_ACQUISITION.items()},
                 **{k: getattr(self.specimens, v) for k, v in FLAT_SPECIMENS.items()}}
        return {k: parts[k] if k in parts else getattr(self, k) for k in FLAT_KEYS}

    @classmethod
    def from_dict(cls, flat: dict, acquisition: Acquisition = SCENE_ACQUISITION) -> "SceneConfig":
        """The scene a file's flat table states (keys of :data:`FLAT_KEYS`; those left
        out keep the default scene's values, the acquisition's other fields
        ``acquisition``'s); lists read as pairs. An unknown key is refused by name."""
        flat = {k: (tuple(v) if isinstance(v, list) else v) for k, v in flat.items()}
        unknown = sorted(set(flat) - set(FLAT_KEYS))
        if unknown:
            raise ValueError(f"scene settings: unknown key(s) {unknown}; expected some of {list(FLAT_KEYS)}")
        _check_flat({**cls(acquisition=acquisition).to_dict(), **flat})  # errors name the table's keys
        acq = {v: flat.pop(k) for k, v in FLAT_ACQUISITION.items() if k in flat}
        spec = {v: flat.pop(k) for k, v in FLAT_SPECIMENS.items() if k in flat}
        return cls(acquisition=acquisition.replace(**acq), specimens=SpecimenSpread().replace(**spec), **flat)

    @classmethod
    def clean(cls, acquisition: Acquisition = SCENE_ACQUISITION, **changes) -> "SceneConfig":
        """A noise-, clutter-, body-, yaw- and quantisation-free scene (for checks)."""
        base = dict(snr_db=None, n_clutter=0, quantise=False)
        return cls(acquisition=acquisition.replace(carrier=(0.0, 0.0), yaw_deg=0.0), **{**base, **changes})
