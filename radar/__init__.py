"""FMCW radar layer: the radar config object, the processing chain and profile I/O,
plus the base utilities every layer above uses (progress bars and the quiet switch,
the package version, atomic file writes).

Imports nothing else of mdaug.
"""
from .config import C0, RadarConfig
from .io import (DataFileError, ProfileSet, atomic_path, atomic_savez, atomic_write,
                 check_writable, load_profiles, read_arrays, remove_stale_parts, zero_rows)
from .profiles import NORMALISATIONS, as_profile_array, centred_slices, check_normalisation, normalise
from .progress import echo, is_quiet, progress_bar, progress_enabled, set_quiet
from .version import package_version

__all__ = [
    "C0", "RadarConfig", "DataFileError", "ProfileSet", "atomic_path", "atomic_savez", "atomic_write",
    "load_profiles", "read_arrays", "check_writable", "remove_stale_parts", "zero_rows",
    "NORMALISATIONS", "as_profile_array", "centred_slices", "check_normalisation", "normalise",
    "echo", "is_quiet", "progress_bar", "progress_enabled", "set_quiet", "package_version",
]
