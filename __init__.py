"""mdaug: model-based, uncertainty-aware augmentation of radar micro-Doppler data.

Subpackages, lowest first (imports only point down):

- ``mdaug.radar``: the radar config object, the FMCW processing chain, profile I/O;
- ``mdaug.generator``: the vibration model, f(x), augmenters and the scene simulator;
- ``mdaug.inference``: likelihood, priors, nlopt fit, emcee posterior;
- ``mdaug.classify``: classifiers, metrics, the sigma_P protocol, the tsaug baseline;
- ``mdaug.strategies``: the strategy registry (name -> how its training set is made);
- ``mdaug.reports``: the study and its report;
- ``mdaug.cli``: the ``mdaug`` command (one module per group of verbs), on top.
"""
from .radar.version import package_version as _package_version

__version__ = _package_version()
