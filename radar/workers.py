"""Worker processes that stop with their parent.

* :func:`worker_init`, the initializer of every local worker process: no progress
  bars (:func:`.progress.quiet_worker`), SIGINT ignored (Ctrl-C on a terminal reaches
  the whole process group: the parent alone answers it, with its one line, and stops
  the workers; no worker prints a traceback), and on Linux the worker is sent SIGTERM
  when its parent dies, however it dies;
* :func:`stop_processes`: the parent's stop, on an interrupt or termination: every
  worker is terminated and waited for, so that nothing of theirs is written after
  the parent's last line.
* :func:`terminate_as_interrupt`: SIGTERM handled like Ctrl-C (a
  :class:`Terminated`, a KeyboardInterrupt) for the duration of a command.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys

from .progress import quiet_worker

PR_SET_PDEATHSIG = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C's KeyboardInterrupt."""


def was_terminated(exc: BaseException | None) -> bool:
    """Whether ``exc`` is, or was raised while handling or from, a :class:`Terminated`
    (a sampler turns the interrupt into its own KeyboardInterrupt)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Terminated):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def worker_init(parent: int | None = None) -> None:
    """``parent``: the parent's pid (a worker whose parent is already gone exits)."""
    quiet_worker()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if parent is not None and os.getppid() != parent:  # the parent died before the line above
            os._exit(1)


def stop_processes(processes, timeout: float = 5.0) -> None:
    """Terminate ``processes`` (multiprocessing.Process objects) and wait for them
    (killed after ``timeout`` seconds)."""
    processes = [p for p in processes if p is not None]
    for p in processes:
        with contextlib.suppress(Exception):
            p.terminate()
    for p in processes:
        with contextlib.suppress(Exception):
            p.join(timeout)
            if p.is_alive():
                p.kill()
                p.join(1.0)


def stop_pool(pool, timeout: float = 5.0) -> None:
    """Stop a concurrent.futures ProcessPoolExecutor now: pending jobs cancelled, its
    workers terminated and waited for, and then its manager thread (which closes the
    pool's wake-up pipe as it ends: left running, it races the interpreter's exit hook,
    which writes to that pipe, and Python 3.11 then prints "Exception ignored ... Bad file
    descriptor" after the command's one line)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    with contextlib.suppress(Exception):
        pool.shutdown(wait=False, cancel_futures=True)
    stop_processes(processes)
    manager = getattr(pool, "_executor_manager_thread", None)
    if manager is not None:
        with contextlib.suppress(Exception):
            manager.join(timeout)


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread (the
    command then ends as on Ctrl-C: workers stopped, one line); the previous handler
    is restored afterwards. Outside the main thread, nothing changes."""
    def handler(signum, frame):
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
