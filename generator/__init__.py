"""The physical vibration model, the generator f(x) and model-based augmenters.

Imports only :mod:`mdaug.radar` below it.
"""
from .augment import (AugmentedBatch, FixedParamsAugmenter, ModelAugmenter, Nuisance,
                      PHASE_TREATMENTS, SIGN_POLICIES, SigmaPAugmenter, as_generator)
from .dataset import SyntheticDataset, load_dataset, make_dataset, save_dataset
from .model import if_signal, magnitude_spectra, profiles, spectra, vibration_terms
from .params import (IDX, N_PARAMS, PARAM_NAMES, ClassParams, Engine, load_reference,
                     param_labels, reference_classes, validate_vectors)

__all__ = [
    "AugmentedBatch", "FixedParamsAugmenter", "ModelAugmenter", "Nuisance", "PHASE_TREATMENTS",
    "SIGN_POLICIES", "SigmaPAugmenter", "as_generator", "SyntheticDataset", "load_dataset",
    "make_dataset", "save_dataset", "if_signal", "magnitude_spectra", "profiles", "spectra",
    "vibration_terms", "IDX", "N_PARAMS", "PARAM_NAMES", "ClassParams", "Engine",
    "load_reference", "param_labels", "reference_classes", "validate_vectors",
]
