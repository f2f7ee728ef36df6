"""One executor interface for the study's independent jobs.

``executor.map(fn, items)`` yields results in order, each as soon as it and those
before it are done (so the study logs each stage's end when it ends, not when the
last job does). ``fn`` must be a picklable top-level function and each item carries
its own seed, so results do not depend on which executor ran them. Workers draw no
bars; each job logs its own start and end there (:func:`mdaug.reports.jobs.announced`).

* :class:`SerialExecutor`: in this process (the default with one worker);
* :class:`ProcessExecutor`: local processes (concurrent.futures);
* :class:`DaskExecutor`: a dask.distributed cluster (``--scheduler ADDRESS``), or a
  LocalCluster it starts itself when the address is ``local``.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor


class SerialExecutor:
    name = "serial"

    def map(self, fn, items):
        return [fn(item) for item in items]

    def close(self) -> None:
        pass


class ProcessExecutor:
    name = "processes"

    def __init__(self, workers: int):
        self.workers = workers
        self._pool = None

    def map(self, fn, items):
        """Results in order; on an interrupt (Ctrl-C, SIGTERM) or any error the workers are
        stopped and waited for before it propagates (:mod:`mdaug.radar.workers`)."""
        import os

        from ..radar.workers import worker_init

        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, initializer=worker_init,
                                             initargs=(os.getpid(),))
        return self._results(self._pool.map(fn, items))  # an iterator: results in order, as they come

    def _results(self, results):
        try:
            yield from results
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        """Cancel what is pending and terminate the workers now."""
        from ..radar.workers import stop_pool

        if self._pool is not None:
            stop_pool(self._pool)
            self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()


class DaskExecutor:
    name = "dask"

    def __init__(self, address: str, workers: int = 1):
        from distributed import Client, LocalCluster

        if address == "local":
            self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                         dashboard_address=None)
            self.client = Client(self._cluster)
        else:
            self._cluster = None
            self.client = Client(address, timeout="20s")

    def map(self, fn, items):
        futures = self.client.map(fn, list(items), pure=False)
        return self._results(futures)  # in order, as they come

    def _results(self, futures):
        try:
            for f in futures:
                yield f.result()
        except BaseException:  # interrupted: nothing more of these jobs runs
            import contextlib

            with contextlib.suppress(Exception):
                self.client.cancel(futures)
                self.close()
            raise

    def close(self) -> None:
        client, self.client = self.client, None
        if client is None:
            return
        client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(workers: int = 1, scheduler: str | None = None):
    """Dask when a scheduler address is given, local processes for workers > 1, else serial."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if scheduler:
        return DaskExecutor(scheduler, workers)
    return ProcessExecutor(workers) if workers > 1 else SerialExecutor()
