"""Stage outputs cached in the study folder, so an interrupted run resumes.

Each stage writes ``DIR/stages/<name>.json`` (and any files it names) atomically,
tagged with a key computed from the settings it depends on; a rerun with the same
key loads it instead of recomputing, a changed key recomputes.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

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

    def _notify(self, event: str, *args) -> None:
        if self.listener is not None:
            getattr(self.listener, event)(*args)

    def path(self, name: str, suffix: str = ".json") -> Path:
        return self.folder / f"{name}{suffix}"

    def _stored(self, name: str, key: str) -> dict | None:
        path = self.path(name)
        if not path.is_file():
            return None
        try:
            stored = json.loads(path.read_text())
        except json.JSONDecodeError:
            return None
        return stored if stored.get("key") == key else None

    def has(self, name: str, key: str) -> bool:
        """Whether stage ``name`` is cached for ``key``."""
        return self._stored(name, key) is not None

    def started(self, name: str, where: str = " (sent to the workers)") -> None:
        """Log that stage ``name`` starts (computed elsewhere: :meth:`store` logs its end;
        the worker logs when it takes the job up)."""
        self.log(f"[{name}] running{where} ...")
        self._notify("stage_started", name)

    def store(self, name: str, key: str, result, seconds: float, where: str = " in a worker"):
        """Record a stage computed elsewhere (e.g. by a worker) with its wall time; log its end."""
        self.timings[name] = seconds
        self.stored.add(name)
        text = json.dumps({"key": key, "seconds": seconds, "result": result}, indent=1)
        atomic_write(self.path(name), lambda fh: fh.write(text.encode()))
        self.log(f"[{name}] done in {seconds:.1f} s{where}")
        self._notify("stage_finished", name, seconds, False)
        return result

    def run(self, name: str, key: str, compute):
        """Return the cached result of stage ``name`` for ``key``, or compute and store it.

        ``compute()`` returns a JSON-serialisable dict; its wall time is recorded.
        """
        stored = self._stored(name, key)
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
