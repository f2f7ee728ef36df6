"""Calibration with uncertainty: measured profiles -> posterior over a class vector.

Rooms, by role: :mod:`.likelihood` (the likelihoods over one base, and the preparation
of measured profiles); :mod:`.space` (priors and the layouts of theta);
:mod:`.samplers` (the sampler registry over its plugins emcee, SMC and Laplace, their
interface and shared toolbox); :mod:`.amortized` (trained estimators, the default
for measured acquisitions); :mod:`.result` (the posterior as arviz InferenceData in
NetCDF, its plots, report and augmenter); :mod:`.population` (the class as a
population of drones); :mod:`.diagnostics` (simulation-based calibration). At the
top: :mod:`.calibrate` (one drone -> a result), :mod:`.fit` (the multi-start nlopt
fit), :mod:`.compare` (engine-count selection), :mod:`.estimator_job` (training an
estimator: simulations, networks, its SBC) and :mod:`.settings`. Imports
:mod:`mdaug.generator` and :mod:`mdaug.radar` only.
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
