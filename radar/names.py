"""The one rule for names that become file names.

Names given in configs and data files (a study's test sets and classes, the drone ids
of a file's ``specimen`` field, stage names) are labels, and mdaug makes file names
of them (``data/<set>.npz``, ``posteriors/<CLASS>.drone-<id>.nc``,
``stages/<stage>.json``). A name that could leave its folder, hide a file or replace
one of the tool's own files is refused here, in one place:

* 1 to 64 characters of ``A-Z a-z 0-9 _ - .``, starting with a letter, digit or ``_``
  (so no path separator, no leading dot, no absolute path, no drive letter);
* no ``..`` anywhere, no trailing dot;
* not a device name of Windows (``CON``, ``NUL``, ``COM1`` ...);
* not one of the ``reserved`` names of the caller's own files (compared without
  case: a case-insensitive file system would make ``Select`` the same file as
  ``select``), nor starting with a reserved prefix.
"""
from __future__ import annotations

import re

MAX_NAME = 64
_SAFE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
_DEVICES = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(1, 10)), *(f"lpt{i}" for i in range(1, 10))}
RULE = (f"a name of 1 to {MAX_NAME} letters, digits, '_', '-' or '.', starting with a letter, digit or '_' "
        "(it becomes a file name)")


def name_problem(name, reserved=(), prefixes=()) -> str | None:
    """Why ``name`` cannot become a file name (None when it can); see the module doc."""
    if not isinstance(name, str):
        return f"expected text, got {type(name).__name__}"
    if not name:
        return "empty"
    if len(name) > MAX_NAME:
        return f"{len(name)} characters, more than {MAX_NAME}"
    if "/" in name or "\\" in name:
        return "holds a path separator"
    if name.startswith("."):
        return "starts with a dot"
    if ".." in name:
        return "holds '..'"
    if not _SAFE.fullmatch(name):
        bad = sorted({c for c in name if not re.fullmatch(r"[A-Za-z0-9_.-]", c)})
        return f"holds {', '.join(map(repr, bad))}" if bad else "does not start with a letter, digit or '_'"
    if name.endswith("."):
        return "ends with a dot"
    if name.split(".")[0].lower() in _DEVICES:
        return "is a device name on Windows"
    low = name.lower()
    clash = next((r for r in reserved if r.lower() == low), None)
    if clash is not None:
        return f"is reserved: the tool's own {clash!r} has that name"
    clash = next((p for p in prefixes if low.startswith(p.lower())), None)
    if clash is not None:
        return f"starts with {clash!r}, the prefix of the tool's own files"
    return None


def check_name(name, where: str, reserved=(), prefixes=(), error=ValueError) -> str:
    """``name`` when it may become a file name; else raise ``error`` naming ``where``
    (the file and field, or the config key) and the rule."""
    problem = name_problem(name, reserved, prefixes)
    if problem is not None:
        raise error(f"{where} = {name!r}: {problem}; expected {RULE}")
    return name


def check_distinct(names, where: str, error=ValueError) -> None:
    """Refuse two names that are one file on a case-insensitive file system."""
    seen: dict[str, str] = {}
    for n in names:
        other = seen.setdefault(str(n).lower(), n)
        if other != n:
            raise error(f"{where}: {other!r} and {n!r} differ only in case; they would be one file on many "
                        "file systems: rename one")
