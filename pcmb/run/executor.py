"""Run a model at every node, in parallel chunks, with failure capture and a resumable journal.

Chunk boundaries depend only on N, the config and the model class, never on workers or
backend, so results are bit-identical however they run. The model's code runs only in worker
processes (unless the backend is ``inprocess``): building it, checking it and every chunk
(:mod:`pcmb.run.worker`); this module dispatches the tasks from the parent process. A
worker that dies (a segfault, ``os._exit``) or overruns its timeout costs only its chunk, and
the node that killed it is named. See ``docs/architecture.md``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import cloudpickle
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.axes import OutputAxis
from pcmb.errors import ConfigProblem, ModelDefinitionError, UsageError
from pcmb.run.backends import Pool, open_pool
from pcmb.run.journal import FRESH, Journal
from pcmb.run.progress import Progress
from pcmb.run.status import ModelTraceback, NodeFailure, Status
from pcmb.run.worker import (
    Layout,
    ModelFacts,
    Outcome,
    SentFactory,
    model_facts,
    run_task,
    with_model,
)

if TYPE_CHECKING:
    from pcmb.adapters.protocol import Model

__all__ = [
    "Execution",
    "JoinedJournal",
    "PendingRun",
    "RunResult",
    "chunk_bounds",
    "describe_model",
    "join_runs",
    "run_in_worker",
    "run_nodes",
    "split_runs",
    "start_run",
]

TARGET_CHUNKS = 16
MAX_CHUNK_SIZE = 256

_T = TypeVar("_T")


# -- results ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunResult:
    """What :func:`run_nodes` returns.

    Attributes
    ----------
    values:
        Output name -> (N, T) float64 values; NaN rows for the nodes that did not succeed.
    status:
        (N,) int8 per node: 0 pending, 1 ok, 2 failed (the codes of the output file).
    failures:
        The failed nodes, by increasing index.
    seconds:
        Wall time of the call.
    resumed:
        Number of nodes taken from the journal instead of being run.
    """

    values: dict[str, NDArray[np.float64]]
    status: NDArray[np.int8]
    failures: tuple[NodeFailure, ...]
    seconds: float
    resumed: int

    def of(self, run: str) -> RunResult:
        """These runs with their failures called ``run`` (``"held-out run"``) in messages."""
        if run == "node":
            return self
        failures = tuple(dataclasses.replace(f, run=run) for f in self.failures)
        return dataclasses.replace(self, failures=failures)


def join_runs(first: RunResult, second: RunResult) -> RunResult:
    """The runs of ``first`` followed by those of ``second`` (its node indices shifted)."""
    offset = first.status.size
    return RunResult(
        values={
            name: np.concatenate([first.values[name], second.values[name]]) for name in first.values
        },
        status=np.concatenate([first.status, second.status]),
        failures=first.failures
        + tuple(dataclasses.replace(f, index=f.index + offset) for f in second.failures),
        seconds=first.seconds + second.seconds,
        resumed=first.resumed + second.resumed,
    )


def split_runs(runs: RunResult, sizes: Sequence[int]) -> list[RunResult]:
    """The runs of ``runs`` cut into parts of ``sizes`` runs, in order (each with its own node
    indices, counted from 0): :func:`join_runs` undone. Each part keeps the wall time of the
    whole call; the count of resumed runs goes with the first part."""
    parts = []
    for k, (start, stop) in enumerate(itertools.pairwise(np.cumsum([0, *sizes]).tolist())):
        parts.append(
            RunResult(
                values={name: array[start:stop] for name, array in runs.values.items()},
                status=runs.status[start:stop],
                failures=tuple(
                    dataclasses.replace(f, index=f.index - start)
                    for f in runs.failures
                    if start <= f.index < stop
                ),
                seconds=runs.seconds,
                resumed=runs.resumed if k == 0 else 0,
            )
        )
    return parts


class JoinedJournal:
    """The journals of runs of different sets joined into one campaign, seen as one journal
    by :func:`run_nodes`: ``parts`` are (journal, runs) in order; a chunk is recorded in the
    journal of each part it holds runs of, at that part's own indices. A part without a
    journal (``None``) is not recorded: it runs again on a resume."""

    def __init__(self, parts: Sequence[tuple[Journal | None, int]]) -> None:
        self.parts = tuple(parts)

    def _pieces(self) -> list[tuple[Journal, int, int]]:
        """(journal, first index, end) of each journaled part, in the joined indices."""
        ends = np.cumsum([0, *(size for _, size in self.parts)]).tolist()
        return [
            (journal, start, stop)
            for (journal, _), start, stop in zip(self.parts, ends, ends[1:], strict=False)
            if journal is not None
        ]

    def record(
        self,
        indices: NDArray[np.intp],
        values: Mapping[str, NDArray[np.float64]],
        status: NDArray[np.int8],
        messages: Mapping[int, str],
        tracebacks: Mapping[int, ModelTraceback],
    ) -> None:
        """:meth:`Journal.record` of a chunk, in the journal of each part it holds runs of."""
        for journal, start, stop in self._pieces():
            mine = (indices >= start) & (indices < stop)
            if not mine.any():
                continue
            journal.record(
                indices[mine] - start,
                {name: part[mine] for name, part in values.items()},
                status[mine],
                {i - start: text for i, text in messages.items() if start <= i < stop},
                {i - start: where for i, where in tracebacks.items() if start <= i < stop},
            )

    def completed(
        self,
    ) -> tuple[NDArray[np.int64], dict[str, NDArray[np.float64]], NDArray[np.int8]]:
        """:meth:`Journal.completed` of every journaled part, at the joined indices."""
        found = [(start, *journal.completed()) for journal, start, _ in self._pieces()]
        names = found[0][2]
        return (
            np.concatenate([start + indices for start, indices, _, _ in found]),
            {name: np.concatenate([values[name] for *_, values, _ in found]) for name in names},
            np.concatenate([status for *_, status in found]),
        )


# -- chunking --------------------------------------------------------------------------------


def chunk_bounds(n_nodes: int, chunk_size: int | None = None) -> list[tuple[int, int]]:
    """Cut ``n_nodes`` nodes into contiguous chunks ``[start, stop)``.

    The boundaries depend only on ``n_nodes`` and ``chunk_size`` (see the module docstring for
    why and for the default rule ``min(256, max(1, ceil(n_nodes / 16)))``).

    Parameters
    ----------
    n_nodes:
        N >= 1.
    chunk_size:
        Nodes per chunk (the last chunk may be shorter); ``None`` for the default rule.

    Returns
    -------
    list of (start, stop) pairs covering ``range(n_nodes)`` in order.

    Raises
    ------
    ValueError
        If ``n_nodes`` or ``chunk_size`` is not a positive integer.
    """
    if n_nodes < 1 or (chunk_size is not None and chunk_size < 1):
        raise ValueError(f"n_nodes and chunk_size must be positive, got {n_nodes}, {chunk_size}")
    size = chunk_size or min(MAX_CHUNK_SIZE, max(1, math.ceil(n_nodes / TARGET_CHUNKS)))
    return [(start, min(start + size, n_nodes)) for start in range(0, n_nodes, size)]


def _balanced(n_nodes: int, most: int | None) -> int | None:
    """The chunk size that cuts ``n_nodes`` nodes into as few chunks of at most ``most`` (a
    model's preference; ``None``: none) as equal as can be: 225 nodes at most 128 -> 113."""
    return None if most is None else math.ceil(n_nodes / math.ceil(n_nodes / most))


# -- tasks -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Task:
    """Nodes to run together: one batched call (``batched``) or one call per node."""

    indices: NDArray[np.intp]
    batched: bool


def _factory(model_factory: Callable[[], Model]) -> SentFactory:
    """``model_factory`` ready to be sent to workers; the token is its identity (the model
    cached in a worker is reused for the same token)."""
    try:
        payload = cloudpickle.dumps(model_factory)
    except Exception as exc:  # pickling can fail with almost any exception type
        raise UsageError(
            [ConfigProblem("model_factory", f"cannot be sent to worker processes: {exc}")],
            source="run_nodes",
        ) from exc
    return SentFactory(hashlib.sha256(payload).hexdigest(), payload, tuple(sys.path))


def describe_model(
    model_factory: Callable[[], Model],
    pool: Pool,
    times: ArrayLike | None = None,
    inputs: Sequence[str] = (),
) -> ModelFacts:
    """Build the model in one of ``pool``'s workers and say what it offers (and, given
    ``times`` or ``inputs``, what it finds wrong with that time grid or those uncertain
    inputs).

    Raises
    ------
    UsageError
        The factory cannot be sent to a worker, or builds no model.
    ModelDefinitionError
        The model's code failed while building, or killed its worker (named by its signal or
        exit code); this process is unharmed.
    """
    factory = _factory(model_factory)
    grid = None if times is None else np.asarray(times, dtype=np.float64)
    # Twice: a worker of a kept pool may have died before this task (killed from outside).
    for _ in range(2):
        facts, death = _wait(pool, pool.submit(model_facts, factory, grid, tuple(inputs)))
        if death is None:
            return facts
    raise ModelDefinitionError(f"could not build the model: {death}")


def run_in_worker(
    model_factory: Callable[[], Model], pool: Pool, task: Callable[..., _T], *args: Any
) -> _T:
    """``task(model, *args)`` in one of ``pool``'s workers, with the model built (or reused)
    there: how methods that need the model's own code besides ``simulate`` (the intrusive
    designs' polynomial form) run it. ``task`` and ``args`` must pickle; what ``task`` raises
    is raised here.

    Raises
    ------
    ModelDefinitionError
        The model's code failed while building, or killed its worker.
    """
    factory = _factory(model_factory)
    for _ in range(2):  # as in describe_model: a kept worker may have died before this task
        result, death = _wait(pool, pool.submit(with_model, factory, task, args))
        if death is None:
            return result  # type: ignore[return-value]
    raise ModelDefinitionError(f"the model's worker died: {death}")


def _wait(
    pool: Pool, future: Future[_T], seconds: float = math.inf, late: Callable[[], str] = str
) -> tuple[_T | None, str | None]:
    """``(result, None)`` of a task, or ``(None, why)`` when its worker died or it ran past
    ``seconds`` (``late()`` says so); the pool is rebuilt then. Other errors are raised."""
    try:
        error = future.exception(timeout=None if math.isinf(seconds) else seconds)
    except FutureTimeout:
        pool.rebuild()  # kills the stuck worker
        return None, late()
    if error is None:
        return future.result(), None
    death = pool.death(error)
    if death is None:
        raise error
    pool.rebuild()
    return None, death


# -- the campaign ----------------------------------------------------------------------------


class _Campaign:
    """The state of one :func:`run_nodes` call: arguments, results so far, journal, progress.

    ``proven``: the model is known to work (see :func:`run_nodes`), so that a break of the
    protocol is never taken for a model error. ``keep_values`` False: the values go to the
    journal only (a streamed study, :mod:`pcmb.run.memory`), the result's arrays have no rows.
    """

    def __init__(
        self,
        factory: SentFactory,
        params: dict[str, NDArray[np.float64]],
        times: NDArray[np.float64],
        outputs: tuple[str, ...],
        retries: int,
        journal: Journal | JoinedJournal | None,
        axes: Mapping[str, OutputAxis | None] | None = None,
        proven: bool = False,
        keep_values: bool = True,
        counted: int | None = None,
        tolerated: NDArray[np.bool_] | None = None,
    ) -> None:
        layout = Layout.of(outputs, times, axes or {})
        self.factory = factory
        self.params, self.layout, self.outputs = params, layout, layout.outputs
        self.retries, self.journal = retries, journal
        n_nodes = len(next(iter(params.values())))
        self.keep_values = keep_values
        self.values = {
            name: np.ascontiguousarray(part)
            for name, part in layout.split(layout.empty(n_nodes if keep_values else 0)).items()
        }
        self.status = np.zeros(n_nodes, dtype=np.int8)
        self.messages: dict[int, str] = {}
        self.tracebacks: dict[int, ModelTraceback] = {}
        self.broken: set[int] = set()  # the failed nodes where the model broke the protocol
        self.proven = proven
        self.resumed = 0
        self.progress: Progress | None = None
        self.counted = n_nodes if counted is None else counted  # those the progress counts
        # The nodes whose failure does not stop the campaign (run_nodes' ``tolerated``).
        self.tolerated = np.zeros(n_nodes, dtype=bool) if tolerated is None else tolerated

    @property
    def stopped(self) -> bool:
        """Whether a node has failed that ``stop_on_failure`` stops the campaign at: one not
        ``tolerated``."""
        return any(not self.tolerated[i] for i in self.messages)

    def resume(self, journal: Journal | JoinedJournal) -> None:
        """Take the successful nodes from the journal; failed ones will be run again."""
        if self.keep_values:
            indices, values, status = journal.completed()
            for name in self.outputs:
                self.values[name][indices[status == Status.OK]] = values[name][status == Status.OK]
        else:
            indices, status = journal.statuses()
        ok = indices[status == Status.OK]
        self.status[ok] = Status.OK
        self.resumed = int(ok.size)

    def plan(self, bounds: Sequence[tuple[int, int]]) -> list[_Task]:
        """The tasks still to run: whole chunks, or the pending nodes of a partly done chunk.

        A partly done chunk had failed nodes in an earlier run; those are run singly, as they
        would have been in an uninterrupted run.
        """
        tasks = []
        for start, stop in bounds:
            pending = start + np.flatnonzero(self.status[start:stop] != Status.OK)
            if pending.size:
                tasks.append(_Task(pending, batched=pending.size == stop - start))
        return tasks

    def arguments(self, task: _Task) -> tuple[Any, ...]:
        """The arguments of :func:`~pcmb.run.worker.run_task` for ``task``."""
        if task.batched:  # a contiguous chunk: node i's batch slice is params[name][a:b]
            start, stop = int(task.indices[0]), int(task.indices[-1]) + 1
            params = {name: array[start:stop] for name, array in self.params.items()}
        else:
            params = {name: array[task.indices] for name, array in self.params.items()}
        return (self.factory, params, self.layout, task.batched, self.retries, os.getpid())

    def accept(
        self,
        task: _Task,
        values: NDArray[np.float64],
        messages: Sequence[str],
        broken: Sequence[bool] = (),
        tracebacks: Sequence[ModelTraceback | None] = (),
    ) -> None:
        """Store a finished task, journal it at once and advance the progress line;
        ``broken``: the nodes whose failure is a break of the protocol; ``tracebacks``: where
        the model's code raised at each node."""
        failed = np.array([bool(m) for m in messages])
        chunk = {
            name: np.where(failed[:, None], np.nan, part)
            for name, part in self.layout.split(values).items()
        }
        if self.keep_values:
            for name, column in chunk.items():
                self.values[name][task.indices] = column
        self.status[task.indices] = np.where(failed, Status.FAILED, Status.OK)
        found = {int(i): m for i, m in zip(task.indices, messages, strict=True) if m}
        raised = {int(i): t for i, t in zip(task.indices, tracebacks, strict=False) if t}
        for i in task.indices:
            self.messages.pop(int(i), None)
            self.tracebacks.pop(int(i), None)
            self.broken.discard(int(i))
        self.messages.update(found)
        self.tracebacks.update(raised)
        self.broken.update(int(i) for i, b in zip(task.indices, broken, strict=False) if b)
        if self.journal is not None:
            self.journal.record(task.indices, chunk, self.status[task.indices], found, raised)
        counted = int(np.count_nonzero(task.indices < self.counted))
        if self.progress is not None and counted:
            self.progress.advance(counted)

    def accept_outcome(self, task: _Task, outcome: Outcome) -> None:
        self.accept(task, outcome.values, outcome.messages, outcome.broken, outcome.tracebacks)

    @property
    def broken_everywhere(self) -> bool:
        """Whether the model, not known to work, broke the protocol at every node it tried:
        none succeeded (none resumed either) and none failed otherwise."""
        return (
            not self.proven
            and bool(self.broken)
            and len(self.broken) == len(self.messages)
            and not (self.status == Status.OK).any()
        )

    def definition_error(self) -> ModelDefinitionError:
        """The model error of a model that broke the protocol at every node it tried."""
        first = min(self.broken)
        return ModelDefinitionError(
            f"{self.messages[first]} (at each of the {len(self.broken)} node(s) tried)"
        )

    def accept_death(self, task: _Task, message: str) -> None:
        n = task.indices.size
        self.accept(task, self.layout.empty(n), [message] * n)

    def result(self, seconds: float) -> RunResult:
        failures = tuple(
            NodeFailure(
                index=i,
                params={
                    name: float(array[i]) if array.ndim == 1 else tuple(map(float, array[i]))
                    for name, array in self.params.items()
                },
                message=self.messages[i],
                traceback=self.tracebacks.get(i),
            )
            for i in sorted(self.messages)
        )
        return RunResult(
            values=self.values,
            status=self.status,
            failures=failures,
            seconds=seconds,
            resumed=self.resumed,
        )


@dataclass(frozen=True)
class _Limits:
    """How long a task may run: ``timeout`` seconds per node (``None``: no limit), plus
    ``grace`` for a fresh worker to start and build the model."""

    timeout: float | None = None
    grace: float = 0.0

    def deadline(self, task: _Task, now: float) -> float:
        if self.timeout is None:
            return math.inf
        return now + self.grace + self.timeout * task.indices.size

    def message(self, task: _Task) -> str:
        return (
            f"timed out after {self.timeout * task.indices.size:g} s "
            f"({self.timeout:g} s per node; its worker process was killed)"
        )


def _run_alone(campaign: _Campaign, pool: Pool, task: _Task, limits: _Limits) -> Outcome | str:
    """Run ``task`` as the only task in the pool: its outcome, or why it did not finish."""
    future = pool.submit(run_task, *campaign.arguments(task))
    outcome, why = _wait(pool, future, limits.deadline(task, 0.0), lambda: limits.message(task))
    return why if outcome is None else outcome


def _isolate(campaign: _Campaign, pool: Pool, task: _Task, limits: _Limits) -> None:
    """Re-run a task whose worker died or overran, alone, down to single nodes."""
    attempts = 1 + campaign.retries if task.indices.size == 1 else 1
    for _ in range(attempts):
        found = _run_alone(campaign, pool, task, limits)
        if isinstance(found, Outcome):
            campaign.accept_outcome(task, found)
            return
    if task.indices.size == 1:
        campaign.accept_death(task, found)
        return
    for index in task.indices:
        _isolate(campaign, pool, _Task(np.array([index]), batched=False), limits)


def _run_pooled(
    campaign: _Campaign,
    pool: Pool,
    tasks: Sequence[_Task],
    limits: _Limits,
    stop_on_failure: bool = False,
) -> None:
    """Run ``tasks`` with at most ``pool.slots`` in flight, handling dead and stuck workers.

    A task past its deadline has its workers killed (the pool is rebuilt); the other tasks
    in flight then are run again, and the late task is isolated like one whose worker died.
    With ``stop_on_failure``, no task is started once a node not tolerated has failed
    (:attr:`_Campaign.stopped`); the tasks in flight
    finish (and are journaled; those a kill of the workers cut short run again), the others
    stay pending. While the model has broken the
    protocol at every node it tried, no task is started either: if the tasks in flight do
    not show it working somewhere, the loop ends there (a model error, see
    :func:`run_nodes`); if they do, the campaign goes on under the failure policy.
    """
    queue = deque(tasks)
    # The tasks in flight when a late one had every worker killed: started, so they finish
    # even after a failure, as every task in flight does.
    restarted: deque[_Task] = deque()
    # One task queued beyond the workers hides the round trip between tasks (no more: loky's
    # queue takes one extra, and a kill must not find tasks waiting outside it). With a
    # timeout each task's clock must start when the task does: no task waits then.
    most = pool.slots + (1 if limits.timeout is None else 0)
    in_flight: dict[Future[Outcome], tuple[_Task, float]] = {}
    lost: list[_Task] = []
    while queue or restarted or in_flight:
        if campaign.broken_everywhere and not in_flight:
            break
        # After a death, feed nothing more: let the chunks in flight finish or fail first.
        if stop_on_failure and campaign.stopped:
            queue.clear()
        while (
            (restarted or queue)
            and not lost
            and len(in_flight) < most
            and not campaign.broken_everywhere
        ):
            task = (restarted or queue).popleft()
            future = pool.submit(run_task, *campaign.arguments(task))
            in_flight[future] = (task, limits.deadline(task, time.monotonic()))
        first = min((deadline for _, deadline in in_flight.values()), default=0.0)
        wait_for = None if math.isinf(first) else max(0.0, first - time.monotonic())
        done, _ = wait(list(in_flight), timeout=wait_for, return_when=FIRST_COMPLETED)
        for future in done:
            task, _ = in_flight.pop(future)
            error = future.exception()
            if error is None:
                campaign.accept_outcome(task, future.result())
            elif pool.death(error) is None:
                raise error
            else:
                lost.append(task)
        now = time.monotonic()
        late = [task for task, deadline in in_flight.values() if deadline <= now]
        if late:
            # The pool cannot kill one worker: all go, and the tasks on time run again.
            restarted.extend(t for t, d in in_flight.values() if d > now)
            in_flight.clear()
            pool.rebuild()
            for task in late:
                if task.indices.size == 1 and not campaign.retries:  # known to hang
                    campaign.accept_death(task, limits.message(task))
                else:
                    _isolate(campaign, pool, task, limits)
        if lost and not in_flight:
            pool.rebuild()
            for task in lost:
                _isolate(campaign, pool, task, limits)
            lost = []


# -- argument checks -------------------------------------------------------------------------


class Execution(Protocol):
    """The validated ``execution:`` settings the executor runs by
    (:class:`pcmb.config.schema.ExecutionSpec`, where each is declared and checked)."""

    jobs: int | None
    backend: str
    address: str | None
    chunk_size: int | None
    timeout: float | None


def _check_arguments(
    params: Mapping[str, ArrayLike], times: ArrayLike, outputs: Sequence[str]
) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.float64], tuple[str, ...]]:
    """Validate the nodes, grid and outputs of :func:`run_nodes` as a whole; return them as
    arrays (the execution settings come validated, :class:`Execution`)."""
    problems: list[ConfigProblem] = []
    arrays: dict[str, NDArray[np.float64]] = {}
    if not isinstance(params, Mapping) or not params:
        problems.append(ConfigProblem("params", "must map at least one input name to an array"))
    else:
        for name, value in params.items():
            try:
                array = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                problems.append(ConfigProblem(f"params.{name}", f"not a float array ({exc})"))
                continue
            if array.ndim not in (1, 2) or array.shape[0] == 0:
                problems.append(
                    ConfigProblem(f"params.{name}", f"must be (N,) or (N, m), got {array.shape}")
                )
            elif not np.isfinite(array).all():
                bad = np.flatnonzero(~np.isfinite(array.reshape(array.shape[0], -1)).all(1))
                problems.append(
                    ConfigProblem(f"params.{name}", f"non-finite values at nodes {bad[:10]}")
                )
            else:
                arrays[name] = array
        lengths = {name: a.shape[0] for name, a in arrays.items()}
        if len(set(lengths.values())) > 1:
            problems.append(
                ConfigProblem("params", f"inputs have different node counts N: {lengths}")
            )
    time_grid = np.asarray(times, dtype=np.float64)
    if time_grid.ndim != 1 or time_grid.size == 0 or not np.isfinite(time_grid).all():
        problems.append(ConfigProblem("times", "must be a non-empty finite (T,) array"))
    if (
        isinstance(outputs, str)
        or not outputs
        or not all(isinstance(o, str) for o in outputs)
        or len(set(outputs)) != len(outputs)
    ):
        problems.append(
            ConfigProblem("outputs", f"must be a sequence of distinct names, got {outputs!r}")
        )
    if problems:
        raise UsageError(problems, source="run_nodes")
    return arrays, time_grid, tuple(outputs)


