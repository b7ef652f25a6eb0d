"""Where envelope tasks run: in this process, on a pool of local processes, or on a Dask cluster.

Each executor has ``map_unordered(function, tasks)`` (results as they finish), ``abort()``, ``close()``,
``workers`` and ``description``; the computation (:mod:`.compute`) does not care which it gets, and the
result is identical for all of them.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import Any

__all__ = ["SerialExecutor", "WorkerDiedError", "make_executor"]


class WorkerDiedError(RuntimeError):
    """A local worker process ended abruptly (a crash in native code, or killed) while tasks were outstanding."""


def _ignore_interrupts() -> None:
    """Worker initialiser: Ctrl-C reaches the whole process group; only the coordinator handles it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# --- executors --------------------------------------------------------------------------------------------


class SerialExecutor:
    """Runs tasks in this process (one worker)."""

    description = "1 worker (in process)"
    workers = 1

    def map_unordered(self, function: Callable[..., Any], tasks: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        for arguments in tasks:
            yield function(*arguments)

    def abort(self) -> None:
        pass

    def close(self) -> None:
        pass


class _ProcessExecutor:
    """A pool of local worker processes (forkserver: workers start from a process that imported CasADi once).

    A ``concurrent.futures`` pool, not ``multiprocessing.Pool``: when a worker dies mid-task (a segmentation fault
    in a native library, the OOM killer), ``multiprocessing.Pool`` replaces it and loses its task, and the
    computation waits for that result for ever; here the outstanding tasks fail and :class:`WorkerDiedError` is raised.
    """

    def __init__(self, workers: int) -> None:
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["helireach_ros.core.envelope.compute", "helireach_ros.core.planning.planner"])
        self.workers = workers
        self.description = f"{workers} local worker processes"
        self._pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=context, initializer=_ignore_interrupts)
        self._futures: list[concurrent.futures.Future] = []

    def map_unordered(self, function: Callable[..., Any], tasks: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        self._futures = [self._pool.submit(function, *arguments) for arguments in tasks]
        try:
            for future in concurrent.futures.as_completed(self._futures):
                yield future.result()
        except BrokenProcessPool as error:
            raise WorkerDiedError(
                "a worker process died with tasks outstanding (a crash in native code, or killed: see the system log)"
            ) from error
        finally:
            self._futures = []

    def abort(self) -> None:
        for future in self._futures:
            future.cancel()
        # the running tasks are not waited for: a solve can take seconds, and an abort is an interrupt or an error
        # (ProcessPoolExecutor has no public way to stop its workers before Python 3.14's terminate_workers)
        for process in list(getattr(self._pool, "_processes", {}).values()):
            process.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        self._pool.shutdown(wait=True)


class _DaskExecutor:
    """Tasks on a Dask distributed cluster (workers need helireach_ros installed)."""

    def __init__(self, address: str, timeout_s: float = 30.0, description: str | None = None) -> None:
        from distributed import Client

        self._client = Client(address, timeout=timeout_s, set_as_default=False)
        self.workers = max(1, sum(self._client.nthreads().values()))
        self.description = f"{description or f'Dask scheduler {address}'} ({self.workers} worker threads)"
        self._futures: list[Any] = []

    def map_unordered(self, function: Callable[..., Any], tasks: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        from distributed import as_completed

        self._futures = [self._client.submit(function, *arguments, pure=False) for arguments in tasks]
        for future in as_completed(self._futures, loop=self._client.loop):
            yield future.result()
        self._futures = []

    def abort(self) -> None:
        if self._futures:
            self._client.cancel(self._futures)
        self._futures = []

    def close(self) -> None:
        self._client.close()


class _LocalDaskExecutor(_DaskExecutor):
    """A Dask ``distributed.LocalCluster`` of ``workers`` single-threaded worker processes, started and stopped here.

    One thread per worker: an IPOPT solve holds the GIL for most of its time, so threads in one process
    would queue behind each other.
    """

    def __init__(self, workers: int) -> None:
        from distributed import LocalCluster

        self._cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        )
        try:
            super().__init__(self._cluster.scheduler_address, description=f"Dask LocalCluster, {workers} processes")
        except BaseException:
            self._cluster.close()
            raise

    def close(self) -> None:
        try:
            super().close()
        finally:
            self._cluster.close()


def make_executor(workers: int | None = None, scheduler: str | None = None, dask_local: int | None = None):
    """The executor for ``--workers N`` (default: every core), ``--scheduler ADDRESS`` (Dask) or
    ``--dask-local N`` (a Dask LocalCluster of N worker processes on this machine).

    Returns:
        An object with ``map_unordered(function, tasks)``, ``abort()``, ``close()``, ``description``.
    """
    if scheduler:
        return _DaskExecutor(scheduler)
    if dask_local is not None:
        if dask_local < 1:
            raise ValueError(f"--dask-local needs >= 1 worker, got {dask_local}")
        return _LocalDaskExecutor(dask_local)
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count < 1:
        raise ValueError(f"workers must be >= 1, got {count}")
    return SerialExecutor() if count == 1 else _ProcessExecutor(count)
