"""Reading measured range profiles and writing files atomically.

Measured-profile format (SPEC section 7): ``profiles`` (N, L) float linear magnitude
and ``labels`` (N,) strings, in NPZ, CSV (one profile a row plus a ``label`` column)
or MATLAB .mat with the same variable names. Every error names the file and field.
"""
from __future__ import annotations

import contextlib
import csv
import glob
import json
import os
import re
import socket
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .names import check_distinct, check_name
from .npz import DataFileError, check_readable, read_arrays  # noqa: F401 (read_arrays: part of this module's API)
from .profiles import as_profile_array


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

    def check_no_zero_rows(self, label: str | None = None) -> "ProfileSet":
        """Refuse all-zero profiles (of class ``label``, or any), naming the file and rows."""
        rows = zero_rows(self.profiles if label is None else self.profiles[self.labels == label])
        if rows.size:
            if label is not None:
                rows = np.flatnonzero(self.labels == label)[rows]
            shown = ", ".join(map(str, rows[:8].tolist())) + (", ..." if rows.size > 8 else "")
            raise DataFileError(f"{self.source}: field 'profiles': {rows.size} of {len(self)} profile(s) "
                                f"are all zeros (rows {shown}); an all-zero profile has no signature, "
                                "remove those rows")
        return self

    def specimens(self, label: str) -> np.ndarray:
        """Drone id (strings) of each profile of class ``label`` (n,): the ``specimen`` field, else "0".
        Drone ids become file names (a drone's posterior): each must pass the one name rule."""
        ids = np.asarray(self.extra.get("specimen", np.zeros(len(self.labels), int)))[self.labels == label].astype(str)
        unique = list(dict.fromkeys(ids.tolist()))
        for drone in unique:
            check_name(drone, f"{self.source}: field 'specimen' drone id", error=DataFileError)
        check_distinct(unique, f"{self.source}: field 'specimen'", error=DataFileError)
        return ids

    def select(self, label: str) -> np.ndarray:
        """Profiles (n, L) of one class; error naming the file when absent."""
        mask = self.labels == label
        if not mask.any():
            raise DataFileError(f"{self.source}: field 'labels' holds no profile of class "
                                f"{label!r} (classes present: {self.classes})")
        return self.profiles[mask]


def zero_rows(profiles) -> np.ndarray:
    """Indices of the rows of ``profiles`` (N, L) that are all zeros."""
    x = np.asarray(profiles)
    return np.flatnonzero(~np.any(x.reshape(x.shape[0], -1) != 0, axis=1))


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


PER_PROFILE_FIELDS = ("param_row", "specimen", "true_params", "range_m", "range_true_m", "mti_profiles")
"""Optional fields of a profile file with one entry per profile (checked on reading)."""

PART_SUFFIX = ".part"
STALE_SECONDS = 3600.0
"""A part file whose writer cannot be checked (another host, or an older mdaug that
did not record its pid) counts as stale after this many seconds."""


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:40] or "host"