def _check_outputs(facts: ModelFacts, outputs: Sequence[str]) -> None:
    """Check that the model offers every requested output."""
    missing = [name for name in outputs if name not in facts.outputs]
    if missing:
        raise UsageError(
            [
                ConfigProblem(
                    "outputs", f"the model has no output {missing} (it has {list(facts.outputs)})"
                )
            ],
            source="run_nodes",
        )


def _check_journal(journal: Journal | JoinedJournal, n_nodes: int, layout: Layout) -> None:
    if isinstance(journal, JoinedJournal):
        for part, size in journal.parts:
            if part is not None:
                _check_journal(part, size, layout)
        return
    found = (journal.n_nodes, tuple(journal.outputs), journal.widths)
    if found != (n_nodes, layout.outputs, layout.widths):
        raise UsageError(
            f"journal {journal.directory} holds (nodes, outputs, columns) = {found}, this run "
            f"has {(n_nodes, layout.outputs, layout.widths)}; delete it or {FRESH}"
        )


# -- the entry point -------------------------------------------------------------------------


def run_nodes(
    model_factory: Callable[[], Model],
    params: Mapping[str, ArrayLike],
    times: ArrayLike,
    outputs: Sequence[str],
    *,
    execution: Execution,
    address: Any = None,
    chunk_size: int | None = None,
    retries: int = 0,
    journal: Journal | JoinedJournal | None = None,
    progress: bool | None = None,
    stop_on_failure: bool = False,
    pool: Pool | None = None,
    facts: ModelFacts | None = None,
    proven: bool = False,
    keep_values: bool = True,
    counted: int | None = None,
    tolerated: ArrayLike | None = None,
) -> RunResult:
    """Run the model at every node, in chunks, in parallel; capture and name failed nodes.

    Parameters
    ----------
    model_factory:
        Picklable callable returning a model (``outputs``, ``simulate(params, times)``); it is
        called once per worker process.
    params:
        Input name -> (N,) values, or (N, m) for a field input; node i is row i.
    times:
        (T,) output time grid, passed to the model.
    outputs:
        Names of the outputs to keep.
    execution:
        The validated ``execution:`` settings (:class:`Execution`): workers (``jobs``), where
        they run (``backend``, ``address``), nodes per chunk (``chunk_size``; default ``min(256,
        max(1, ceil(N / 16)))``; results depend on it, so a journal fingerprint includes an
        explicit one) and the seconds a node may take (``timeout``: a chunk of B nodes B times
        that, plus the time a fresh worker takes to start and build the model; a node past it
        is a failed run and its worker is killed).
    address:
        Overrides ``execution.address``: a dask scheduler's address, or a
        ``distributed.Client`` or ``Cluster`` of the caller's.
    chunk_size:
        Overrides ``execution.chunk_size``.
    retries:
        How many more times a failed node is tried before it is reported.
    journal:
        Persists every finished chunk; its successful nodes are taken instead of being run. A
        :class:`JoinedJournal`: the nodes are several sets, each journaled on its own.
    progress:
        Progress line on stderr; default: only when stderr is a terminal.
    stop_on_failure:
        Start no more chunks once a node has failed (the policy ``abort``): the chunks in
        flight finish and every failure found in them is reported; the nodes never run stay
        pending (status 0), in the journal too, so a resumed run runs them; a failure at a
        ``tolerated`` node does not stop it.
    pool:
        Workers to run on (see :func:`pcmb.run.backends.open_pool`), shared by several
        campaigns; default: a pool of ``backend`` opened and closed by this call.
    facts:
        What :func:`describe_model` said of this factory on ``pool``, to skip asking again.
    proven:
        The model is known to work (it ran at other nodes: a study's later rounds, held-out
        and nominal runs), so that a node where it breaks the protocol is a failed node,
        never a :class:`~pcmb.errors.ModelDefinitionError`.
    keep_values:
        False: the values go to the ``journal`` only (a streamed study reads them from it
        block by block) and the result's arrays have no rows.
    counted:
        The progress line counts the first ``counted`` nodes only (default: all): the others
        are runs of other sets joined to them (a study's held-out and nominal runs).
    tolerated:
        (N,) bool: the nodes whose failure does not stop the campaign under
        ``stop_on_failure`` (a study's held-out runs in the tails of its inputs, see
        ``docs/diagnostics.md``); default: none.

    Returns
    -------
    RunResult
        (N, T) values per output, (N,) status, the failed nodes, wall time, resumed count.

    Raises
    ------
    UsageError
        Before anything runs, for invalid arguments, a model without a requested output, or a
        journal that does not match this run.
    ModelDefinitionError
        If the model cannot be built (its code failed or killed the worker), or breaks the
        protocol (:class:`~pcmb.adapters.protocol.Model`) at every node it was tried at: no
        node succeeded, none of those tried failed otherwise, and the model is not
        ``proven``. The model stops being tried at the first such node of a campaign, as soon
        as the tasks in flight have finished. A break of the protocol at some nodes only is a
        failure of each of those nodes, like any other.
    """
    start = time.perf_counter()
    arrays, time_grid, names = _check_arguments(params, times, outputs)
    n_nodes = len(next(iter(arrays.values())))
    factory = _factory(model_factory)
    chunk_size = chunk_size or execution.chunk_size
    timeout = execution.timeout
    if pool is None:
        tasks = len(chunk_bounds(n_nodes, chunk_size))
        where = execution.address if address is None else address
        with open_pool(execution.backend, execution.jobs, where, tasks=tasks) as own:
            return run_nodes(
                model_factory,
                arrays,
                time_grid,
                names,
                execution=execution,
                chunk_size=chunk_size,
                retries=retries,
                journal=journal,
                progress=progress,
                stop_on_failure=stop_on_failure,
                pool=own,
                proven=proven,
                keep_values=keep_values,
                counted=counted,
                tolerated=tolerated,
            )
    if keep_values is False and journal is None:
        raise UsageError("values not kept in memory must go to a journal", source="run_nodes")
    if timeout is not None and not pool.kills:
        raise UsageError(
            [
                ConfigProblem(
                    "timeout",
                    f"needs workers pcmb can kill (backend loky), not {type(pool).__name__}",
                )
            ],
            source="run_nodes",
        )
    facts = facts or describe_model(model_factory, pool)
    _check_outputs(facts, names)
    if journal is not None:
        _check_journal(journal, n_nodes, Layout.of(names, time_grid, facts.axes))
    campaign = _Campaign(
        factory,
        arrays,
        time_grid,
        names,
        retries,
        journal,
        facts.axes,
        proven=proven,
        keep_values=keep_values,
        counted=counted,
        tolerated=None if tolerated is None else np.asarray(tolerated, dtype=bool),
    )
    if journal is not None:
        campaign.resume(journal)
    # A model may prefer a chunk size (model protocol: the most per chunk, made as equal as
    # can be); an explicit one wins. Either way the boundaries depend on N, the config and
    # the model class only, never on jobs or backend.
    tasks = campaign.plan(chunk_bounds(n_nodes, chunk_size or _balanced(n_nodes, facts.chunk_size)))
    limits = _Limits(timeout, pool.startup_seconds + 2 * facts.build_seconds)
    show = sys.stderr.isatty() if progress is None else progress
    reused = int(np.count_nonzero(campaign.status[: campaign.counted] == Status.OK))
    campaign.progress = Progress(campaign.counted, reused, sys.stderr if show else None)
    try:
        _run_pooled(campaign, pool, tasks, limits, stop_on_failure)
    finally:
        campaign.progress.close()
    if campaign.broken_everywhere:
        raise campaign.definition_error()
    return campaign.result(time.perf_counter() - start)


