"""``results.json``: strict JSON that another machine can read.

* every value plain JSON: numpy scalars and arrays converted, NaN and +-inf written as
  ``null`` (``json.dumps(..., allow_nan=False)`` then refuses anything left over, so a
  strict parser never meets a bare ``NaN`` token);
* every path relative to the study folder: the files the study wrote under it
  (``data/new.npz``, ``figures/profiles.png``) and the input files of a study config
  (``../new.npz``), so a study folder can be moved or copied to another machine.
  A string counts as a path when it lies under the study folder (as the folder was
  given, relative or absolute), or is absolute and names an existing file or folder.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from ..radar import atomic_write


def plain(obj, folder: Path):
    """``obj`` as JSON-ready Python: non-finite floats as None, paths relative to ``folder``."""
    given = Path(folder)
    folder = given.absolute()
    # the folder as the study was given it (a relative --out gives paths relative to the working
    # directory), as an absolute path, and with its links resolved
    prefixes = tuple({str(given) + os.sep, str(folder) + os.sep, str(folder.resolve()) + os.sep})

    def convert(v):  # v holds plain Python types only (jsonable below)
        if isinstance(v, dict):
            return {k: convert(x) for k, x in v.items()}
        if isinstance(v, list):
            return [convert(x) for x in v]
        if isinstance(v, float):
            return v if math.isfinite(v) else None
        if isinstance(v, str) and v.startswith(prefixes):
            base = folder.resolve() if v.startswith(str(folder.resolve()) + os.sep) else folder
            return os.path.relpath(os.path.abspath(v), base)
        if isinstance(v, str) and os.path.isabs(v) and os.path.exists(v):
            return os.path.relpath(v, folder)
        return v

    return convert(jsonable(obj))


def write_results(results: dict, folder: Path, name: str = "results.json") -> Path:
    """Write ``results`` as strict JSON to ``folder/name`` (atomically); the path."""
    text = json.dumps(plain(results, folder), indent=1, allow_nan=False)
    path = Path(folder) / name
    atomic_write(path, lambda fh: fh.write(text.encode()))
    return path


def jsonable(obj):
    """Plain Python types for JSON (numpy scalars and arrays converted)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "to_dict") and hasattr(obj, "index"):  # a pandas table: {row: {column: value}}
        return jsonable(obj.to_dict(orient="index"))
    return obj
