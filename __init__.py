"""mdaug: model-based, uncertainty-aware augmentation of radar micro-Doppler data.

Subpackages, lowest first (imports only point down):

- ``mdaug.radar``: the radar config object, the FMCW processing chain, profile I/O;
- ``mdaug.generator``: the vibration model, f(x), augmenters and the scene simulator;
- ``mdaug.inference``: likelihood, priors, nlopt fit, emcee posterior;
- ``mdaug.classify``: classifiers, metrics, the sigma_P protocol, the tsaug baseline;
- ``mdaug.reports``: the study and its report.
"""
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("mdaug")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
