"""A study folder knows its study.

The study is its data: the seed, the classes, the measured files (or the simulated
scene) and the acquisition's K (:func:`study_key`, the key of the ``data`` stage). The
folder records it in ``stages/study.json``; a rerun of the same study resumes (the
protocol's settings may change: the stages they touch are computed again), another
study is refused by name before anything is written, unless it is asked to replace
the folder's study (``mdaug run --overwrite``: the study's own files, and only them,
are removed first).
"""
from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path

from ..radar import atomic_write
from .cache import settings_key

STUDY_FILES = ("report.html", "results.json", "stages/", "data/", "posteriors/", "models/", "figures/")
"""What a study writes in its folder (subfolders end in /)."""
IDENTITY = "study.json"
PARTS = ("seed", "classes", "data", "simulation", "ramps")


def _parts(cfg) -> dict:
    c = cfg.to_dict()
    return {"seed": c["seed"], "classes": c["classes"], "data": c["data"], "simulation": c["simulation"],
            "ramps": cfg.scene_ramps if cfg.simulated else cfg.ramps}


def study_key(cfg) -> str:
    """The study's identity: the key of its data (and of its ``data`` stage). Hashed as
    mdaug 0.1 hashed it, when K was two settings (``[simulation] ramps``, 4 under
    ``--quick``, and ``[protocol] acquisition_ramps``), so a study folder of 0.1 resumes."""
    p = _parts(cfg)
    scene = cfg.scene_ramps if cfg.simulated else (4 if cfg.quick else 32)
    return settings_key(p["seed"], p["classes"], p["data"], {"ramps": scene, **p["simulation"]},
                        None if cfg.simulated else cfg.ramps)


def _stored(out: Path) -> tuple[str | None, dict]:
    """(key, record) of the study in ``out`` (None: none recorded or readable)."""
    for name, read in ((IDENTITY, lambda d: (d["key"], d)), ("data.json", lambda d: (d["key"], {}))):
        try:
            record = json.loads((out / "stages" / name).read_text(encoding="utf-8"))
            key, record = read(record)
            if isinstance(key, str):
                return key, record if isinstance(record, dict) else {}
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None, {}


def check_study_folder(out, cfg, overwrite: bool = False) -> bool:
    """Refuse (ValueError naming the folder, both configs and what differs) a folder
    that holds another study, unless ``overwrite``; True when that study is to be
    replaced (see :func:`clear_study`). Writes nothing."""
    out = Path(out)
    key, record = _stored(out)
    if key is None or key == study_key(cfg):
        return False
    if overwrite:
        return True
    parts = record.get("parts") or {}
    mine = json.loads(json.dumps(_parts(cfg)))
    differ = [p for p in PARTS if p in parts and parts[p] != mine[p]] or ["its data"]
    shown = ", ".join(f"{p} {parts[p]!r} -> {mine[p]!r}" if p in ("seed", "classes", "ramps") else p
                      for p in differ if p in parts) or "its data"
    raise ValueError(f"{out}: --out holds another study (made from {record.get('config', 'another config')}; this run: "
                     f"{cfg.source}; differs in {shown}): choose another --out folder, or give --overwrite to "
                     "replace that study (its report, results, stages, data, posteriors, models and figures are "
                     "removed first)")


def clear_study(out) -> None:
    """Remove the study's own files from ``out`` (:data:`STUDY_FILES`), nothing else."""
    out = Path(out)
    for name in STUDY_FILES:
        path = out / name.rstrip("/")
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()


def claim(out, cfg) -> None:
    """Record the study of ``cfg`` in ``out/stages/study.json``."""
    text = json.dumps({"key": study_key(cfg), "config": cfg.source, "parts": _parts(cfg)}, indent=1)
    atomic_write(Path(out) / "stages" / IDENTITY, lambda fh: fh.write(text.encode()))


# ---- a study folder in use, and what a refused run leaves ----------------------------------------
LOCK = "run.lock"
"""``stages/run.lock``: the pid, host and start time of the ``mdaug run`` using the folder."""
SKELETON = ("data/", "posteriors/", "models/", "figures/", "stages/", f"stages/{IDENTITY}", f"stages/{LOCK}")
"""What a study writes before its first stage: empty folders and its records."""


def _lock_path(out) -> Path:
    return Path(out) / "stages" / LOCK


def _started(pid: int) -> float | None:
    try:
        import psutil

        return float(psutil.Process(pid).create_time())
    except Exception:  # psutil missing, or no such process
        return None


def study_in_use(out) -> dict | None:
    """The lock record of another live run using ``out`` (None: no lock, our own, or
    its owner is gone: a stale lock)."""
    import os
    import socket

    try:
        record = json.loads(_lock_path(out).read_text(encoding="utf-8"))
        pid = int(record["pid"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if record.get("host") != socket.gethostname():
        return record  # another machine's run: its pid cannot be checked from here
    if pid == os.getpid():
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        return record
    started, stored = _started(pid), record.get("started")
    if started is not None and isinstance(stored, (int, float)) and abs(started - stored) > 1.0:
        return None  # the pid was reused by another process
    return record


def check_not_in_use(out) -> None:
    """Refuse (ValueError naming the folder, the owner's pid and the lock) a study folder
    another ``mdaug run`` is using: it is never replaced, not even with --overwrite."""
    record = study_in_use(out)
    if record is not None:
        raise ValueError(f"{out}: --out is in use by another mdaug run (pid {record.get('pid')} on "
                         f"{record.get('host')}); wait for it to end or stop it (a study in use is never replaced, "
                         f"not even with --overwrite; if that run is gone, remove {_lock_path(out)})")


@contextlib.contextmanager
def study_lock(out):
    """Hold ``out``'s lock (its folder and ``stages/`` created when missing) while the
    block runs; refuses a folder another run holds; the lock is removed afterwards."""
    import os
    import socket

    check_not_in_use(out)
    path = _lock_path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)  # stale (its owner is gone): checked just above
    record = {"pid": os.getpid(), "host": socket.gethostname(), "started": _started(os.getpid())}
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:  # another run took it in between
        check_not_in_use(out)
        raise ValueError(f"{out}: --out is in use by another mdaug run (its lock {path} appeared just now)") from None
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(record, fh)
    try:
        yield path
    finally:
        try:
            if json.loads(path.read_text(encoding="utf-8")).get("pid") == os.getpid():
                path.unlink()
        except (OSError, ValueError):
            pass


def snapshot(out) -> set | None:
    """The paths under ``out`` now (None: ``out`` does not exist), for :func:`remove_skeleton`."""
    out = Path(out)
    return {p.relative_to(out).as_posix() for p in out.rglob("*")} if out.exists() else None


def remove_skeleton(out, before: set | None) -> bool:
    """After a run refused before its first stage: remove what it created in ``out``
    (``before``: :func:`snapshot` taken before it started), when that is only the
    study's skeleton (:data:`SKELETON`: empty folders, its records); stages of work
    are never removed. True when something was removed."""
    out = Path(out)
    if not out.is_dir() or out.is_symlink():
        return False
    now = {p.relative_to(out).as_posix() for p in out.rglob("*")}
    new = now - (before or set())
    skeleton = {s.rstrip("/") for s in SKELETON}
    if not new or any(p not in skeleton for p in new):
        return False
    for rel in sorted(new, key=lambda r: -r.count("/")):  # files, then folders, deepest first
        path = out / rel
        if path.is_dir():
            with contextlib.suppress(OSError):
                path.rmdir()  # only when empty
        else:
            path.unlink(missing_ok=True)
    if before is None:
        with contextlib.suppress(OSError):
            out.rmdir()
    return True
