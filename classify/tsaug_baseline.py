"""The conventional augmentation baseline: tsaug on the few measured profiles, then the CNN.

The published choice is drift + pool + reverse (all keep the 400-sample length); the
paper gives no parameters, so ours are stated in :class:`TsaugSettings` (tsaug's own
README values for drift and reverse, tsaug's default pool).

tsaug draws from a fixed seed identically on every call, so each
:meth:`TsaugAugmenter.sample` call builds its pipeline with fresh seeds drawn from
the generator: repeated calls differ, the same user seed replays the same sequence.
:class:`TsaugAugmenter` has the toolkit's one augmenter interface
(:mod:`mdaug.radar.batch`), so a tsaug set feeds any classifier.

Leakage: augment only inside training folds. :func:`tsaug_baseline` augments exactly
the profiles it is given (the caller's training fold), and the CNN's internal
80/10/10 split is made by *source profile* (all augmented copies of one measured
profile land in one split). :func:`tsaug_cross_validate` does the whole k-fold
protocol on a measured set: no augmented copy of a test profile reaches training.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..radar.batch import AugmentedBatch, Augmenter
from ..radar.seeds import rng as rng_from
from ..radar.seeds import child_seed, seed_sequence
from .preprocess import as_profiles, preprocess


@dataclass(frozen=True)
class TsaugSettings:
    """tsaug parameters: Drift(max_drift, n_drift_points) @ drift_prob + Pool(size) +
    Reverse() @ reverse_prob. ``max_drift`` is relative to each profile's range
    (tsaug's ``normalize=True``)."""

    max_drift: tuple[float, float] = (0.1, 0.5)
    n_drift_points: int = 3
    drift_prob: float = 0.8
    pool_size: int = 2
    reverse_prob: float = 0.5


class TsaugAugmenter(Augmenter):
    """tsaug augmentation of the measured profiles of one class.

    profiles (N, L) and labels (N,) are the measurements; the augmenter keeps those of
    class ``label`` and ``sample(n, rng)`` returns an :class:`AugmentedBatch` of n
    augmented profiles (float32) of that class, ``sources`` the index (into the given
    profiles) of each one's source; every source is used about equally often
    (round-robin over a fresh permutation). Profiles are normalised with
    ``normalisation`` before augmentation so measurements of different amplitude are
    treated alike. tsaug draws identically under a fixed seed, so every call builds
    its pipeline with fresh seeds from the generator."""

    def __init__(self, profiles, labels, label: str, random_state=None, settings: TsaugSettings = TsaugSettings(),
                 normalisation: str = "peak"):
        x = preprocess(as_profiles(profiles, "tsaug source profiles"), normalisation)
        y = np.asarray(labels).astype(str).ravel()
        if y.size != x.shape[0]:
            raise ValueError(f"{x.shape[0]} profiles but {y.size} labels")
        self.label = str(label)
        self.rows = np.flatnonzero(y == self.label)
        if not self.rows.size:
            raise ValueError(f"no tsaug source profile of class {self.label!r} (classes: {sorted(set(y.tolist()))})")
        self.profiles = x
        self.tsaug = settings
        self.normalisation = normalisation
        self._rng = rng_from(random_state)

    def _pipeline(self, seeds):
        from tsaug import Drift, Pool, Reverse

        s = self.tsaug
        return (Drift(max_drift=s.max_drift, n_drift_points=s.n_drift_points, seed=int(seeds[0])) @ s.drift_prob
                + Pool(size=s.pool_size, seed=int(seeds[1]))
                + Reverse(seed=int(seeds[2])) @ s.reverse_prob)

    def sample(self, n: int, rng=None, **kw) -> AugmentedBatch:
        if isinstance(n, bool) or int(n) != n or n <= 0:
            raise ValueError(f"n (profiles to make) must be a positive integer, got {n!r}")
        rng = self._rng if rng is None else rng_from(rng)
        sources = np.resize(rng.permutation(self.rows), int(n))
        seeds = rng.integers(0, 2**31 - 1, size=3)
        x = self._pipeline(seeds).augment(self.profiles[sources].astype(np.float64)).astype(np.float32)
        return AugmentedBatch(profiles=x, labels=np.full(int(n), self.label), params=None,
                              settings=self.settings(), sources=sources)

    def settings(self) -> dict:
        return {"strategy": "tsaug", **asdict(self.tsaug), "normalisation": self.normalisation,
                "n_sources": int(self.rows.size)}


def tsaug_set(profiles, labels, n_per_class: int, random_state=None, settings: TsaugSettings = TsaugSettings(),
              normalisation: str = "peak"):
    """A balanced tsaug training set: (X (n_per_class x classes, L), y, sources) from one
    augmenter per class, each class from its own child stream of ``random_state``."""
    y = np.asarray(labels).astype(str).ravel()
    parts = [TsaugAugmenter(profiles, y, c, settings=settings, normalisation=normalisation).sample(
        n_per_class, rng_from(random_state, "tsaug", c)) for c in np.unique(y)]
    return (np.concatenate([p.profiles for p in parts]), np.concatenate([p.labels for p in parts]),
            np.concatenate([p.sources for p in parts]))


def tsaug_baseline(train_profiles, train_labels, n_per_class: int = 16000, random_state=None,
                   epochs: int = 100, settings: TsaugSettings = TsaugSettings(), **cnn_params):
    """The published conventional baseline: tsaug-augment the *training* measured
    profiles to ``n_per_class`` per class and train the CNN (100 epochs as published).

    The CNN's 80/10/10 split is grouped by source profile. Returns the fitted
    :class:`~mdaug.classify.cnn.CNNClassifier` (``augmenter_settings_`` records tsaug's).
    """
    from .cnn import CNNClassifier

    x, y, sources = tsaug_set(train_profiles, train_labels, n_per_class, seed_sequence(random_state, "augment"),
                              settings, cnn_params.get("normalisation", "peak"))
    model = CNNClassifier(epochs=epochs, random_state=int(seed_sequence(random_state, "cnn").generate_state(1)[0]),
                          **cnn_params)
    model.fit(x, y, groups=sources)
    model.augmenter_settings_ = {"strategy": "tsaug", **asdict(settings)}
    return model


def tsaug_cross_validate(profiles, labels, n_splits: int = 5, n_per_class: int = 4000, random_state=0,
                         epochs: int = 100, **kw) -> tuple[np.ndarray, np.ndarray]:
    """Stratified k-fold on a measured set: each fold's training profiles are augmented
    and a CNN trained on them predicts the held-out fold. Returns out-of-fold
    predictions (N,) and fold ids (N,); score them with :func:`evaluate`."""
    from sklearn.model_selection import StratifiedKFold

    x = as_profiles(profiles, "measured profiles")
    y = np.asarray(labels).astype(str).ravel()
    folds = StratifiedKFold(n_splits=n_splits, shuffle=True, random_state=child_seed(random_state, "folds"))
    pred = np.empty(y.size, dtype=y.dtype)
    fold_id = np.empty(y.size, dtype=np.int64)
    for k, (tr, te) in enumerate(folds.split(x, y)):
        model = tsaug_baseline(x[tr], y[tr], n_per_class, seed_sequence(random_state, "fold", k), epochs=epochs, **kw)
        pred[te] = model.predict(x[te])
        fold_id[te] = k
    return pred, fold_id
