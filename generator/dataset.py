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

from ..radar import DataFileError, ProfileSet, atomic_savez, load_profiles, package_version
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


def dataset_nbytes(augmenters: list[ModelAugmenter], n_per_class: int) -> tuple[int, int]:
    """(bytes, bytes per profile of every class): the peak memory of
    :func:`make_dataset` (each class's batch plus the concatenated dataset)."""
    per = 0
    width = max(len(a.label) for a in augmenters)
    for a in augmenters:
        item = np.dtype(a.dtype).itemsize
        per += 2 * a.radar.slice_length * item + 2 * (13 * a.n_engines + 2) * 8 + 4 * width + 8
    return int(per) * int(n_per_class), int(per)


def check_dataset_memory(augmenters: list[ModelAugmenter], n_per_class: int, what: str = "n_per_class") -> None:
    """Refuse (ValueError naming ``what``) a dataset larger than the available memory."""
    from ..radar.memory import check_memory

    nbytes, per = dataset_nbytes(augmenters, n_per_class)
    check_memory(nbytes, f"{what} {n_per_class:,}: {len(augmenters)} class(es) x {n_per_class:,} profiles "
                         f"x {augmenters[0].radar.slice_length} bins", per, "per class")


def make_dataset(augmenters: list[ModelAugmenter], n_per_class: int, seed: int,
                 progress: bool | None = None, extra_settings: dict | None = None) -> SyntheticDataset:
    """n_per_class profiles from each augmenter, class by class, from one seed.

    Refuses (ValueError) a dataset that would not fit in the available memory."""
    labels = [a.label for a in augmenters]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two augmenters share a class label: {labels}")
    check_dataset_memory(augmenters, n_per_class)
    streams = class_streams(seed, labels)
    parts = [a.sample(n_per_class, streams[a.label], progress=progress) for a in augmenters]
    radar = augmenters[0].radar
    settings = {
        "seed": seed, "n_per_class": n_per_class, "classes": labels,
        "radar": radar.to_dict(), "package_version": package_version(), "simulated": True,
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
