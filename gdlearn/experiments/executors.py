"""Where experiment tasks run: in this process, a local process pool, or a Dask cluster.

Every executor has ``map(fn, items) -> list`` returning results in the order of ``items``, and is a
context manager that releases what it started. Tasks are deterministic functions of their
arguments (seeds included; see :mod:`.progressive` on determinism), so every executor returns the
same images and errors for the same tasks -- only wall-clock timings differ.

* :class:`SerialExecutor`: a plain loop, for debugging and for the book.
* :class:`LocalExecutor` (the default): a ``concurrent.futures`` process pool. Processes are
  *spawned*, not forked: forking a process whose numba threading layer is already running is
  unsafe. Its default is **one worker**: an equal-time study measures wall time, and two tasks
  running side by side on a 2-core machine would slow each other down unevenly. Raise
  ``max_workers`` for pass budgets (equal samples), where timing does not decide the outcome.
* :class:`DaskExecutor`: Dask distributed, the scale-out path. Give a scheduler address
  (``tcp://host:8786``) to use an existing cluster, or nothing to start a ``LocalCluster`` of
  worker processes on loopback, which is closed with the executor.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
import multiprocessing


class SerialExecutor:
    """Runs tasks one after the other in the calling process."""

    def map(self, fn, items) -> list:
        return [fn(x) for x in items]

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class LocalExecutor(SerialExecutor):
    """A pool of ``max_workers`` spawned processes (default 1: see the module docstring)."""

    def __init__(self, max_workers: int = 1):
        if max_workers < 1:
            raise ValueError(f"max_workers={max_workers} must be >= 1")
        self.max_workers = int(max_workers)

    def map(self, fn, items) -> list:
        items = list(items)
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=min(self.max_workers, max(len(items), 1)),
                                 mp_context=ctx) as pool:
            return list(pool.map(fn, items))


class DaskExecutor(SerialExecutor):
    """Dask distributed: ``DaskExecutor("tcp://10.0.0.5:8786")`` or ``DaskExecutor()`` for a
    ``LocalCluster(n_workers, processes=True, threads_per_worker=1)`` on 127.0.0.1.

    One thread per worker because each task already uses the machine's cores through numba; a
    worker running two renders at once would distort their timings.
    """

    def __init__(self, address: str | None = None, *, client=None, n_workers: int = 2,
                 threads_per_worker: int = 1, upload_files=()):
        try:
            from distributed import Client, LocalCluster
        except ImportError as err:      # pragma: no cover - dask is an optional extra
            raise RuntimeError("the Dask executor needs the [dist] extra: pip install "
                               "'gdlearn[dist]' (dask[distributed])") from err
        self._cluster = None
        self._own_client = client is None
        if client is not None:
            self.client = client
        elif address is not None:
            self.client = Client(address)
        else:
            self._cluster = LocalCluster(n_workers=n_workers, processes=True,
                                         threads_per_worker=threads_per_worker, host="127.0.0.1",
                                         dashboard_address=None)
            self.client = Client(self._cluster)
        for path in upload_files:       # e.g. a module defining a custom integrator
            self.client.upload_file(str(path))

    def map(self, fn, items) -> list:
        futures = self.client.map(fn, list(items), pure=False)
        return self.client.gather(futures)

    def close(self) -> None:
        if self._own_client:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def get_executor(spec=None):
    """An executor from a short description.

    ``None`` or ``"local"`` -> :class:`LocalExecutor`; ``"local:N"`` -> N workers; ``"serial"``;
    ``"dask"`` -> Dask ``LocalCluster``; ``"tcp://host:port"`` (or any ``scheme://``) -> the Dask
    scheduler at that address; an executor object is returned as is.
    """
    if spec is None or spec == "local":
        return LocalExecutor()
    if not isinstance(spec, str):
        return spec
    if spec == "serial":
        return SerialExecutor()
    if spec.startswith("local:"):
        return LocalExecutor(int(spec.split(":", 1)[1]))
    if spec == "dask":
        return DaskExecutor()
    if "://" in spec:
        return DaskExecutor(spec)
    raise ValueError(f"unknown executor {spec!r}; use 'local', 'local:N', 'serial', 'dask' or a "
                     "Dask scheduler address such as tcp://127.0.0.1:8786")
