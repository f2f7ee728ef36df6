"""Simulated measurement campaigns: one class's specimens and acquisitions through the
scene simulator (:mod:`.scene`) and the published chain, and their files."""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ...radar import DataFileError, ProfileSet, RadarConfig, atomic_savez, read_arrays
from ...radar.chain import ChainConfig
from ...radar.seeds import rng as as_generator
from ...radar.seeds import seed_sequence
from ..params import ClassParams, load_reference
from .config import SceneConfig
from .scene import draw_acquisitions, draw_specimens, literal_chain, true_vectors


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
        """The acquisition of the campaign's profiles (:meth:`SceneConfig.acquisition_for`)."""
        scene = SceneConfig.from_dict(self.settings.get("scene", {}))
        radar = RadarConfig.from_dict(self.settings["radar"]) if "radar" in self.settings else RadarConfig()
        return scene.acquisition_for(radar)

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
