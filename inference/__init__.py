"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

The amortized calibration (:mod:`.amortized`: trained estimators, the default for
measured acquisitions); the closed-form likelihood route: nlopt global fit, emcee
posterior (resumable, HDF5), engine-count selection; arviz InferenceData (NetCDF),
corner and trace plots, posterior augmentation, the population of drones.
Imports :mod:`mdaug.generator` and :mod:`mdaug.radar` only.
"""
from .calibrate import calibrate
from .closed_form import ClosedFormLikelihood
from .likelihood import LogPosterior, prepare_measured
from .posterior_augment import PosteriorAugmenter, PosteriorSource
from .layout import Layout
from .line_layout import LineLayout
from .priors import Priors
from .result import CalibrationResult
from .settings import CalibrationSettings
from .synthetic import SyntheticLikelihood

__all__ = ["CalibrationResult", "CalibrationSettings", "ClosedFormLikelihood", "Layout", "LineLayout", "LogPosterior", "PosteriorAugmenter", "PosteriorSource", "SyntheticLikelihood", "Priors",
           "calibrate", "prepare_measured"]
