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
        if self._pool is None:
            from ..radar.progress import quiet_worker

            self._pool = ProcessPoolExecutor(max_workers=self.workers, initializer=quiet_worker)
        return self._pool.map(fn, items)  # an iterator: results in order, as they come

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
        return (f.result() for f in futures)  # in order, as they come

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(workers: int = 1, scheduler: str | None = None):
    """Dask when a scheduler address is given, local processes for workers > 1, else serial."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if scheduler:
        return DaskExecutor(scheduler, workers)
    return ProcessExecutor(workers) if workers > 1 else SerialExecutor()
