"""The fast classifiers of the published protocol: SVM, Gaussian naive Bayes, XGBoost.

All share :class:`~mdaug.classify.base.ProfileClassifier` (raw profiles in, the
classifier's own normalisation applied, input length and labels recorded).

SVM choice: ``kernel="rbf"`` (default) is scikit-learn's ``SVC()`` default, the most
likely published setting; it costs ~1 s at 4,000 x 400 and ~4 s at 8,000 x 400 on one
core here (~17 s at 16,000, super-linear). ``kernel="linear"`` uses ``LinearSVC``
(~1 s at 8,000, ~5 s at 32,000) for large sets. Scores: with ``probability=False``
(default, no 5-fold Platt fit) ``predict_proba`` is the softmax of the decision
scores: it ranks like the SVM and its argmax is the SVM's prediction, but it is
not a calibrated probability. ``probability=True`` adds Platt scaling
(``CalibratedClassifierCV(SVC, ensemble=False)``, 5-fold: ~5x slower fit).

XGBoost: ``tree_method="hist"`` with ``max_bin=64`` (2-3x faster than 256 bins at the
same synthetic-test accuracy here), 100 trees of depth 6, ``n_jobs=threads``.
"""
from __future__ import annotations

import numpy as np

from ..radar.seeds import child_seed
from .base import ProfileClassifier, softmax

SVM_KERNELS = ("rbf", "linear", "poly", "sigmoid")


class SVMClassifier(ProfileClassifier):
    name = "svm"

    def __init__(self, kernel: str = "rbf", C: float = 1.0, gamma="scale", probability: bool = False,
                 max_iter: int = -1, **kw):
        super().__init__(**kw)
        if kernel not in SVM_KERNELS:
            raise ValueError(f"svm kernel must be one of {SVM_KERNELS}, got {kernel!r}")
        self.kernel, self.C, self.gamma = kernel, float(C), gamma
        self.probability, self.max_iter = bool(probability), int(max_iter)
        self.estimator_ = None

    def params(self) -> dict:
        return {**super().params(), "kernel": self.kernel, "C": self.C, "gamma": self.gamma,
                "probability": self.probability, "max_iter": self.max_iter}

    def _fit(self, X, yi):
        seed = child_seed(self.random_state, 1)
        if self.kernel == "linear" and not self.probability:
            from sklearn.svm import LinearSVC

            self.estimator_ = LinearSVC(C=self.C, random_state=seed,
                                        max_iter=self.max_iter if self.max_iter > 0 else 2000)
        else:
            from sklearn.svm import SVC

            self.estimator_ = SVC(kernel=self.kernel, C=self.C, gamma=self.gamma, random_state=seed,
                                  max_iter=self.max_iter)
            if self.probability:  # Platt scaling, SVC(probability=True) being deprecated
                from sklearn.calibration import CalibratedClassifierCV

                self.estimator_ = CalibratedClassifierCV(self.estimator_, method="sigmoid", ensemble=False)
        self.estimator_.fit(X, yi)

    def _proba(self, X):
        if self.probability:
            return self.estimator_.predict_proba(X)
        d = np.asarray(self.estimator_.decision_function(X), dtype=np.float64)
        if d.ndim == 1:  # binary: score > 0 means the second class
            d = np.stack([-0.5 * d, 0.5 * d], axis=1)
        return softmax(d)

    def predict(self, X):
        x = self._prepare(X)
        return self.classes_[self.estimator_.predict(x)]


class NaiveBayesClassifier(ProfileClassifier):
    """Gaussian naive Bayes (scikit-learn ``GaussianNB``)."""

    name = "nb"

    def __init__(self, var_smoothing: float = 1e-9, **kw):
        super().__init__(**kw)
        self.var_smoothing = float(var_smoothing)
        self.estimator_ = None

    def params(self) -> dict:
        return {**super().params(), "var_smoothing": self.var_smoothing}

    def _fit(self, X, yi):
        from sklearn.naive_bayes import GaussianNB

        self.estimator_ = GaussianNB(var_smoothing=self.var_smoothing).fit(X, yi)

    def _proba(self, X):
        return self.estimator_.predict_proba(X)


class XGBClassifierWrapper(ProfileClassifier):
    """XGBoost gradient-boosted trees (``xgboost.XGBClassifier``, hist method)."""

    name = "xgb"

    def __init__(self, n_estimators: int = 100, max_depth: int = 6, learning_rate: float = 0.3,
                 max_bin: int = 64, subsample: float = 1.0, **kw):
        super().__init__(**kw)
        self.n_estimators, self.max_depth = int(n_estimators), int(max_depth)
        self.learning_rate, self.max_bin, self.subsample = float(learning_rate), int(max_bin), float(subsample)
        self.estimator_ = None

    def params(self) -> dict:
        return {**super().params(), "n_estimators": self.n_estimators, "max_depth": self.max_depth,
                "learning_rate": self.learning_rate, "max_bin": self.max_bin, "subsample": self.subsample}

    def new_estimator(self):
        from xgboost import XGBClassifier

        return XGBClassifier(n_estimators=self.n_estimators, max_depth=self.max_depth,
                             learning_rate=self.learning_rate, max_bin=self.max_bin,
                             subsample=self.subsample, tree_method="hist", n_jobs=self.threads,
                             random_state=child_seed(self.random_state, 2), verbosity=0)

    def _fit(self, X, yi):
        self.estimator_ = self.new_estimator().fit(X, yi)

    def _proba(self, X):
        return self.estimator_.predict_proba(X)


def _cnn_class():
    from .cnn import CNNClassifier

    return CNNClassifier


CLASSIFIERS = {"svm": lambda: SVMClassifier, "nb": lambda: NaiveBayesClassifier,
               "xgb": lambda: XGBClassifierWrapper, "cnn": _cnn_class}
"""Names accepted by :func:`make_classifier` (the CNN pulls in torch only when asked)."""


def classifier_class(name: str):
    if name not in CLASSIFIERS:
        raise ValueError(f"unknown classifier {name!r}; expected one of {tuple(CLASSIFIERS)}")
    return CLASSIFIERS[name]()


def make_classifier(name: str, random_state=None, **params) -> ProfileClassifier:
    """A fresh classifier ``name`` in ("svm", "nb", "xgb", "cnn").

    Common params: ``normalisation`` ("peak"), ``threads`` (1). Others per class
    (SVM: kernel, C, gamma, probability; NB: var_smoothing; XGB: n_estimators,
    max_depth, learning_rate, max_bin; CNN: epochs, batch_size, patience, ...).
    """
    return classifier_class(name)(random_state=random_state, **params)
