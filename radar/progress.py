"""Progress bars for long steps, and the one switch that silences them.

Every step longer than a few seconds (calibration, CNN epochs, sweep cells, study
stages) draws a tqdm bar with an ETA on stderr, through :func:`progress_bar`. A bar
is drawn only when

* stderr is a terminal (never in a log file, a pipe or a test), and
* quiet is off: ``mdaug --quiet`` (or the environment variable ``MDAUG_QUIET=1``,
  which worker processes inherit) silences every bar and the status chatter.

Library functions take ``progress=None`` (automatic: the rule above), ``False``
(never) or ``True`` (even when stderr is not a terminal; still silenced by quiet).
"""
from __future__ import annotations

import os
import sys

QUIET_ENV = "MDAUG_QUIET"
NO_BARS_ENV = "MDAUG_NO_BARS"  # set in worker processes: no bars, status lines as in the parent
_TRUE = ("1", "true", "yes", "on")


def is_quiet() -> bool:
    """Whether progress and status chatter are silenced (``MDAUG_QUIET``)."""
    return os.environ.get(QUIET_ENV, "").strip().lower() in _TRUE


def set_quiet(quiet: bool = True) -> bool:
    """Switch quiet on or off for this process and the workers it starts; returns
    the previous setting."""
    before = is_quiet()
    os.environ[QUIET_ENV] = "1" if quiet else "0"
    return before


def quiet_worker() -> None:
    """Initializer of worker processes: their bars would garble the parent's on the
    same terminal, so workers draw none (the parent shows the jobs' progress). Their
    status lines (a job's start and end) print as the parent's do: silenced only by
    quiet, which the workers inherit."""
    os.environ[NO_BARS_ENV] = "1"


def in_worker() -> bool:
    """Whether this process is a worker of another (a process pool's or dask's)."""
    import multiprocessing

    return multiprocessing.parent_process() is not None or os.environ.get(NO_BARS_ENV) == "1"


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def progress_enabled(progress: bool | None = None, stream=None) -> bool:
    """Whether to draw a bar: ``progress`` None = stderr is a terminal, True = always,
    False = never; quiet wins over all three."""
    if is_quiet() or progress is False or os.environ.get(NO_BARS_ENV) == "1":
        return False
    if progress is True:
        return True
    return _isatty(sys.stderr if stream is None else stream)


def progress_bar(iterable=None, *, total=None, desc: str | None = None, unit: str = "it",
                 progress: bool | None = None, leave: bool | None = None, **kw):
    """A tqdm bar on stderr (elapsed, rate and ETA), disabled by :func:`progress_enabled`.

    Same interface as ``tqdm.tqdm``; a disabled bar still iterates and accepts
    ``update`` / ``set_postfix``, so callers need no branches. ``leave`` None keeps
    an outermost bar on screen when it ends and removes a nested one.
    """
    from tqdm import tqdm

    show = progress_enabled(progress)
    if show:  # follow the terminal's size; a pty that reports 0 x 0 gets 100 x 50
        try:
            size = os.get_terminal_size(sys.stderr.fileno())
        except (OSError, ValueError, AttributeError):
            size = os.terminal_size((0, 0))
        if size.columns > 0 and size.lines > 0:
            kw.setdefault("dynamic_ncols", True)
        else:
            kw.setdefault("ncols", size.columns if size.columns > 0 else 100)
            kw.setdefault("nrows", size.lines if size.lines > 0 else 50)
    return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, leave=leave, disable=not show, **kw)


def echo(message: str = "", *, err: bool = False, force: bool = False) -> None:
    """Print a status line without breaking an active bar; silent when quiet
    (unless ``force``: results and warnings are always printed)."""
    if is_quiet() and not force:
        return
    stream = sys.stderr if err else sys.stdout
    from tqdm import tqdm

    if getattr(tqdm, "_instances", None):
        tqdm.write(message, file=stream)
    else:  # one write of the whole line: workers sharing the terminal do not interleave halves
        stream.write(f"{message}\n")
        stream.flush()
