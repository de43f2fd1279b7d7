"""Where chunks run: this process, a private loky pool, or a dask.distributed cluster.

:data:`BACKENDS` maps ``execution.backend`` to its pool class; the config schema and the
command line take their choices from it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, Protocol, TypeVar

from pcmb.errors import MissingDependencyError

__all__ = ["BACKENDS", "DaskPool", "InProcessPool", "LokyPool", "Pool"]

_T = TypeVar("_T")


class Pool(Protocol):
    """Where chunks run: submit callables, report worker deaths, rebuild, close.

    Built as ``Pool(jobs, workers, address)``; ``startup_seconds`` is the estimated cost of
    starting it, which the executor weighs against running the rest in this process.
    """

    slots: int
    startup_seconds: float

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]: ...

    def death(self, error: BaseException) -> str | None:
        """A message if ``error`` means the worker running the task died, else None."""

    def rebuild(self) -> None: ...

    def close(self) -> None: ...


#: Environment variables that cap native thread pools in worker processes.
_THREAD_LIMITS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


class LokyPool:
    """A private loky process pool (joblib's process backend), shut down after the campaign.

    Private rather than joblib's global reusable pool: sharing that singleton breaks a later
    ``joblib.Parallel`` in the user's process, which expects the pool to be set up its own way.
    """

    startup_seconds = 1.0

    def __init__(self, jobs: int | None, workers: int, address: str | None = None) -> None:
        self.slots = workers
        self._executor: Any = None
        self.rebuild()

    def rebuild(self) -> None:
        from joblib.externals.loky import ProcessPoolExecutor

        # A broken pool is replaced by a fresh one here. Each worker gets its share of the cores
        # for native thread pools (BLAS, OpenMP, MuJoCo's threads), as joblib.Parallel does,
        # so that `slots` workers do not each start one thread per core.
        share = str(max(1, (os.cpu_count() or 1) // self.slots))
        if self._executor is not None:
            self._executor.shutdown(wait=False, kill_workers=True)
        self._executor = ProcessPoolExecutor(
            max_workers=self.slots, env={name: share for name in _THREAD_LIMITS}
        )

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        return self._executor.submit(fn, *args)

    def death(self, error: BaseException) -> str | None:
        from joblib.externals.loky.process_executor import TerminatedWorkerError

        if not isinstance(error, TerminatedWorkerError):
            return None
        # loky reports e.g. "The exit codes of the workers are {SIGSEGV(-11)}" or "{EXIT(7)}".
        codes = re.findall(r"([A-Z]+)\((-?\d+)\)", str(error).partition("exit codes")[2])
        causes = [
            f"signal {-int(code)}, {name}" if int(code) < 0 else f"exit code {code}"
            for name, code in codes
        ]
        return f"worker process died ({'; '.join(causes) or 'cause unknown'})"

    def close(self) -> None:
        self._executor.shutdown(wait=True)


class DaskPool:
    """A dask.distributed cluster: ``address``, or a local cluster that is closed afterwards."""

    startup_seconds = 3.0

    def __init__(self, jobs: int | None, workers: int, address: str | None = None) -> None:
        try:
            import dask
            import distributed
        except ImportError as error:
            raise MissingDependencyError("distributed", "dask", "backend dask") from error

        self._killed = distributed.KilledWorker
        self._cluster = None
        if address is None:
            # Report a task at its first worker death (dask would try it on 3 more workers,
            # killing each): the executor's own isolation then names the node.
            with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                self._cluster = distributed.LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
                )
        try:
            self._client = distributed.Client(address or self._cluster)
        except BaseException:
            if self._cluster is not None:
                self._cluster.close()
            raise
        self.slots = jobs or sum(self._client.nthreads().values()) or 1
        # pure=False: a re-run of a task must run again, not come back from dask's cache.
        self._executor = self._client.get_executor(pure=False)

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        return self._executor.submit(fn, *args)

    def death(self, error: BaseException) -> str | None:
        # dask reschedules a task whose worker died, until its allowed failures are used up.
        if isinstance(error, self._killed):
            return "worker process died (dask KilledWorker: see the dask worker logs)"
        return None

    def rebuild(self) -> None:
        """Nothing to do: dask's nannies restart dead workers."""

    def close(self) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


class InProcessPool:
    """Runs each task in this process, one at a time (no start-up cost, no isolation)."""

    slots = 1
    startup_seconds = 0.0

    def __init__(self, jobs: int | None = None, workers: int = 1, address: str | None = None):
        pass

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        future: Future[_T] = Future()
        try:
            future.set_result(fn(*args))
        except Exception as error:
            future.set_exception(error)
        return future

    def death(self, error: BaseException) -> str | None:
        return None

    def rebuild(self) -> None:
        """Nothing to rebuild."""

    def close(self) -> None:
        """Nothing to close."""


#: ``execution.backend`` -> pool class.
BACKENDS: dict[str, type[Pool]] = {
    "loky": LokyPool,
    "dask": DaskPool,
    "inprocess": InProcessPool,
}
