"""The one preprocessing step shared by training and testing.

Synthetic and measured profiles go through the same :func:`preprocess`: the SPEC's
named normalisation (:func:`mdaug.radar.normalise`) applied row by row, cast to
float32. Classifiers call it themselves with the normalisation they were trained
with, so callers hand over raw profiles (normalised or not) of either origin.
"""
from __future__ import annotations

import numpy as np

from ..radar import as_profile_array, check_normalisation, normalise


def as_profiles(profiles, what: str = "profiles") -> np.ndarray:
    """Check and return profiles as a finite numeric (N, L) array (1-D -> one row)."""
    return as_profile_array(profiles, what)


def preprocess(profiles, normalisation: str = "peak") -> np.ndarray:
    """Normalise each profile (N, L) with ``normalisation`` and return float32 (N, L).

    ``normalisation`` is one of :data:`mdaug.radar.NORMALISATIONS` (``peak``: peak =
    1; ``db``: dB relative to the peak, floored at -80; ``l2``; ``none``). Peak
    normalisation is idempotent, so already-normalised profiles are unchanged.
    """
    check_normalisation(normalisation)
    x = as_profiles(profiles)
    return np.ascontiguousarray(normalise(x.astype(np.float64), normalisation), dtype=np.float32)
