"""Readers of raw FMCW acquisitions (SPEC section 7).

A raw file is NPZ or MATLAB .mat holding either

* ``cube``: one acquisition, (frames, antennas, samples) or, with K ramps per frame,
  (frames, ramps, antennas, samples); int16 ADC codes or float; or
* ``cubes``: several acquisitions stacked on a leading axis, (N, frames, antennas,
  samples) or (N, frames, ramps, antennas, samples) (what ``mdaug simulate
  --keep-cubes`` writes), optionally with ``labels`` (N,) beside it.

An optional ``label`` (one string) or ``labels`` names the class. Every error names
the file, the field and what was expected.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import RadarConfig
from .io import DataFileError, check_labels, read_arrays

RAMPS_FIELD_NOTE = "(frames, antennas, samples) or (frames, ramps, antennas, samples)"


@dataclass
class RawFile:
    """The acquisitions of one raw file: cubes (N, F, K, A, S) float32 (K = 1 when the
    file had no ramps axis), labels (N,) str or None, and the path."""

    cubes: np.ndarray
    labels: np.ndarray | None
    source: str

    def __len__(self) -> int:
        return self.cubes.shape[0]


def check_cube(cube, source: str, radar: RadarConfig = RadarConfig(), field: str = "cube") -> np.ndarray:
    """Validate one acquisition; return it as float32 (F, K, A, S)."""
    arr = np.asarray(cube)
    if arr.size == 0:
        raise DataFileError(f"{source}: field {field!r} is empty (shape {arr.shape}); expected {RAMPS_FIELD_NOTE}")
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise DataFileError(f"{source}: field {field!r} must be int16 ADC codes or float, got dtype {arr.dtype}")
    if arr.ndim not in (3, 4):
        raise DataFileError(f"{source}: field {field!r} has rank {arr.ndim} (shape {arr.shape}); "
                            f"expected {RAMPS_FIELD_NOTE}")
    if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])  # in the file's own shape
        raise DataFileError(f"{source}: field {field!r} holds NaN or inf (first at index {idx} of shape "
                            f"{arr.shape})")
    big = np.finfo(np.float32).max if np.issubdtype(arr.dtype, np.floating) else 2 ** 16
    if np.issubdtype(arr.dtype, np.integer) and arr.dtype.itemsize <= 2:
        big = None  # int8/int16/uint16 ADC codes
    if big is not None and np.max(np.abs(arr.astype(np.float64))) >= big:
        what = "exceed float32" if big != 2 ** 16 else "are not 16-bit ADC codes (|code| >= 65536)"
        raise DataFileError(f"{source}: field {field!r} holds values that {what} (dtype {arr.dtype}); they would "
                            "not survive the chain's float32 samples")
    if arr.ndim == 3:
        arr = arr[:, None]
    f, _, a, s = arr.shape
    if f < radar.mti_depth + 1:
        raise DataFileError(f"{source}: field {field!r} has {f} frame(s); the MTI needs at least "
                            f"mti_depth + 1 = {radar.mti_depth + 1}")
    if s < 2 or s > radar.fft_points:
        raise DataFileError(f"{source}: field {field!r} has {s} samples per chirp; expected 2 .. "
                            f"fft_points = {radar.fft_points} (the platform's is {radar.samples_per_chirp})")
    return arr.astype(np.float32, copy=False)


def _labels(arrays: dict, n: int, source: str) -> np.ndarray | None:
    for key in ("labels", "label"):
        if key in arrays:
            lab = check_labels(arrays[key], source, key)
            if lab.size == 1 and n > 1:
                lab = np.repeat(lab, n)
            if lab.size != n or np.any(lab == ""):
                raise DataFileError(f"{source}: field {key!r} must hold one non-empty label or one per "
                                    f"acquisition ({n}), got {lab.size}")
            return lab
    return None


def read_raw(path, radar: RadarConfig = RadarConfig()) -> RawFile:
    """Read and validate the acquisition(s) of one NPZ/.mat raw file."""
    path = Path(path)
    arrays = read_arrays(path)
    src = str(path)
    if "cube" in arrays:
        cubes = check_cube(arrays["cube"], src, radar)[None]
    elif "cubes" in arrays:
        stack = np.asarray(arrays["cubes"])
        if stack.ndim not in (4, 5) or stack.shape[0] == 0:
            raise DataFileError(f"{src}: field 'cubes' has shape {stack.shape}; expected (N, frames, "
                                "antennas, samples) or (N, frames, ramps, antennas, samples)")
        cubes = np.stack([check_cube(c, src, radar, field=f"cubes[{i}]") for i, c in enumerate(stack)])
    else:
        raise DataFileError(f"{src}: missing field 'cube' (expected {RAMPS_FIELD_NOTE} ADC codes or "
                            f"float); fields present: {sorted(arrays)}")
    return RawFile(cubes=cubes, labels=_labels(arrays, cubes.shape[0], src), source=src)
