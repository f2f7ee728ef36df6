"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

nlopt global fit, emcee posterior (resumable, HDF5), arviz InferenceData (NetCDF),
corner and trace plots, engine-count selection, posterior augmentation.
Imports :mod:`mdaug.generator` and :mod:`mdaug.radar` only.
"""
from .calibrate import calibrate
from .likelihood import LogPosterior, prepare_measured
from .posterior_augment import FitSigmaPAugmenter, PosteriorAugmenter, PosteriorSource
from .layout import Layout
from .priors import Priors
from .result import CalibrationResult
from .settings import CalibrationSettings
from .synthetic import SyntheticLikelihood

__all__ = ["CalibrationResult", "CalibrationSettings", "Layout", "LogPosterior", "PosteriorAugmenter", "PosteriorSource", "FitSigmaPAugmenter", "SyntheticLikelihood", "Priors",
           "calibrate", "prepare_measured"]
