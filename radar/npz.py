"""Reading array files with care: the one pre-open check, NPZ and .mat opened without
pickle, and the checked reader of an NPZ artefact's fields.

Every file mdaug reads back (profile sets, raw cubes, population files, and any
future NPZ artefact such as a trained estimator) goes through :func:`read_arrays`;
artefacts with a fixed layout list their fields as :class:`Field` and call
:func:`read_checked`: every field present, with the dtype kind, rank and shape
stated, finite where it must be. Every error is one :class:`DataFileError` naming
the file and the field; truncated archives, zip errors and pickled objects included.
"""
from __future__ import annotations

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class DataFileError(ValueError):
    """A data file is missing, unreadable or holds the wrong thing."""


def check_readable(path, what: str = "data file") -> Path:
    """The one pre-open check: ``path`` is a non-empty regular file that can be opened
    (else one line naming it)."""
    path = Path(path)
    if path.is_dir():
        raise DataFileError(f"{path}: is a folder, not a {what}")
    if not path.is_file():
        raise DataFileError(f"{path}: {'file' if what == 'data file' else what} not found")
    if path.stat().st_size == 0:
        raise DataFileError(f"{path}: file is empty")
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return path


def _read_mat(path: Path) -> dict:
    from scipy.io import loadmat

    try:
        return {k: v for k, v in loadmat(path).items() if not k.startswith("__")}
    except Exception as exc:  # scipy raises several types for corrupt files
        raise DataFileError(f"{path}: not a readable MATLAB file ({exc})") from None


def read_arrays(path, what: str = "data file") -> dict:
    """All arrays of an NPZ or .mat file, loaded without pickle."""
    path = check_readable(path, what)
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if magic.startswith(b"\x93NUMPY"):
        raise DataFileError(f"{path}: expected an NPZ archive, found a single .npy array")
    if not magic.startswith(b"PK"):
        kind = "a Python pickle; refusing to unpickle it" if magic[:1] == b"\x80" else "not a ZIP archive"
        raise DataFileError(f"{path}: not a readable NPZ file ({kind})")
    try:
        with np.load(path, allow_pickle=False) as data:
            out = {}
            for key in data.files:
                try:
                    out[key] = data[key]
                except ValueError as exc:
                    if "allow_pickle" in str(exc):
                        raise DataFileError(f"{path}: field {key!r} holds Python objects; refusing to "
                                            "unpickle it") from None
                    raise DataFileError(f"{path}: field {key!r} is not a readable array ({exc})") from None
                except (zipfile.BadZipFile, zlib.error, EOFError, KeyError, OSError) as exc:
                    raise DataFileError(f"{path}: field {key!r} is cut short or corrupt ({_why(exc)})") from None
            return out
    except DataFileError:
        raise
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except Exception as exc:  # BadZipFile, EOFError, ValueError of a truncated or corrupt archive
        raise DataFileError(f"{path}: not a readable NPZ file ({_why(exc)})") from None


def _why(exc: BaseException, limit: int = 100) -> str:
    """``Type: message`` of an archive error, cut to ``limit`` characters (zip errors
    can quote whole headers)."""
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Field:
    """One field of an NPZ artefact: ``kinds``, the numpy dtype kinds it may have
    (``"f"`` float, ``"iu"`` integers, ``"b"`` bool, ``"U"`` text; ints are accepted
    where floats are); ``ndim`` its rank; ``shape`` per axis an int, a name bound on
    first use (``"n"``: every field naming it must agree), or None (any); ``finite``:
    no NaN or infinity; ``text``: what it holds, for the messages."""

    name: str
    kinds: str
    ndim: int
    shape: tuple = ()
    finite: bool = True
    text: str = ""


_KIND_WORDS = {"f": "floats", "i": "integers", "u": "integers", "b": "booleans", "U": "text"}


def check_field(arrays: dict, f: Field, src, sizes: dict | None = None) -> np.ndarray:
    """``arrays[f.name]`` checked against ``f`` (see :class:`Field`); ``sizes``: the
    named axis lengths bound so far (updated)."""
    sizes = {} if sizes is None else sizes
    want = f"{f.text or _KIND_WORDS.get(f.kinds[0], f.kinds)} of rank {f.ndim}"
    if f.name not in arrays:
        raise DataFileError(f"{src}: missing field {f.name!r} (expected {want}); fields present: {sorted(arrays)}")
    a = np.asarray(arrays[f.name])
    kinds = f.kinds + ("iu" if "f" in f.kinds else "")
    if a.dtype.kind not in kinds:
        raise DataFileError(f"{src}: field {f.name!r} has dtype {a.dtype}; expected {want}")
    if a.ndim != f.ndim:
        raise DataFileError(f"{src}: field {f.name!r} has shape {a.shape}; expected {want}")
    for axis, (got, spec) in enumerate(zip(a.shape, f.shape)):
        expected = sizes.setdefault(spec, got) if isinstance(spec, str) else spec
        if expected is not None and got != expected:
            named = f" (as its {spec!r} elsewhere in the file)" if isinstance(spec, str) else ""
            raise DataFileError(f"{src}: field {f.name!r} has shape {a.shape}; expected {expected} along axis "
                                f"{axis}{named}")
    if f.finite and a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise DataFileError(f"{src}: field {f.name!r} holds NaN or infinite values")
    return a


def read_checked(path, fields, what: str = "NPZ file", sizes: dict | None = None) -> dict:
    """The arrays of the NPZ artefact ``path``, each of ``fields`` (:class:`Field`)
    present and checked; other fields are returned unchecked. ``sizes``: named axis
    lengths known beforehand (e.g. {"params": 13})."""
    arrays = read_arrays(path, what)
    sizes = dict(sizes or {})
    for f in fields:
        arrays[f.name] = check_field(arrays, f, path, sizes)
    return arrays
