"""The one interface of every classifier: fit / predict / predict_proba on raw profiles.

A :class:`ProfileClassifier` applies :func:`~mdaug.classify.preprocess.preprocess`
itself with its ``normalisation`` and records what it was trained with (input
length, normalisation, class labels), so a model cannot silently be applied to
profiles of another length or scored against labels it never saw.
"""
from __future__ import annotations

import numpy as np

from ..radar import check_normalisation
from .preprocess import as_profiles, preprocess


DEVICES = ("auto", "cpu", "cuda")
PRECISIONS = ("auto", "float32", "bfloat16")  # the CNN's forward passes: classify.cnn.resolve_precision
"""Where the torch models run: "auto" (a CUDA GPU when torch sees one, else the CPU)."""


class ProfileClassifier:
    """Base class. Subclasses set ``name`` and implement ``_fit(X, yi)`` and
    ``_proba(X)`` on preprocessed float32 (N, L) profiles and integer labels
    (indices into ``classes_``), plus ``params()`` (constructor arguments)."""

    name = "base"

    def __init__(self, normalisation: str = "peak", random_state=None, threads: int = 1):
        self.normalisation = check_normalisation(normalisation)
        self.random_state = random_state
        if int(threads) < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        self.threads = int(threads)
        self.classes_: np.ndarray | None = None
        self.n_features_in_: int | None = None
        self.train_seconds_: float | None = None

    # -- interface -------------------------------------------------------------------
    def params(self) -> dict:
        return {"normalisation": self.normalisation, "random_state": self.random_state,
                "threads": self.threads}

    def fit(self, X, y, **kw):
        """Train on profiles X (N, L) with labels y (N,) (strings)."""
        import time

        x = as_profiles(X)
        y = np.asarray(y).astype(str).ravel()
        if y.size != x.shape[0]:
            raise ValueError(f"{x.shape[0]} profiles but {y.size} labels")
        self.classes_, yi = np.unique(y, return_inverse=True)
        if self.classes_.size < 2:
            raise ValueError(f"training needs at least 2 classes, got {self.classes_.tolist()}")
        self.n_features_in_ = int(x.shape[1])
        t0 = time.perf_counter()
        self._fit(preprocess(x, self.normalisation), yi.astype(np.int64), **kw)
        self.train_seconds_ = time.perf_counter() - t0
        return self

    def predict_proba(self, X) -> np.ndarray:
        """Class scores (N, n_classes) in ``classes_`` order (rows sum to 1)."""
        return self._proba(self._prepare(X))

    def predict(self, X) -> np.ndarray:
        """Predicted labels (N,) (strings from ``classes_``)."""
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]

    def score(self, X, y) -> float:
        return float(np.mean(self.predict(X) == np.asarray(y).astype(str)))

    # -- checks ----------------------------------------------------------------------
    def check_fitted(self) -> None:
        if self.classes_ is None:
            raise ValueError(f"this {self.name} classifier is not trained yet; call fit() first")

    def check_input(self, X, source: str = "profiles") -> np.ndarray:
        """Raise a clear error when X's profile length differs from training."""
        self.check_fitted()
        x = as_profiles(X, what=source)
        if x.shape[1] != self.n_features_in_:
            raise ValueError(f"{source}: profiles have {x.shape[1]} bins but this {self.name} model "
                             f"was trained on {self.n_features_in_}-bin profiles")
        return x

    def check_labels(self, y, source: str = "labels") -> np.ndarray:
        """Raise a clear error when y holds labels the model was not trained on."""
        self.check_fitted()
        y = np.asarray(y).astype(str).ravel()
        unknown = sorted(set(y.tolist()) - set(self.classes_.tolist()))
        if unknown:
            raise ValueError(f"{source}: labels {unknown} are unknown to this {self.name} model "
                             f"(trained on {self.classes_.tolist()})")
        return y

    def _prepare(self, X) -> np.ndarray:
        return preprocess(self.check_input(X), self.normalisation)

    def _fit(self, X: np.ndarray, yi: np.ndarray, **kw) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _proba(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"


def softmax(scores: np.ndarray) -> np.ndarray:
    z = scores - scores.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)
