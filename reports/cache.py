"""Stage outputs cached in the study folder, so an interrupted run resumes.

Each stage writes ``DIR/stages/<name>.json`` (and any files it names) atomically,
tagged with a key computed from the settings it depends on; a rerun with the same
key loads it instead of recomputing, a changed key recomputes. A stage file that
does not read back (cut short, not JSON, not a stage record) is named in a log line
and its stage computed again. The files a stage names inside the study folder are
recorded relative to it (``{"study_path": "posteriors/HELI.nc"}``) and read back under
the folder as it is named now: a rerun from another working directory, or of a moved
folder, finds them.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

STUDY_PATH = "study_path"

from ..radar import atomic_write
from ..radar.keys import cache_key


def settings_key(*parts) -> str:
    return cache_key(parts)


class StageCache:
    """``listener``: None, or an object with ``stage_started(name)`` and
    ``stage_finished(name, seconds, cached)`` (the command line's study progress bar);
    it may be set after construction."""

    def __init__(self, folder: Path, log=print, listener=None):
        self.folder = Path(folder) / "stages"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.log = log
        self.listener = listener
        self.timings: dict[str, float] = {}
        self.resumed: list[str] = []
        self.stored: set[str] = set()  # stages computed elsewhere in this run (not resumed)
        self.unreadable: set[str] = set()  # stage files that did not read back (logged once)
        self.root = os.path.abspath(self.folder.parent)

    def _notify(self, event: str, *args) -> None:
        if self.listener is not None:
            getattr(self.listener, event)(*args)

    def path(self, name: str, suffix: str = ".json") -> Path:
        return self.folder / f"{name}{suffix}"

    def _stored(self, name: str, key: str, needs=()) -> dict | None:
        path = self.path(name)
        if not path.is_file():
            return None
        try:
            stored = json.loads(path.read_text(encoding="utf-8"))
            problem = None if isinstance(stored, dict) and isinstance(stored.get("key"), str) \
                and isinstance(stored.get("seconds"), (int, float)) and "result" in stored \
                else "not a stage record (key, seconds, result)"
            if problem is None and stored["key"] == key:
                lacks = [k for k in needs if not isinstance(stored["result"], dict) or k not in stored["result"]]
                problem = f"its result lacks {lacks}" if lacks else None
        except (OSError, ValueError) as exc:  # cut short, not JSON, not UTF-8, unreadable
            problem = f"{type(exc).__name__}: {exc}"
        if problem is not None:
            if name not in self.unreadable:
                self.unreadable.add(name)
                self.log(f"[{name}] {path} does not read back ({' '.join(problem.split())[:120]}); computing the "
                         "stage again")
            return None
        if stored["key"] != key:
            return None
        stored["result"] = self._from_record(stored["result"])
        return stored

    def relative(self, value):
        """``value`` (JSON data) with every path of an existing file inside the study folder
        as ``{"study_path": path relative to the folder}``: as stage records hold them, and
        for keys that must not depend on where the folder is."""
        return self._to_record(value)

    def _to_record(self, value):
        if isinstance(value, dict):
            return {k: self._to_record(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [self._to_record(v) for v in value]
        if isinstance(value, str) and ("/" in value or os.sep in value):
            full = os.path.abspath(value)
            if full.startswith(self.root + os.sep) and os.path.exists(full):
                return {STUDY_PATH: os.path.relpath(full, self.root)}
        return value

    def _from_record(self, value):
        if isinstance(value, dict):
            if set(value) == {STUDY_PATH} and isinstance(value[STUDY_PATH], str):
                return str(self.folder.parent / value[STUDY_PATH])
            return {k: self._from_record(v) for k, v in value.items()}
        if isinstance(value, list):
            return [self._from_record(v) for v in value]
        return value

    def has(self, name: str, key: str, needs=()) -> bool:
        """Whether stage ``name`` is cached for ``key`` (with the keys ``needs``)."""
        return self._stored(name, key, needs) is not None

    def started(self, name: str, where: str = " (sent to the workers)") -> None:
        """Log that stage ``name`` starts (computed elsewhere: :meth:`store` logs its end;
        the worker logs when it takes the job up)."""
        self.log(f"[{name}] running{where} ...")
        self._notify("stage_started", name)

    def store(self, name: str, key: str, result, seconds: float, where: str = " in a worker"):
        """Record a stage computed elsewhere (e.g. by a worker) with its wall time; log its end."""
        self.timings[name] = seconds
        self.stored.add(name)
        text = json.dumps({"key": key, "seconds": seconds, "result": self._to_record(result)}, indent=1)
        atomic_write(self.path(name), lambda fh: fh.write(text.encode()))
        self.log(f"[{name}] done in {seconds:.1f} s{where}")
        self._notify("stage_finished", name, seconds, False)
        return result

    def run(self, name: str, key: str, compute, needs=()):
        """Return the cached result of stage ``name`` for ``key``, or compute and store it.

        ``compute()`` returns a JSON-serialisable dict; its wall time is recorded.
        ``needs``: the keys a stored result must hold to be used (else it is computed again).
        """
        stored = self._stored(name, key, needs)
        if stored is not None and name in self.stored:  # computed by a worker in this run
            return stored["result"]
        if stored is not None:
            self.timings[name] = stored["seconds"]
            self.resumed.append(name)
            self.log(f"[{name}] cached ({stored['seconds']:.1f} s when computed)")
            self._notify("stage_finished", name, stored["seconds"], True)
            return stored["result"]
        self.started(name, "")
        t0 = time.perf_counter()
        result = compute()
        return self.store(name, key, result, time.perf_counter() - t0, "")
