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
