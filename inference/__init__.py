"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

nlopt global fit, emcee posterior (resumable, HDF5), arviz InferenceData (NetCDF),
corner and trace plots, engine-count selection, posterior augmentation.
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
