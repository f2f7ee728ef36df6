"""The physical vibration model, the generator f(x) and model-based augmenters.

Imports only :mod:`mdaug.radar` below it.
"""
from .acquisition import PHASE_TREATMENTS, Acquisition, acquisition_from_file, render
from .augment import (AugmentedBatch, Augmenter, FixedParamsAugmenter, FixedSource, MixtureAugmenter,
                      ModelAugmenter, Renderer, SIGN_POLICIES, SigmaPAugmenter, SigmaPSource, SpecimenSource,
                      VectorSource)
from .specimens import SpecimenSpread
from .dataset import SyntheticDataset, load_dataset, make_dataset, save_dataset
from .model import if_signal, magnitude_spectra, profiles, spectra, vibration_terms
from .params import (IDX, N_PARAMS, PARAM_NAMES, ClassParams, Engine, load_reference,
                     param_labels, reference_classes, validate_vectors)

__all__ = [
    "Acquisition", "acquisition_from_file", "render", "AugmentedBatch", "Augmenter", "FixedParamsAugmenter",
    "FixedSource", "MixtureAugmenter", "ModelAugmenter", "Renderer", "PHASE_TREATMENTS", "SIGN_POLICIES",
    "SigmaPAugmenter", "SigmaPSource", "SpecimenSource", "SpecimenSpread", "VectorSource",
    "SyntheticDataset", "load_dataset",
    "make_dataset", "save_dataset", "if_signal", "magnitude_spectra", "profiles", "spectra",
    "vibration_terms", "IDX", "N_PARAMS", "PARAM_NAMES", "ClassParams", "Engine",
    "load_reference", "param_labels", "reference_classes", "validate_vectors",
]
