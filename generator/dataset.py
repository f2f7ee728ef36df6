"""Synthetic datasets: profiles, labels, the vectors that made them, and the settings.

NPZ layout (loads with ``allow_pickle=False``):

* ``profiles`` (N, L) float32, ``labels`` (N,) fixed-width unicode, ``r0`` (N,) m;
* ``params_<LABEL>`` (n_label, 13 E) the vectors of each class, and ``param_row``
  (N,) the row of each profile in its class's array;
* ``settings``: a JSON string (strategy, sigma_P, seed, radar config,
  normalisation, nuisances, package version, ...).

The same file is a valid measured-profile file (``profiles`` + ``labels``), so the
classifiers and the calibration read both through :func:`mdaug.radar.load_profiles`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from .. import __version__
from ..radar import DataFileError, ProfileSet, atomic_savez, load_profiles
from .augment import ModelAugmenter


@dataclass
class SyntheticDataset:
    profiles: np.ndarray
    labels: np.ndarray
    r0: np.ndarray
    params: dict[str, np.ndarray]
    param_row: np.ndarray
    settings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.labels)


def class_streams(seed, labels) -> dict[str, np.random.Generator]:
    """One independent generator per class, all derived from the user's one seed."""
    children = np.random.SeedSequence(seed).spawn(len(labels))
    return {lab: np.random.default_rng(ch) for lab, ch in zip(labels, children)}


def make_dataset(augmenters: list[ModelAugmenter], n_per_class: int, seed: int,
                 progress: bool | None = None, extra_settings: dict | None = None) -> SyntheticDataset:
    """n_per_class profiles from each augmenter, class by class, from one seed."""
    labels = [a.label for a in augmenters]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two augmenters share a class label: {labels}")
    streams = class_streams(seed, labels)
    parts = [a.sample(n_per_class, streams[a.label], progress=progress) for a in augmenters]
    radar = augmenters[0].radar
    settings = {
        "seed": seed, "n_per_class": n_per_class, "classes": labels,
        "radar": radar.to_dict(), "package_version": __version__, "simulated": True,
        "per_class": {a.label: a.settings() for a in augmenters},
        **(extra_settings or {}),
    }
    first = augmenters[0].settings()
    for key in ("strategy", "sigma_p", "normalisation", "nuisance"):
        if key in first:
            settings.setdefault(key, first[key])
    width = max(len(lab) for lab in labels)
    return SyntheticDataset(
        profiles=np.concatenate([p.profiles for p in parts]),
        labels=np.repeat(np.array(labels, dtype=f"<U{width}"), n_per_class),
        r0=np.concatenate([p.r0 for p in parts]),
        params={lab: p.params for lab, p in zip(labels, parts)},
        param_row=np.tile(np.arange(n_per_class), len(labels)),
        settings=settings,
    )


def save_dataset(path, ds: SyntheticDataset):
    """Write ``ds`` to ``path`` (NPZ) atomically."""
    arrays = {"profiles": ds.profiles, "labels": ds.labels, "r0": ds.r0,
              "param_row": ds.param_row, "settings": np.array(json.dumps(ds.settings))}
    arrays.update({f"params_{lab}": p for lab, p in ds.params.items()})
    return atomic_savez(path, **arrays)


def load_dataset(path) -> SyntheticDataset:
    """Read a dataset written by :func:`save_dataset` (errors name the file and field)."""
    ps: ProfileSet = load_profiles(path)
    for key in ("r0", "param_row", "settings"):
        if key not in ps.extra:
            raise DataFileError(f"{path}: missing field {key!r}; not an mdaug synthetic dataset")
    params = {k[len("params_"):]: v for k, v in ps.extra.items() if k.startswith("params_")}
    missing = sorted(set(ps.labels.tolist()) - set(params))
    if missing:
        raise DataFileError(f"{path}: missing field(s) {['params_' + m for m in missing]}")
    return SyntheticDataset(profiles=ps.profiles.astype(np.float32), labels=ps.labels, r0=ps.extra["r0"],
                            params=params, param_row=ps.extra["param_row"], settings=ps.settings())
