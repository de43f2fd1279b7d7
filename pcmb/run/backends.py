"""Where chunks run: a private loky pool of child processes, a dask.distributed cluster, or
(for debugging only) this process.

:data:`BACKENDS` maps ``execution.backend`` to its pool class; the config schema and the
command line take their choices from it. :func:`open_pool` hands one to a campaign; loky pools
are started early (:func:`warm_up`) and kept warm between campaigns. A model is checked in
:func:`checking_pool`: the kept loky workers, or, within :func:`checking_process` (``pcmb
validate``), one short-lived worker process (:class:`OneProcessPool`).
"""

from __future__ import annotations

import atexit
import functools
import gc
import logging
import os
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from contextvars import ContextVar
from typing import Any, Protocol, TypeVar

from pcmb.errors import ClusterError, ConfigProblem, MissingDependencyError, UsageError
from pcmb.run.files import process_running
from pcmb.run.lifeline import die_with_parent, tag
from pcmb.run.threads import THREAD_LIMITS, one_thread_here
from pcmb.wording import plural, signal_name

__all__ = [
    "BACKENDS",
    "CONNECT_SECONDS",
    "GREET_SECONDS",
    "DaskPool",
    "InProcessPool",
    "LokyPool",
    "OneProcessPool",
    "Pool",
    "checking_pool",
    "checking_process",
    "default_workers",
    "describe_cluster",
    "open_pool",
    "silenced",
]

_T = TypeVar("_T")


class Pool(Protocol):
    """Where chunks run: submit callables, report worker deaths, rebuild, close.

    Built as ``Pool(jobs, workers, address, key)``: ``key`` names the setting ``address``
    came from, for messages (only dask uses an address). ``startup_seconds`` is the estimated
    time its workers take to start (allowed on top of a task's timeout); ``kills`` says
    whether :meth:`rebuild` kills the workers running tasks, which a timeout needs.
    """

    slots: int
    startup_seconds: float
    kills: bool

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]: ...

    def death(self, error: BaseException) -> str | None:
        """A message if ``error`` means the worker running the task died, else None."""

    def rebuild(self) -> None:
        """Replace broken or stuck workers; tasks in flight are lost."""

    def close(self, kill: bool = False) -> None:
        """Release the workers: after their tasks end, or at once with ``kill``."""


def _warm_up() -> None:
    """Import what tasks need (the worker's side of the executor, and what python models
    commonly build on: their adapter and pcmb's batched integrator), so that the first task does
    not wait for it."""
    import pcmb.adapters.python.model
    import pcmb.integrate.stacked_ode
    import pcmb.run.worker  # noqa: F401


