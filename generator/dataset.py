"""Synthetic datasets: profiles, labels, the vectors that made them, and the settings.

NPZ layout (loads with ``allow_pickle=False``):

* ``profiles`` (N, L) float32, ``labels`` (N,) fixed-width unicode;
* ``params_<LABEL>`` (n_label, 13 E) the vectors of each class where the augmenter
  has them (not for tsaug), and ``param_row`` (N,) the row of each profile in its
  class's array (-1 without vectors);
* ``settings``: a JSON string (strategy, sigma_P, seed, radar config, the
  acquisition, normalisation, package version, ...); ``acquisition`` (JSON) and
  ``ramps_per_frame`` when the augmenters share one acquisition, so the file states
  how its profiles were made (:func:`mdaug.generator.acquisition.acquisition_from_file`).

The same file is a valid measured-profile file (``profiles`` + ``labels``), so the
classifiers and the calibration read both through :func:`mdaug.radar.load_profiles`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..radar import DataFileError, ProfileSet, RadarConfig, atomic_savez, load_profiles, package_version
from ..radar.seeds import rng as as_generator
from .augment import Augmenter


@dataclass
class SyntheticDataset:
    profiles: np.ndarray
    labels: np.ndarray
    params: dict[str, np.ndarray]
    param_row: np.ndarray
    settings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def acquisition(self):
        """The acquisition the profiles were made under (None when the classes differ)."""
        from .acquisition import Acquisition

        d = self.settings.get("acquisition")
        return None if d is None else Acquisition.from_dict(d, "dataset settings")


def _item(a) -> int:
    renderer = getattr(a, "renderer", None)
    return np.dtype(renderer.dtype if renderer is not None else "float32").itemsize


def dataset_nbytes(augmenters: list[Augmenter], n_per_class: int) -> tuple[int, int]:
    """(bytes, bytes per profile of every class): the peak memory of
    :func:`make_dataset` (each class's batch plus the concatenated dataset)."""
    per = 0
    width = max(len(a.label) for a in augmenters)
    length = RadarConfig().slice_length
    for a in augmenters:
        per += 2 * length * _item(a) + 2 * (13 * getattr(a, "n_engines", 4) + 2) * 8 + 4 * width + 8
    return int(per) * int(n_per_class), int(per)


def check_dataset_memory(augmenters: list[Augmenter], n_per_class: int, what: str = "n_per_class") -> None:
    """Refuse (ValueError naming ``what``) a dataset larger than the available memory."""
    from ..radar.memory import check_memory

    nbytes, per = dataset_nbytes(augmenters, n_per_class)
    check_memory(nbytes, f"{what} {n_per_class:,}: {len(augmenters)} class(es) x {n_per_class:,} profiles "
                         f"x {RadarConfig().slice_length} bins", per, "per class")


def make_dataset(augmenters: list[Augmenter], n_per_class: int, seed,
                 progress: bool | None = None, extra_settings: dict | None = None) -> SyntheticDataset:
    """The toolkit's one training-set builder: n_per_class profiles from each augmenter
    (one per class), class by class, each class from its own child stream of the one
    ``seed`` (so a class's profiles do not depend on the others).

    Refuses (ValueError) a dataset that would not fit in the available memory."""
    labels = [a.label for a in augmenters]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two augmenters share a class label: {labels}")
    if isinstance(n_per_class, bool) or not isinstance(n_per_class, (int, np.integer)) or n_per_class <= 0:
        raise ValueError(f"n_per_class must be a positive integer, got {n_per_class!r}")
    check_dataset_memory(augmenters, n_per_class)
    parts = [a.sample(n_per_class, as_generator(seed, "class", a.label), progress=progress)
             for a in augmenters]
    settings = {
        "seed": seed if not isinstance(seed, np.random.SeedSequence) else str(seed.entropy),
        "n_per_class": int(n_per_class), "classes": labels,
        "radar": RadarConfig().to_dict(), "package_version": package_version(), "simulated": True,
        "per_class": {a.label: p.settings for a, p in zip(augmenters, parts)},
        **(extra_settings or {}),
    }
    first = parts[0].settings
    for key in ("strategy", "sigma_p", "normalisation", "acquisition"):
        if key in first and all(p.settings.get(key) == first[key] for p in parts):
            settings.setdefault(key, first[key])
    width = max(len(lab) for lab in labels)
    have = all(p.params is not None for p in parts)
    return SyntheticDataset(
        profiles=np.concatenate([p.profiles for p in parts]),
        labels=np.repeat(np.array(labels, dtype=f"<U{width}"), n_per_class),
        params={lab: p.params for lab, p in zip(labels, parts)} if have else {},
        param_row=np.tile(np.arange(n_per_class), len(labels)) if have else np.full(len(labels) * n_per_class, -1),
        settings=settings,
    )


def save_dataset(path, ds: SyntheticDataset):
    """Write ``ds`` to ``path`` (NPZ) atomically."""
    arrays = {"profiles": ds.profiles, "labels": ds.labels,
              "param_row": ds.param_row, "settings": np.array(json.dumps(ds.settings))}
    arrays.update({f"params_{lab}": p for lab, p in ds.params.items()})
    if ds.settings.get("acquisition") is not None:
        arrays["acquisition"] = np.array(json.dumps(ds.settings["acquisition"]))
        arrays["ramps_per_frame"] = np.array(int(ds.settings["acquisition"]["ramps"]))
    return atomic_savez(path, **arrays)


def load_dataset(path) -> SyntheticDataset:
    """Read a dataset written by :func:`save_dataset` (errors name the file and field)."""
    ps: ProfileSet = load_profiles(path)
    for key in ("param_row", "settings"):
        if key not in ps.extra:
            raise DataFileError(f"{path}: missing field {key!r}; not an mdaug synthetic dataset")
    params = {k[len("params_"):]: v for k, v in ps.extra.items() if k.startswith("params_")}
    missing = sorted(set(ps.labels.tolist()) - set(params))
    if params and missing:
        raise DataFileError(f"{path}: missing field(s) {['params_' + m for m in missing]}")
    return SyntheticDataset(profiles=ps.profiles.astype(np.float32), labels=ps.labels, params=params,
                            param_row=ps.extra["param_row"], settings=ps.settings())