@dataclass
class PendingRun:
    """A few nodes sent to a pool as one task ahead of a campaign on the same pool (see
    :func:`start_run`)."""

    campaign: _Campaign
    task: _Task
    future: Future[Outcome]
    started: float

    def result(self) -> RunResult | None:
        """The run (its failed nodes named as :func:`run_nodes` names them), or ``None`` if
        the task itself was lost — its worker died or the pool was rebuilt under it — so the
        caller runs the nodes again the usual way."""
        try:
            outcome = self.future.result()
        except Exception:  # a dead worker, a broken pool: nothing of the model's own
            return None
        self.campaign.accept_outcome(self.task, outcome)
        return self.campaign.result(time.perf_counter() - self.started)


def start_run(
    model_factory: Callable[[], Model],
    params: Mapping[str, ArrayLike],
    times: ArrayLike,
    outputs: Sequence[str],
    pool: Pool,
    facts: ModelFacts,
) -> PendingRun:
    """Send a few nodes (one task, no journal, no retries) to ``pool`` now and return at once,
    so that they run while the caller's next campaign keeps the other workers busy: how a
    study overlaps its nominal run with its nodes. Only for pools without a timeout, whose
    chunks may wait in the queue behind it. A break of the protocol is a failure of its
    node here (the run is ``proven``, see :func:`run_nodes`).

    Raises
    ------
    UsageError
        For invalid arguments, or a model without a requested output.
    """
    started = time.perf_counter()
    arrays, time_grid, names = _check_arguments(params, times, outputs)
    _check_outputs(facts, names)
    campaign = _Campaign(
        _factory(model_factory), arrays, time_grid, names, 0, None, facts.axes, proven=True
    )
    (task,) = campaign.plan([(0, len(next(iter(arrays.values()))))])
    future = pool.submit(run_task, *campaign.arguments(task))
    return PendingRun(campaign, task, future, started)
