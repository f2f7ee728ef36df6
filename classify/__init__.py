"""Classifiers on range-profile arrays, the published sigma_P protocol, the tsaug
baseline and honest metrics.

Imports only :mod:`mdaug.radar` (normalisation, I/O, progress); the synthetic sets
of ``mdaug sweep`` are built by the command line (:mod:`mdaug.cli.classify`) with
mdaug.generator. torch loads only when the CNN is used.
"""
from .base import ProfileClassifier
from .metrics import evaluate, format_metrics, plot_confusion
from .models import (CLASSIFIERS, NaiveBayesClassifier, SVMClassifier, XGBClassifierWrapper,
                     make_classifier)
from .persist import load_model, save_model
from .preprocess import preprocess
from .protocol import FAST_MODELS, PUBLISHED_SIGMA_PS, SweepResult, sigma_p_sweep
from .tsaug_baseline import TsaugAugmenter, TsaugSettings, tsaug_baseline, tsaug_cross_validate, tsaug_set

__all__ = [
    "ProfileClassifier", "evaluate", "format_metrics", "plot_confusion", "CLASSIFIERS",
    "NaiveBayesClassifier", "SVMClassifier", "XGBClassifierWrapper", "make_classifier",
    "load_model", "save_model", "preprocess", "FAST_MODELS", "PUBLISHED_SIGMA_PS", "SweepResult",
    "sigma_p_sweep", "TsaugAugmenter", "TsaugSettings", "tsaug_baseline", "tsaug_cross_validate", "tsaug_set",
    "CNNClassifier",
]


def __getattr__(name):  # the CNN (and torch) only on demand
    if name == "CNNClassifier":
        from .cnn import CNNClassifier

        return CNNClassifier
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
