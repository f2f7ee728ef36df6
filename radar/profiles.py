"""Pure functions on range profiles: peak-centred slices and normalisation.

Shared by the generator's f(x), the processing chain's signature extraction and the
classifiers' preprocessing, so that synthetic and measured profiles are treated alike.
"""
from __future__ import annotations

import numpy as np

NORMALISATIONS = ("peak", "db", "l2", "none")
"""Named normalisations of a profile:

* ``peak``: divide by the profile's maximum (peak = 1);
* ``db``: 20*log10 relative to the maximum, floored at ``db_floor`` (peak = 0 dB);
* ``l2``: divide by the Euclidean norm;
* ``none``: linear magnitude as it is.

An all-zero profile stays all zero (``db``: all at the floor), never NaN.
"""

DB_FLOOR = -80.0


def check_normalisation(name: str) -> str:
    if name not in NORMALISATIONS:
        raise ValueError(f"unknown normalisation {name!r}; expected one of {NORMALISATIONS}")
    return name


def as_profile_array(profiles, what: str = "profiles", error: type[Exception] = ValueError) -> np.ndarray:
    """Check and return profiles as a finite numeric (N, L) array (1-D -> one row).

    ``what`` names the input in the message (e.g. ``"f.npz: field 'profiles'"``);
    ``error`` is the exception type raised.
    """
    x = np.asarray(profiles)
    if x.dtype == object or not np.issubdtype(x.dtype, np.number):
        raise error(f"{what} must be a numeric (N, L) array, got dtype {x.dtype}")
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[0] == 0 or x.shape[1] < 2:
        raise error(f"{what} must be a non-empty (N, L) array, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise error(f"{what} holds NaN or inf (first in row {int(np.argwhere(~np.isfinite(x))[0, 0])})")
    return x


def normalise(profiles: np.ndarray, method: str = "peak", db_floor: float = DB_FLOOR) -> np.ndarray:
    """Normalise each row of ``profiles`` (..., L) of linear magnitudes.

    Returns a new array of the same shape and floating dtype.
    """
    check_normalisation(method)
    x = np.asarray(profiles)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float64)
    if method == "none":
        return x.copy()
    if method == "l2":
        scale = np.sqrt(np.sum(x.astype(np.float64) ** 2, axis=-1, keepdims=True)).astype(x.dtype)
    else:
        scale = np.max(np.abs(x), axis=-1, keepdims=True)
    safe = np.where(scale > 0, scale, 1).astype(x.dtype)
    y = x / safe
    if method == "db":
        with np.errstate(divide="ignore"):
            y = 20.0 * np.log10(np.abs(y))
        y = np.maximum(y, db_floor).astype(x.dtype)
    return y


def centred_slices(spectra: np.ndarray, centres: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Cut a ``length``-bin window out of each row of ``spectra`` around ``centres``.

    spectra: (N, B) magnitudes; centres: (N,) integer bins. The centre bin lands at
    index ``length // 2`` of every window, always: a window that would reach past
    either end of the spectrum is *not* shifted back inside; the missing bins are
    filled with zeros and reported.

    Returns ``(windows (N, length), n_missing (N,))`` where ``n_missing`` counts the
    zero-filled bins of each window (0 for a window fully inside).
    """
    spectra = np.asarray(spectra)
    centres = np.asarray(centres, dtype=np.int64)
    n, b = spectra.shape
    idx = centres[:, None] + (np.arange(length) - length // 2)[None, :]
    inside = (idx >= 0) & (idx < b)
    windows = np.take_along_axis(spectra, np.clip(idx, 0, b - 1), axis=1)
    n_missing = length - inside.sum(axis=1)
    if np.any(n_missing):
        windows = np.where(inside, windows, 0)
    return windows, n_missing
