"""The conventional augmentation baseline: tsaug on the few measured profiles, then the CNN.

The published choice is drift + pool + reverse (all keep the 400-sample length); the
paper gives no parameters, so ours are stated in :class:`TsaugSettings` (tsaug's own
README values for drift and reverse, tsaug's default pool).

tsaug draws from a fixed seed identically on every call, so each
:meth:`TsaugAugmenter.sample` call builds its pipeline with fresh seeds derived from
the user's seed and a call counter: repeated calls differ, the same user seed
replays the same sequence.

Leakage: augment only inside training folds. :func:`tsaug_baseline` augments exactly
the profiles it is given (the caller's training fold), and the CNN's internal
80/10/10 split is made by *source profile* (all augmented copies of one measured
profile land in one split). :func:`tsaug_cross_validate` does the whole k-fold
protocol on a measured set: no augmented copy of a test profile reaches training.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

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


class TsaugAugmenter:
    """Balanced tsaug augmentation of measured profiles (N, L) with labels (N,).

    ``sample(n_per_class)`` returns ``(X (n_per_class * n_classes, L) float32, y)``;
    every source profile of a class is used about equally often (round-robin over a
    fresh permutation). Profiles are normalised with ``normalisation`` before
    augmentation so measured profiles of different amplitude are treated alike.
    """

    def __init__(self, profiles, labels, random_state=None, settings: TsaugSettings = TsaugSettings(),
                 normalisation: str = "peak"):
        self.profiles = preprocess(as_profiles(profiles, "tsaug source profiles"), normalisation)
        self.labels = np.asarray(labels).astype(str).ravel()
        if self.labels.size != self.profiles.shape[0]:
            raise ValueError(f"{self.profiles.shape[0]} profiles but {self.labels.size} labels")
        self.classes = np.unique(self.labels)
        self.settings = settings
        self.normalisation = normalisation
        self._seq = np.random.SeedSequence(random_state)
        self.last_sources_: np.ndarray | None = None

    def _pipeline(self, seeds):
        from tsaug import Drift, Pool, Reverse

        s = self.settings
        return (Drift(max_drift=s.max_drift, n_drift_points=s.n_drift_points, seed=int(seeds[0])) @ s.drift_prob
                + Pool(size=s.pool_size, seed=int(seeds[1]))
                + Reverse(seed=int(seeds[2])) @ s.reverse_prob)

    def sample(self, n_per_class: int, return_sources: bool = False):
        """Augmented profiles (n_per_class per class) and their labels; with
        ``return_sources`` also the index (into the given profiles) of each one's source."""
        if isinstance(n_per_class, bool) or int(n_per_class) != n_per_class or n_per_class <= 0:
            raise ValueError(f"n_per_class must be a positive integer, got {n_per_class!r}")
        child = self._seq.spawn(1)[0]  # fresh per call: tsaug repeats itself under a fixed seed
        rng = np.random.default_rng(child)
        sources = np.concatenate([
            np.resize(rng.permutation(np.flatnonzero(self.labels == c)), int(n_per_class)) for c in self.classes])
        seeds = rng.integers(0, 2**31 - 1, size=3)
        x = self._pipeline(seeds).augment(self.profiles[sources].astype(np.float64)).astype(np.float32)
        self.last_sources_ = sources
        out = (x, self.labels[sources])
        return out + (sources,) if return_sources else out

    def settings_dict(self) -> dict:
        return {"strategy": "tsaug", **asdict(self.settings), "normalisation": self.normalisation}


def tsaug_baseline(train_profiles, train_labels, n_per_class: int = 16000, random_state=None,
                   epochs: int = 100, settings: TsaugSettings = TsaugSettings(), **cnn_params):
    """The published conventional baseline: tsaug-augment the *training* measured
    profiles to ``n_per_class`` per class and train the CNN (100 epochs as published).

    The CNN's 80/10/10 split is grouped by source profile. Returns the fitted
    :class:`~mdaug.classify.cnn.CNNClassifier` (``augmenter_settings_`` records tsaug's).
    """
    from .cnn import CNNClassifier

    seed = np.random.SeedSequence(random_state)
    aug_seed, cnn_seed = (int(s.generate_state(1)[0]) for s in seed.spawn(2))
    aug = TsaugAugmenter(train_profiles, train_labels, random_state=aug_seed, settings=settings,
                         normalisation=cnn_params.get("normalisation", "peak"))
    x, y, sources = aug.sample(n_per_class, return_sources=True)
    model = CNNClassifier(epochs=epochs, random_state=cnn_seed, **cnn_params)
    model.fit(x, y, groups=sources)
    model.augmenter_settings_ = aug.settings_dict()
    return model


def tsaug_cross_validate(profiles, labels, n_splits: int = 5, n_per_class: int = 4000, random_state=0,
                         epochs: int = 100, **kw) -> tuple[np.ndarray, np.ndarray]:
    """Stratified k-fold on a measured set: each fold's training profiles are augmented
    and a CNN trained on them predicts the held-out fold. Returns out-of-fold
    predictions (N,) and fold ids (N,); score them with :func:`evaluate`."""
    from sklearn.model_selection import StratifiedKFold

    x = as_profiles(profiles, "measured profiles")
    y = np.asarray(labels).astype(str).ravel()
    folds = StratifiedKFold(n_splits=n_splits, shuffle=True,
                            random_state=int(np.random.SeedSequence(random_state).generate_state(1)[0] >> 1))
    pred = np.empty(y.size, dtype=y.dtype)
    fold_id = np.empty(y.size, dtype=np.int64)
    for k, (tr, te) in enumerate(folds.split(x, y)):
        seed = np.random.SeedSequence(random_state, spawn_key=(k,))
        model = tsaug_baseline(x[tr], y[tr], n_per_class, int(seed.generate_state(1)[0]), epochs=epochs, **kw)
        pred[te] = model.predict(x[te])
        fold_id[te] = k
    return pred, fold_id