def _part_prefix(path: Path) -> str:
    return f".{path.name}."


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists, owned by someone else
    try:  # a killed but not yet reaped process is a zombie: its writing is over
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def stale_parts(path) -> list[Path]:
    """Temporary files of earlier writes of ``path`` whose writer is gone.

    :func:`atomic_write` names its temporary file ``.NAME.PID@HOST.XXXXXXXX.part``
    beside the target; one is left behind only when the writer was killed outright
    (SIGKILL, power loss). It is stale when its PID is no longer running on this
    host, or, when that cannot be checked (another host, an older file without
    PID), when it is older than :data:`STALE_SECONDS`.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    prefix = _part_prefix(path)
    pattern = re.compile(r"^(\d+)@([A-Za-z0-9_-]+)\.[A-Za-z0-9_]+$")
    host, now, out = _host(), time.time(), []
    for name in glob.glob(glob.escape(prefix) + "*" + PART_SUFFIX, root_dir=parent):
        middle = name[len(prefix): -len(PART_SUFFIX)]
        part = parent / name
        m = pattern.match(middle)
        try:
            if m and m.group(2) == host:
                stale = int(m.group(1)) != os.getpid() and not _pid_alive(int(m.group(1)))
            else:
                stale = now - part.stat().st_mtime > STALE_SECONDS
        except OSError:
            continue
        if stale:
            out.append(part)
    return out


def remove_stale_parts(path) -> list[Path]:
    """Delete the :func:`stale_parts` of ``path``; returns what was removed."""
    removed = []
    for part in stale_parts(path):
        with contextlib.suppress(OSError):
            part.unlink()
            removed.append(part)
    return removed


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` to write by name; on success it gets the
    usual file mode (0666 minus the umask) and is renamed onto ``path``.

    The target appears only when complete; on any error (or KeyboardInterrupt) the
    temporary file is removed. Stale temporary files of earlier, killed writes of
    the same target are removed first (:func:`stale_parts`).
    """
    path = check_writable(path)
    parent = path.parent if str(path.parent) else Path(".")
    remove_stale_parts(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f"{_part_prefix(path)}{os.getpid()}@{_host()}.",
                                   suffix=PART_SUFFIX, dir=parent)
    except OSError as exc:
        raise DataFileError(f"{path}: cannot write ({exc.strerror})") from exc
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600 files; give the usual mode
        os.replace(tmp, path)
    except OSError as exc:  # disk full, quota, read-only file system...: one line naming the target
        Path(tmp).unlink(missing_ok=True)
        raise DataFileError(f"{path}: cannot write ({exc.strerror or exc}); nothing was written") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write(path, write) -> Path:
    """Call ``write(fileobj)`` on a temporary file beside ``path``, then rename it.

    The target appears only when complete; on any error nothing is left behind
    (see :func:`atomic_path`).
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            write(fh)
    return path


def atomic_savez(path, **arrays) -> Path:
    """``np.savez_compressed`` to ``path`` atomically (no half-written file)."""
    return atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


def check_labels(labels, src: str, field: str = "labels") -> np.ndarray:
    """Class labels as a (N,) unicode array, refusing what is not a vector of text:
    numbers (they would become class names like '0.0'), bytes that are not UTF-8,
    a table of more than one column. Errors name the file and field."""
    arr = np.asarray(labels)
    what = f"{src}: field {field!r}"
    if arr.dtype == object:  # MATLAB cell arrays
        items = [np.squeeze(v) for v in arr.ravel()]
        if not all(isinstance(v, str) or (isinstance(v, np.ndarray) and v.dtype.kind == "U") for v in items):
            raise DataFileError(f"{what} must hold text (class names), found other objects")
        arr = np.array([str(v) for v in items])
    if arr.dtype.kind == "S":
        try:
            arr = np.array([v.decode("utf-8") for v in arr.ravel()]).reshape(arr.shape)
        except UnicodeDecodeError as exc:
            raise DataFileError(f"{what} holds bytes that are not UTF-8 text ({exc.reason} at byte {exc.start})") \
                from None
    if arr.dtype.kind != "U":
        raise DataFileError(f"{what} must hold text (class names such as HELI), got dtype {arr.dtype}")
    if arr.ndim > 1 and sum(s > 1 for s in arr.shape) > 1:
        raise DataFileError(f"{what} has shape {arr.shape}; expected one label per profile, (N,)")
    return np.char.strip(arr.ravel())


def _check_profiles(profiles, labels, src: str) -> tuple[np.ndarray, np.ndarray]:
    raw = np.asarray(profiles)
    if np.iscomplexobj(raw):
        raise DataFileError(f"{src}: field 'profiles' is complex (dtype {raw.dtype}); expected linear magnitudes "
                            "(take np.abs first)")
    profiles = as_profile_array(raw, f"{src}: field 'profiles'", DataFileError)
    with np.errstate(over="ignore"):
        profiles = profiles.astype(np.float64)
    if not np.all(np.isfinite(profiles)):
        raise DataFileError(f"{src}: field 'profiles' overflows float64 (dtype {raw.dtype})")
    labels = check_labels(labels, src)
    if labels.shape[0] != profiles.shape[0]:
        raise DataFileError(f"{src}: field 'labels' has {labels.shape[0]} entries for "
                            f"{profiles.shape[0]} profiles")
    if np.any(labels == ""):
        raise DataFileError(f"{src}: field 'labels' has empty entries")
    return profiles, labels


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError as exc:
        raise DataFileError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); save the CSV as UTF-8") \
            from None
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except csv.Error as exc:
        raise DataFileError(f"{path}: not a readable CSV file ({exc})") from None
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


def load_profiles(path) -> ProfileSet:
    """Read measured or synthetic profiles from NPZ, CSV or .mat (SPEC section 7)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        check_readable(path)
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
    _check_metadata(extra, labels, str(path))
    return ProfileSet(profiles=profiles, labels=labels, extra=extra, source=str(path))


def _check_metadata(extra: dict, labels: np.ndarray, src: str) -> None:
    """The fields that describe the profiles must agree with them: ``settings`` a JSON
    table whose ``classes`` (when stated) hold every label, ``param_row`` and the other
    per-profile fields one entry per profile."""
    n = len(labels)
    if "settings" in extra:
        raw = np.asarray(extra["settings"])
        try:
            settings = json.loads(str(raw)) if raw.dtype.kind == "U" and raw.size == 1 else None
        except ValueError:
            settings = None
        if not isinstance(settings, dict):
            raise DataFileError(f"{src}: field 'settings' is not a JSON table (dtype {raw.dtype}, shape {raw.shape})")
        classes = settings.get("classes")
        if isinstance(classes, list):
            stray = sorted(set(labels.tolist()) - set(map(str, classes)))
            if stray:
                raise DataFileError(f"{src}: field 'labels' holds class(es) {stray} that field 'settings' does not "
                                    f"list (classes {classes}); the file's metadata disagrees with its content")
    for key in PER_PROFILE_FIELDS:
        if key in extra:
            arr = np.asarray(extra[key])
            if arr.ndim == 0 or arr.shape[0] != n:
                raise DataFileError(f"{src}: field {key!r} has shape {arr.shape}; expected one entry per profile "
                                    f"({n})")
    if "specimen" in extra:
        arr = np.asarray(extra["specimen"])
        if arr.ndim != 1 or arr.dtype.kind not in "iuUS":
            raise DataFileError(f"{src}: field 'specimen' has dtype {arr.dtype} and shape {arr.shape}; expected one "
                                f"integer or string drone id per profile ({n},)")
