"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

The amortized calibration (:mod:`.amortized`: trained estimators, the default for
measured acquisitions); the closed-form likelihood route: nlopt global fit, emcee
posterior (resumable, HDF5), engine-count selection; arviz InferenceData (NetCDF),
corner and trace plots, posterior augmentation, the population of drones.
Imports :mod:`mdaug.generator` and :mod:`mdaug.radar` only.
"""
from .calibrate import calibrate
from .likelihood.closed_form import ClosedFormLikelihood
from .likelihood.base import prepare_measured
from .likelihood.fitted_phases import LogPosterior
from .result.augment import PosteriorAugmenter, PosteriorSource
from .space.layout import Layout
from .space.line_layout import LineLayout
from .space.priors import Priors
from .result.posterior import CalibrationResult
from .settings import CalibrationSettings
from .likelihood.synthetic import SyntheticLikelihood

__all__ = ["CalibrationResult", "CalibrationSettings", "ClosedFormLikelihood", "Layout", "LineLayout", "LogPosterior", "PosteriorAugmenter", "PosteriorSource", "SyntheticLikelihood", "Priors",
           "calibrate", "prepare_measured"]
