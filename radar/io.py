"""Reading measured range profiles and writing files atomically.

Measured-profile format (SPEC section 7): ``profiles`` (N, L) float linear magnitude
and ``labels`` (N,) strings, in NPZ, CSV (one profile a row plus a ``label`` column)
or MATLAB .mat with the same variable names. Every error names the file and field.
"""
from __future__ import annotations

import csv
import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .profiles import as_profile_array


class DataFileError(ValueError):
    """A data file is missing, unreadable or holds the wrong thing."""


@dataclass
class ProfileSet:
    """Range profiles with their labels, as read from a file.

    profiles: (N, L) float64 linear magnitudes (or already-normalised values);
    labels: (N,) unicode; extra: every other array the file held; source: the path.
    """

    profiles: np.ndarray
    labels: np.ndarray
    extra: dict = field(default_factory=dict)
    source: str = ""

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def classes(self) -> list[str]:
        return sorted(set(self.labels.tolist()))

    def settings(self) -> dict:
        """The JSON ``settings`` the file carries ({} when it has none)."""
        raw = self.extra.get("settings")
        return {} if raw is None else json.loads(str(raw))

    def select(self, label: str) -> np.ndarray:
        """Profiles (n, L) of one class; error naming the file when absent."""
        mask = self.labels == label
        if not mask.any():
            raise DataFileError(f"{self.source}: field 'labels' holds no profile of class "
                                f"{label!r} (classes present: {self.classes})")
        return self.profiles[mask]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable(path) -> Path:
    """Fail early (before any work) when ``path`` cannot be written."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise DataFileError(f"{path}: cannot write, folder {parent} does not exist")
    if path.is_dir():
        raise DataFileError(f"{path}: cannot write, it is a folder")
    if not os.access(parent, os.W_OK):
        raise DataFileError(f"{path}: cannot write, folder {parent} is not writable")
    return path


def check_outputs(*paths) -> None:
    """:func:`check_writable` on every given output path (None = not asked for)."""
    for path in paths:
        if path is not None:
            check_writable(path)


def atomic_write(path, write) -> Path:
    """Call ``write(fileobj)`` on a temporary file beside ``path``, then rename it.

    The target appears only when complete; on any error nothing is left behind.
    """
    path = check_writable(path)
    parent = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=parent)
    except OSError as exc:
        raise DataFileError(f"{path}: cannot write ({exc.strerror})") from exc
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600 files; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_savez(path, **arrays) -> Path:
    """``np.savez_compressed`` to ``path`` atomically (no half-written file)."""
    return atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


def _check_profiles(profiles, labels, src: str) -> tuple[np.ndarray, np.ndarray]:
    profiles = as_profile_array(profiles, f"{src}: field 'profiles'", DataFileError).astype(np.float64)
    labels = np.asarray(labels)
    if labels.dtype == object:
        labels = np.array([str(np.squeeze(v)) for v in labels.ravel()])
    labels = np.char.strip(labels.astype(str).ravel())
    if labels.shape[0] != profiles.shape[0]:
        raise DataFileError(f"{src}: field 'labels' has {labels.shape[0]} entries for "
                            f"{profiles.shape[0]} profiles")
    if np.any(labels == ""):
        raise DataFileError(f"{src}: field 'labels' has empty entries")
    return profiles, labels


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise DataFileError(f"{path}: empty CSV file")
    header = [h.strip().lower() for h in rows[0]]
    label_col = next((i for i, h in enumerate(header) if h in ("label", "labels")), None)
    if label_col is None:
        raise DataFileError(f"{path}: CSV header has no 'label' column (header: {rows[0][:5]}...)")
    values, labels = [], []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        try:
            values.append([float(v) for i, v in enumerate(row) if i != label_col])
        except ValueError as exc:
            raise DataFileError(f"{path}: line {lineno}: field 'profiles' is not numeric ({exc})") from None
        labels.append(row[label_col])
    if len({len(v) for v in values}) > 1:
        raise DataFileError(f"{path}: rows have different numbers of profile values")
    return np.array(values), np.array(labels), {}


def _read_mat(path: Path) -> dict:
    from scipy.io import loadmat

    try:
        return {k: v for k, v in loadmat(path).items() if not k.startswith("__")}
    except Exception as exc:  # scipy raises several types for corrupt files
        raise DataFileError(f"{path}: not a readable MATLAB file ({exc})") from None


def read_arrays(path) -> dict:
    """All arrays of an NPZ or .mat file, loaded without pickle."""
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path}: file not found")
    if path.stat().st_size == 0:
        raise DataFileError(f"{path}: file is empty")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        return _read_mat(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise DataFileError(f"{path}: expected an NPZ archive, found a single array")
            return {k: data[k] for k in data.files}
    except DataFileError:
        raise
    except ValueError as exc:
        raise DataFileError(f"{path}: holds Python objects; refusing to unpickle ({exc})") from None
    except Exception as exc:
        raise DataFileError(f"{path}: not a readable NPZ file ({exc})") from None


def load_profiles(path) -> ProfileSet:
    """Read measured or synthetic profiles from NPZ, CSV or .mat (SPEC section 7)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        if not path.is_file():
            raise DataFileError(f"{path}: file not found")
        profiles, labels, extra = _read_csv(path)
    else:
        arrays = read_arrays(path)
        for key, what in (("profiles", "(N, L) float array"), ("labels", "(N,) strings")):
            if key not in arrays:
                raise DataFileError(f"{path}: missing field {key!r} (expected {what}); "
                                    f"fields present: {sorted(arrays)}")
        profiles, labels = arrays.pop("profiles"), arrays.pop("labels")
        extra = arrays
    profiles, labels = _check_profiles(profiles, labels, str(path))
    return ProfileSet(profiles=profiles, labels=labels, extra=extra, source=str(path))
