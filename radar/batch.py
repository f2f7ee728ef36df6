"""The one augmenter interface, in the bottom layer so that every augmenter shares it:
the model-based ones (:mod:`mdaug.generator.augment`, :mod:`mdaug.inference`) and
the data-space tsaug baseline (:mod:`mdaug.classify.tsaug_baseline`), which works
on arrays and imports nothing above :mod:`mdaug.radar`.

An augmenter has a class ``label`` and ``sample(n, rng=None) -> AugmentedBatch``;
:func:`mdaug.generator.make_dataset` builds a training set from one per class.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np


@dataclass
class AugmentedBatch:
    """profiles (n, L); labels (n,); params (n, 13E) the class vectors that made them
    (None for data-space augmenters such as tsaug); settings: how they were made;
    sources (n,) for data-space augmenters, the index of each profile's source
    measurement (None otherwise)."""

    profiles: np.ndarray
    labels: np.ndarray
    params: np.ndarray | None = None
    settings: dict = field(default_factory=dict)
    sources: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.labels)


class Augmenter(ABC):
    """One interface for every augmenter: ``sample(n, rng) -> AugmentedBatch``."""

    label: str

    @abstractmethod
    def sample(self, n: int, rng=None, **kw) -> AugmentedBatch: ...

    def settings(self) -> dict:
        return {}