class LokyPool:
    """A private loky process pool (joblib's process backend), shut down after the campaign.

    Private rather than joblib's global reusable pool: sharing that singleton breaks a later
    ``joblib.Parallel`` in the user's process, which expects the pool to be set up its own way.
    """

    startup_seconds = 1.0
    kills = True

    def __init__(
        self, jobs: int | None, workers: int, address: Any = None, key: str = "address"
    ) -> None:
        self.slots = workers
        self._executor: Any = None
        # The named semaphores of the executors made (rebuilt ones too), which close waits for.
        self._semaphores: set[str] = set()
        remove_orphaned_semaphores()
        self.rebuild()

    def rebuild(self) -> None:
        from joblib.externals.loky import ProcessPoolExecutor

        # A broken pool is replaced by a fresh one here. Each worker gets its share of the cores
        # for native thread pools (BLAS, OpenMP, MuJoCo's threads), as joblib.Parallel does,
        # so that `slots` workers do not each start one thread per core.
        share = str(max(1, (os.cpu_count() or 1) // self.slots))
        if self._executor is not None:
            self._settle()
            self._executor.shutdown(wait=False, kill_workers=True)
        with _MAKING:  # no other pool's semaphores are made meanwhile
            before = _semaphores_of_this_process()
            self._executor = ProcessPoolExecutor(
                max_workers=self.slots,
                # Tagged: what the workers start ends with this process too (see lifeline.tag).
                env={**dict.fromkeys(THREAD_LIMITS, share), **tag()},
                # A worker must not go on running a model after pcmb died (kill -9, a crash).
                initializer=die_with_parent,
                initargs=(os.getpid(),),
            )
            self._semaphores |= _semaphores_of_this_process() - before
        # Start the workers now, while the caller prepares the work.
        self._submitted = [self._executor.submit(_warm_up) for _ in range(self.slots)]

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        from concurrent.futures import BrokenExecutor

        try:
            future = self._executor.submit(fn, *args)
        except BrokenExecutor:  # a worker died after its last task was reported: start afresh
            self.rebuild()
            future = self._executor.submit(fn, *args)
        self._submitted = [f for f in self._submitted if not f.done()] + [future]
        return future

    def _settle(self, seconds: float = 1.0) -> None:
        """Wait (briefly) until loky has moved every task submitted to its call queue: killing
        its workers while a task still waits outside the queue breaks its manager thread."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and any(
            not (f.running() or f.done()) for f in self._submitted
        ):
            time.sleep(0.005)

    def death(self, error: BaseException) -> str | None:
        from joblib.externals.loky.process_executor import TerminatedWorkerError

        if not isinstance(error, TerminatedWorkerError):
            return None
        # loky reports e.g. "The exit codes of the workers are {SIGSEGV(-11)}" or "{EXIT(7)}".
        codes = re.findall(r"[A-Z]+\((-?\d+)\)", str(error).partition("exit codes")[2])
        return _died([int(code) for code in codes])

    def close(self, kill: bool = False) -> None:
        if kill:
            self._settle()
        # Waited for, and its queues collected now, even when killing: else their named
        # semaphores are freed by loky's daemon threads while the interpreter exits, which can
        # freeze them between unlinking one and telling the resource tracker, who then warns on
        # stderr of a leaked semaphore it cannot find.
        self._executor.shutdown(wait=True, kill_workers=kill)
        self._executor = None
        gc.collect()
        _until_unlinked(self._semaphores, _FREE_SECONDS)


#: A loky named semaphore's file, named after the process that made it (loky's SemLock names).
_LOKY_SEMAPHORE = re.compile(r"sem\.loky-(\d+)-\w+")

#: Where named semaphores are files (Linux); elsewhere none is seen, and none waited for.
_SEMAPHORE_FOLDER = "/dev/shm"

#: Held while a loky pool is made, so that the semaphores made meanwhile are its own.
_MAKING = threading.Lock()

#: The most seconds :meth:`LokyPool.close` waits for its pool's semaphores to be unlinked.
_FREE_SECONDS = 5.0


def _loky_semaphores(
    folder: str | os.PathLike[str],
) -> Iterator[tuple[os.DirEntry[str], int]]:
    """The files in ``folder`` named as loky's semaphores, each with the pid of the process
    that made it (none without ``folder``)."""
    try:
        entries = list(os.scandir(folder))
    except OSError:  # no such folder: named semaphores live elsewhere on this system
        return
    for entry in entries:
        if match := _LOKY_SEMAPHORE.fullmatch(entry.name):
            yield entry, int(match[1])


def _semaphores_of_this_process() -> set[str]:
    """The files of the loky semaphores this process holds now."""
    mine = os.getpid()
    return {entry.path for entry, pid in _loky_semaphores(_SEMAPHORE_FOLDER) if pid == mine}


def _until_unlinked(semaphores: set[str], seconds: float) -> None:
    """Wait, at most ``seconds``, until none of the files ``semaphores`` exists (a pool's
    whose executor was rebuilt and shut down without waiting are among them).

    loky's ``shutdown(wait=True)`` returns once its manager thread has ended, but its call
    queue's feeder thread may still be running: the queue's ``join_thread`` waits only for
    queues made by another process (multiprocessing's rule), and the thread holds the queue's
    two locks and bounded semaphore until it ends, under load after ``shutdown`` returned.
    They are unlinked when the queue is collected, right after.
    """
    deadline, pause = time.monotonic() + seconds, 0.002
    while any(map(os.path.exists, semaphores)) and time.monotonic() < deadline:
        time.sleep(pause)
        gc.collect()
        pause = min(2 * pause, 0.1)


def remove_orphaned_semaphores(folder: str | os.PathLike[str] = _SEMAPHORE_FOLDER) -> int:
    """Unlink the named semaphores of loky pools whose process is gone: a ``kill -9`` of
    pcmb's process group kills loky's resource tracker too, which would have unlinked them.
    Only this user's regular files named ``sem.loky-PID-*`` whose process PID has ended (a
    pid reused since keeps them). The number removed (0 without ``folder``)."""
    ended: dict[int, bool] = {}
    removed = 0
    for entry, pid in _loky_semaphores(folder):
        if pid not in ended:
            ended[pid] = not process_running(pid)
        try:
            if not (
                ended[pid]
                and entry.is_file(follow_symlinks=False)
                and entry.stat(follow_symlinks=False).st_uid == os.geteuid()
            ):
                continue
            os.unlink(entry.path)
        except OSError:  # removed meanwhile (by its tracker, another run), or not ours to remove
            continue
        removed += 1
    return removed


def _died(codes: Iterable[int]) -> str:
    """The message of a worker death, from exit codes (negative: the signal that killed it)."""
    causes = [
        f"signal {-code}, {signal_name(-code)}" if code < 0 else f"exit code {code}"
        for code in codes
    ]
    return f"worker process died ({'; '.join(causes) or 'cause unknown'})"


class _WorkerDied(Exception):
    """The worker process of a :class:`OneProcessPool` ended while it ran a task."""

    def __init__(self, exitcode: int | None) -> None:
        super().__init__(exitcode)
        self.exitcode = exitcode


def _serve(connection: Any, parent: int, environment: dict[str, str]) -> None:
    """The worker of a :class:`OneProcessPool`: run each task received, send back its result
    or its exception, until the pool closes the connection."""
    os.environ.update(environment)  # before any native library loads
    die_with_parent(parent)
    import pickle

    _warm_up()
    # The designs whose checks run here too (Galerkin's polynomial form), while the caller
    # reads the config.
    import pcmb.designs  # noqa: F401

    while True:
        try:
            fn, args = pickle.loads(connection.recv_bytes())
        except (EOFError, KeyboardInterrupt):  # closed, or the user's Ctrl-C while idle
            return
        try:
            reply: tuple[bool, Any] = (True, fn(*args))
        except BaseException as error:  # the caller's to raise, as a loky worker does
            reply = (False, error)
        try:
            connection.send(reply)
        except Exception as error:  # an unpicklable result or exception
            connection.send((False, TypeError(f"cannot send the task's result back: {error}")))


class OneProcessPool:
    """One worker process, started at once, that runs its tasks one at a time: what checking a
    model needs, without the import and the workers of a loky pool.

    The process is a fresh interpreter (multiprocessing's ``spawn``), tagged and dying with
    this process as loky's workers do (:mod:`pcmb.run.lifeline`). :meth:`submit` waits for
    the task, so an interrupt meanwhile reaches the caller at once.
    """

    slots = 1
    startup_seconds = 1.0
    kills = True

    def __init__(self) -> None:
        self._process: Any = None
        self.rebuild()

    def rebuild(self) -> None:
        import multiprocessing

        if self._process is not None:
            self.close(kill=True)
        context = multiprocessing.get_context("spawn")
        self._connection, theirs = context.Pipe()
        environment = {**dict.fromkeys(THREAD_LIMITS, str(os.cpu_count() or 1)), **tag()}
        self._process = context.Process(
            target=_serve, args=(theirs, os.getpid(), environment), name="pcmb-worker"
        )
        self._process.start()
        theirs.close()

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        from multiprocessing.connection import wait

        import cloudpickle

        future: Future[_T] = Future()
        try:
            self._connection.send_bytes(cloudpickle.dumps((fn, args)))
            # The reply, or the end of the process: whichever comes first.
            wait([self._connection, self._process.sentinel])
            ok, value = self._connection.recv()
        except (EOFError, OSError):  # the process ended before it replied
            self._process.join()
            future.set_exception(_WorkerDied(self._process.exitcode))
            return future
        if ok:
            future.set_result(value)
        else:
            future.set_exception(value)
        return future

    def death(self, error: BaseException) -> str | None:
        if not isinstance(error, _WorkerDied):
            return None
        return _died([] if error.exitcode is None else [error.exitcode])

    def close(self, kill: bool = False) -> None:
        """End the worker at once, ``kill`` or not: :meth:`submit` waits for each task, so
        it is idle now, with nothing to finish."""
        self._connection.close()
        self._process.kill()
        self._process.join()


#: Seconds pcmb waits for a dask scheduler's address to accept a connection; the scheduler
#: then has until :data:`GREET_SECONDS` from the start to say it is one.
CONNECT_SECONDS = 3.0
GREET_SECONDS = 5.0


def _greet_scheduler(address: str, key: str) -> None:
    """Raise :class:`ClusterError` (its path: ``key``) unless a dask scheduler answers at
    ``address`` within :data:`GREET_SECONDS`.

    ``distributed.Client(address, timeout=...)`` bounds the connection, not the greeting that
    follows: a program at that port that is not dask accepts and never answers, and the client
    waits forever. So the scheduler is asked who it is (distributed's ``rpc``) under a deadline
    first, in a thread of its own (the caller may be running an event loop).
    """
    import asyncio  # here: 30 ms of import that only a scheduler address needs

    import distributed

    # The client's TLS settings of the dask config, as distributed.Client takes them.
    connection = distributed.Security().get_connection_args("client")

    async def identity() -> dict[str, Any]:
        async with distributed.rpc(
            address, timeout=CONNECT_SECONDS, connection_args=connection
        ) as remote:
            return await remote.identity()

    async def within_deadline() -> dict[str, Any]:
        return await asyncio.wait_for(identity(), GREET_SECONDS)

    def refused(message: str) -> ClusterError:
        return ClusterError([ConfigProblem(key, message)])

    with ThreadPoolExecutor(1) as thread:
        try:
            found = thread.submit(asyncio.run, within_deadline()).result()
        except (ValueError, TypeError) as error:
            raise refused(
                f"{address!r} is not a dask scheduler address ({error}); "
                "expected e.g. tcp://HOST:8786"
            ) from None
        except TimeoutError:  # connected, but no answer
            raise refused(
                f"{address} did not answer as a dask scheduler within {GREET_SECONDS:g} s: "
                "is this the address the scheduler printed, not another program's?"
            ) from None
        except OSError as error:
            raise refused(
                f"no dask scheduler answered at {address} ({error}): is the scheduler "
                "running, and is this the address it printed?"
            ) from None
    kind = found.get("type") if isinstance(found, dict) else None
    if kind != "Scheduler":
        raise refused(
            f"{address} is a dask {kind or 'server'}, not a scheduler: give the address "
            "the scheduler printed (`dask scheduler`)"
        )


class DaskPool:
    """A dask.distributed cluster: the scheduler at ``address``, a ``distributed.Client`` or
    ``Cluster`` (e.g. ``LocalCluster``) of the caller's, which is left open, or else a local
    cluster started here and closed afterwards.

    ``key`` names the setting the address came from in the error raised when no scheduler
    answers there (:class:`ClusterError`).
    """

    startup_seconds = 3.0
    kills = False

    def __init__(
        self, jobs: int | None, workers: int, address: Any = None, key: str = "address"
    ) -> None:
        try:
            import dask
            import distributed
        except ImportError as error:
            raise MissingDependencyError("distributed", "dask", "backend dask") from error

        self._killed = distributed.KilledWorker
        self._cluster = None  # the local cluster started here, closed here
        self._own_client = not isinstance(address, distributed.Client)
        if not self._own_client:
            self._client = address
        else:
            if address is None:
                # Report a task at its first worker death (dask would try it on 3 more
                # workers, killing each): the executor's own isolation then names the node.
                with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                    self._cluster = distributed.LocalCluster(
                        n_workers=workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",
                        env=tag(),  # what the workers start ends with this process too
                    )
            elif isinstance(address, str):
                _greet_scheduler(address, key)
            elif not isinstance(address, distributed.deploy.Cluster):
                raise UsageError(
                    [
                        ConfigProblem(
                            key,
                            "expected a dask scheduler's address, a distributed.Client or a "
                            f"Cluster, got {type(address).__name__}",
                        )
                    ]
                )
            try:
                self._client = distributed.Client(
                    address or self._cluster, timeout=CONNECT_SECONDS, set_as_default=False
                )
            except BaseException as error:
                if self._cluster is not None:
                    self._cluster.close()
                if isinstance(error, OSError):  # the scheduler went away since it answered
                    message = f"cannot connect to the dask scheduler at {address}: {error}"
                    raise ClusterError([ConfigProblem(key, message)]) from None
                raise
        self.slots = jobs or sum(self._client.nthreads().values()) or 1
        self._tasks: set[Any] = set()  # this pool's dask futures not yet relayed

    def describe(self) -> str:
        """``tcp://127.0.0.1:8786: 2 workers, 2 threads, 4.0 GiB``: the scheduler's address
        and its workers now, with their threads and memory limits."""
        info = self._client.scheduler_info()
        workers = list(info["workers"].values())
        threads = sum(worker["nthreads"] for worker in workers)
        limits = [worker.get("memory_limit") or 0 for worker in workers]
        memory = f"{sum(limits) / 2**30:.1f} GiB" if all(limits) else "memory not limited"
        wait = "" if workers else " (tasks wait until a worker joins)"
        return (
            f"{info['address']}: {plural(len(workers), 'worker')}, "
            f"{plural(threads, 'thread')}, {memory}{wait}"
        )

    def submit(self, fn: Callable[..., _T], *args: Any) -> Future[_T]:
        # pure=False: a re-run of a task must run again, not come back from dask's cache.
        task = self._client.submit(fn, *args, pure=False)
        self._tasks.add(task)
        relayed: Future[_T] = Future()
        relayed.set_running_or_notify_cancel()
        task.add_done_callback(functools.partial(_relay, relayed, self._tasks))
        return relayed

    def death(self, error: BaseException) -> str | None:
        # dask reschedules a task whose worker died, until its allowed failures are used up.
        if isinstance(error, self._killed):
            return "worker process died (dask KilledWorker: see the dask worker logs)"
        return None

    def rebuild(self) -> None:
        """Nothing to do: dask's nannies restart dead workers."""

    def close(self, kill: bool = False) -> None:
        """Close what was started here (its tasks end with it); of a client given, only this
        pool's tasks end (cancelled with ``kill``)."""
        if self._own_client:
            self._client.close()
        elif kill:
            self._client.cancel(list(self._tasks))
        elif self._tasks:
            import distributed

            distributed.wait(list(self._tasks))
        if self._cluster is not None:
            self._cluster.close()


def _relay(relayed: Future[Any], tasks: set[Any], task: Any) -> None:
    """Hand a finished dask future's outcome to ``relayed``, read once by ``result()``.

    Not distributed's ``get_executor()``: it reads a future's status apart from its value, and
    a worker death between the two (a finished result lost, its task run again) made it raise
    ``TypeError: cannot unpack non-iterable Outcome object`` instead of either outcome.
    """
    tasks.discard(task)
    try:
        relayed.set_result(task.result())
    except BaseException as error:  # the task's own error, KilledWorker, CancelledError
        relayed.set_exception(error)


def describe_cluster(address: Any, key: str = "address") -> str:
    """What :meth:`DaskPool.describe` says of the cluster at ``address``, connected for the
    purpose (:class:`ClusterError` naming ``key`` if nothing answers)."""
    pool = DaskPool(None, 1, address, key)
    try:
        return pool.describe()
    finally:
        pool.close()


#: The loggers dask.distributed gives a level of their own (the others inherit theirs).
_DASK_LOGGERS = (
    "distributed",
    "distributed.client",
    "distributed.gc",
    "tornado",
    "tornado.application",
    "bokeh",
)
#: dask's setting of the level of its ``distributed`` logger, read by the processes it starts.
_DASK_LOG_LEVEL = "DASK_LOGGING__DISTRIBUTED"


@contextmanager
def silenced(backend: str) -> Iterator[None]:
    """The backend's own logging limited to CRITICAL messages while the block runs
    (``--quiet``).

    For dask: the loggers of this process (the local cluster's scheduler and nannies, the
    client) and, through the environment, those of the worker processes started meanwhile;
    pcmb reports every failure they would log (a dead worker is a failed node). The other
    backends log nothing.
    """
    if backend != "dask":
        yield
        return
    try:
        import distributed  # noqa: F401  (its import sets the levels: override them after)
    except ImportError:  # the pool says what to install
        yield
        return
    loggers = [logging.getLogger(name) for name in _DASK_LOGGERS]
    levels = [logger.level for logger in loggers]
    environment = os.environ.get(_DASK_LOG_LEVEL)
    os.environ[_DASK_LOG_LEVEL] = "critical"
    for logger in loggers:
        logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)
        if environment is None:
            os.environ.pop(_DASK_LOG_LEVEL, None)
        else:
            os.environ[_DASK_LOG_LEVEL] = environment


class InProcessPool:
    """Runs each task in this process, one at a time: for debugging and profiling a model, with
    no isolation (a crash of the model is a crash of pcmb) and no timeout."""

    slots = 1
    startup_seconds = 0.0
    kills = False

    def __init__(
        self, jobs: int | None = None, workers: int = 1, address: Any = None, key: str = "address"
    ):
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

    def close(self, kill: bool = False) -> None:
        """Nothing to close."""


#: ``execution.backend`` -> pool class.
BACKENDS: dict[str, type[Pool]] = {
    "loky": LokyPool,
    "dask": DaskPool,
    "inprocess": InProcessPool,
}


def default_workers() -> int:
    """Worker processes when ``jobs`` is not given: the cores this process may use."""
    from joblib import cpu_count

    return max(1, cpu_count())


def _workers(backend: str, jobs: int | None, tasks: int | None) -> int:
    workers = jobs or (1 if backend == "inprocess" else default_workers())
    return workers if tasks is None else max(1, min(workers, tasks))


#: Loky pools kept warm between the campaigns of this process, by number of workers.
_KEPT: dict[int, LokyPool] = {}


def close_kept(kill: bool = False) -> None:
    """Close the kept loky pools; ``kill``: at once, busy or not (a process about to end).

    At interpreter exit loky's own hook ends their workers first, gracefully: after their
    tasks, so ``pcmb`` kills them when its command is done instead of waiting for that.
    """
    while _KEPT:
        _KEPT.popitem()[1].close(kill=kill)


atexit.register(close_kept)


def warm_up(jobs: int | None = None, tasks: int | None = None) -> None:
    """Start now the loky workers :func:`open_pool` will hand out for these settings, so that
    they start (and import what tasks need) while the caller prepares the work."""
    workers = _workers("loky", jobs, tasks)
    if workers not in _KEPT:
        _KEPT[workers] = LokyPool(jobs, workers)


#: The worker process of the innermost :func:`checking_process`, if one is open.
_CHECKER: ContextVar[OneProcessPool | None] = ContextVar("pcmb_checker", default=None)


@contextmanager
def checking_process() -> Iterator[None]:
    """While open, :func:`checking_pool` builds models in one worker process, started now (so
    that it starts while the caller reads the config) and ended on exit: for a command that
    checks a model and then runs nothing, ``pcmb validate``."""
    pool = OneProcessPool()
    token = _CHECKER.set(pool)
    try:
        yield
    finally:
        _CHECKER.reset(token)
        pool.close()


@contextmanager
def checking_pool(backend: str, jobs: int | None = None) -> Iterator[Pool]:
    """Where a model of a study on ``backend`` is built to check it: this process for
    ``inprocess``; else the worker of :func:`checking_process` when one is open, or the kept
    loky workers (the ones a loky run then uses; no dask cluster is started for a check)."""
    checker = _CHECKER.get()
    if backend != "inprocess" and checker is not None:
        yield checker
        return
    with open_pool("inprocess" if backend == "inprocess" else "loky", jobs) as pool:
        yield pool


@contextmanager
def open_pool(
    backend: str,
    jobs: int | None = None,
    address: Any = None,
    tasks: int | None = None,
    key: str = "address",
) -> Iterator[Pool]:
    """Workers of ``backend`` for one campaign.

    Loky pools are kept warm for the next campaign of this process (and closed at its exit);
    the others are started and closed here. While the pool is open, this process keeps one
    native thread (:func:`pcmb.run.threads.one_thread_here`). On an error or an interrupt the
    workers are killed (a kept pool is dropped), so that none is left running.

    Parameters
    ----------
    jobs:
        Worker processes (default: :func:`default_workers`).
    address:
        For dask: a scheduler's address, or a ``distributed.Client`` or ``Cluster`` of the
        caller's (left open); default: a local cluster started and closed here.
    tasks:
        Most tasks that will run at once, if known: no more workers than that are used.
    key:
        The setting ``address`` came from, named when no scheduler answers there.
    """
    workers = _workers(backend, jobs, tasks)
    # Workers die with the thread that started them (see pcmb.run.lifeline): only those of the
    # main thread can be kept.
    kept = backend == "loky" and threading.current_thread() is threading.main_thread()
    if kept:
        warm_up(jobs, tasks)
        pool: Pool = _KEPT[workers]
    else:
        pool = BACKENDS[backend](jobs, workers, address, key)
    # The workers have the cores: this process keeps one native thread meanwhile.
    bounded = nullcontext() if backend == "inprocess" else one_thread_here()
    try:
        with bounded:
            yield pool
    except BaseException:
        if kept:
            del _KEPT[workers]
        pool.close(kill=True)
        raise
    if not kept:
        pool.close()
