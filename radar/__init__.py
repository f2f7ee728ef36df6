"""FMCW radar layer: the radar config object, the processing chain and profile I/O.

Imports nothing else of mdaug.
"""
from .config import C0, RadarConfig
from .io import (DataFileError, ProfileSet, atomic_savez, atomic_write, check_outputs, check_writable,
                 load_profiles, read_arrays)
from .profiles import NORMALISATIONS, as_profile_array, centred_slices, check_normalisation, normalise

__all__ = [
    "C0", "RadarConfig", "DataFileError", "ProfileSet", "atomic_savez", "atomic_write",
    "load_profiles", "read_arrays", "check_outputs", "check_writable", "NORMALISATIONS", "as_profile_array", "centred_slices",
    "check_normalisation", "normalise",
]
