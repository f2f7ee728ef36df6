"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

nlopt global fit, emcee posterior (resumable, HDF5), arviz InferenceData (NetCDF),
corner and trace plots, engine-count selection, posterior augmentation.
Imports :mod:`mdaug.generator` and :mod:`mdaug.radar` only.
"""
from .calibrate import calibrate
from .likelihood import LogPosterior, prepare_measured
from .posterior_augment import PosteriorAugmenter
from .priors import Layout, Priors
from .result import CalibrationResult
from .settings import CalibrationSettings

__all__ = ["CalibrationResult", "CalibrationSettings", "Layout", "LogPosterior", "PosteriorAugmenter", "Priors",
           "calibrate", "prepare_measured"]
