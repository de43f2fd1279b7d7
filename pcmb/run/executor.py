"""Run a model at every node, in parallel chunks, with failure capture and a resumable journal.

Chunk boundaries depend only on N, the config and the model class, never on workers or
backend, so results are bit-identical however they run. The model's code runs only in worker
processes (unless the backend is ``inprocess``): building it, checking it and every chunk. A
worker that dies (a segfault, ``os._exit``) or overruns its timeout costs only its chunk, and
the node that killed it is named. See ``docs/architecture.md``.

Whatever the model's code raises while it builds or simulates is a failure of the nodes it was
running, described by type and message, with the model's part of the traceback
(:mod:`pcmb.run.tracebacks`) — ``BaseException`` s included: ``sys.exit()`` in a
model is ``SystemExit: 0`` at its node, never an exit of pcmb. The one exception is the user's
Ctrl-C: a ``KeyboardInterrupt`` (or anything else) raised while a SIGINT reached the process
stops the run, as does a SIGINT the model swallowed (see :class:`_SigintWatch`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import cloudpickle
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.adapters.protocol import float_array
from pcmb.axes import OutputAxis, axis_problems
from pcmb.errors import (
    ConfigError,
    ConfigProblem,
    ModelDefinitionError,
    ModelError,
    PcmbError,
    UsageError,
)
from pcmb.run.backends import BACKENDS, Pool, open_pool
from pcmb.run.journal import FRESH, Journal
from pcmb.run.progress import Progress
from pcmb.run.status import ModelTraceback, NodeFailure, Status
from pcmb.run.tracebacks import model_exception, model_traceback

if TYPE_CHECKING:
    from pcmb.adapters.protocol import Model

__all__ = [
    "ModelFacts",
    "PendingRun",
    "RunResult",
    "chunk_bounds",
    "describe_model",
    "join_runs",
    "post_mortem",
    "run_in_worker",
    "run_nodes",
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


# -- what runs inside a worker ---------------------------------------------------------------


@dataclass(frozen=True)
class _Task:
    """Nodes to run together: one batched call (``batched``) or one call per node."""

    indices: NDArray[np.intp]
    batched: bool


@dataclass(frozen=True)
class _Outcome:
    """A finished task: (B, W) values (:class:`Layout`), per-node messages ("" = ok), model
    seconds, the nodes where the model broke the protocol (a ``ModelDefinitionError``), and
    per node where the model's code raised (``None``: it did not)."""

    values: NDArray[np.float64]
    messages: tuple[str, ...]
    seconds: float
    broken: tuple[bool, ...] = ()
    tracebacks: tuple[ModelTraceback | None, ...] = ()


@dataclass(frozen=True)
class Layout:
    """How a task's outputs sit side by side in one (B, W) array.

    Attributes
    ----------
    outputs:
        The output names, in order.
    shapes:
        Each output's shape per node: ``(T,)`` on time, ``(K,)`` on its own axis, ``()`` a
        scalar (see :mod:`pcmb.axes`).
    times:
        (T,) the time grid (named in messages).
    """

    outputs: tuple[str, ...]
    shapes: tuple[tuple[int, ...], ...]
    times: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        outputs: Sequence[str],
        times: NDArray[np.float64],
        axes: Mapping[str, OutputAxis | None],
    ) -> Layout:
        """Outputs on time unless ``axes`` puts them on an axis (or makes them scalars)."""
        shapes = []
        for name in outputs:
            axis = axes.get(name)
            shapes.append(
                (times.size,) if name not in axes else () if axis is None else axis.values.shape
            )
        return cls(tuple(outputs), tuple(shapes), times)

    @property
    def widths(self) -> tuple[int, ...]:
        """Columns of each output (1 for a scalar)."""
        return tuple(shape[0] if shape else 1 for shape in self.shapes)

    @property
    def bounds(self) -> list[tuple[int, int]]:
        """``[start, stop)`` columns of each output."""
        return list(itertools.pairwise(np.cumsum([0, *self.widths]).tolist()))

    def empty(self, n: int) -> NDArray[np.float64]:
        """(n, W) NaN."""
        return np.full((n, sum(self.widths)), np.nan)

    def split(self, values: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
        """Output name -> its (n, W_k) columns of (n, W) ``values``."""
        return {
            name: values[:, a:b] for name, (a, b) in zip(self.outputs, self.bounds, strict=True)
        }

    def where(self, k: int, j: int) -> str:
        """Where column ``j`` of output ``k`` is, for a message: ``" at t=0.5"``."""
        shape = self.shapes[k]
        if not shape:
            return ""
        if shape == (self.times.size,):
            return f" at t={self.times[j]:.6g}"
        return f" at axis point {j}"


# -- calls into the model's code -------------------------------------------------------------


class _SigintWatch:
    """Tells the user's Ctrl-C from a ``KeyboardInterrupt`` the model's code raised itself.

    Python turns SIGINT into ``KeyboardInterrupt`` in the main thread through the SIGINT
    handler. While the model runs, the watch puts a handler in front of the current one that
    notes the signal and passes it on, so the model sees exactly what it would without it.
    Afterwards the watch knows whether a SIGINT reached this process during the call
    (:attr:`signalled`), or whether it cannot tell (:attr:`blind`): the model replaced the
    handler, or Python's handler is not a Python callable. Where no Python handler raises
    ``KeyboardInterrupt`` on SIGINT (a thread other than the main one, as in dask workers, or
    the signal ignored), a ``KeyboardInterrupt`` can only come from the code itself.

    Loky workers share the terminal's process group, so a Ctrl-C reaches them too: there the
    watch sees the signal as in the main process and the interrupt stays the user's.
    """

    def __init__(self) -> None:
        self.signalled = False
        self._unknown_handler = False
        self._previous: Any = None

    def _note(self, signum: int, frame: Any) -> None:
        self.signalled = True
        self._previous(signum, frame)  # Python's default handler raises KeyboardInterrupt

    def __enter__(self) -> _SigintWatch:
        if threading.current_thread() is not threading.main_thread():
            return self
        current = signal.getsignal(signal.SIGINT)
        if current is None:  # a handler installed outside Python: it may raise anything
            self._unknown_handler = True
        elif callable(current):
            self._previous = current
            signal.signal(signal.SIGINT, self._note)
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._previous is not None:  # the handler of before the call, whatever the model did
            signal.signal(signal.SIGINT, self._previous)

    @property
    def blind(self) -> bool:
        """Whether a SIGINT may have gone unseen: the handler is not (or no longer) ours."""
        if self._previous is None:
            return self._unknown_handler
        return signal.getsignal(signal.SIGINT) != self._note

    @property
    def interrupts(self) -> bool:
        """Whether a SIGINT raises ``KeyboardInterrupt`` here (Python's default handler)."""
        return self._previous is signal.default_int_handler

    def users(self, error: BaseException) -> bool:
        """Whether ``error``, raised by the model's code, is the user's interrupt: a
        ``KeyboardInterrupt`` after a SIGINT or one the watch may have missed, or anything the
        model made of a Ctrl-C (``sys.exit()``, an error) where SIGINT means interrupt."""
        if isinstance(error, KeyboardInterrupt):
            return self.signalled or self.blind
        return self.signalled and self.interrupts


class _ModelExit(Exception):
    """A ``BaseException`` (``SystemExit``, ``KeyboardInterrupt``, ``GeneratorExit``, ...) the
    model's code raised, carried as an ordinary failure; the message describes it."""


def _describe(error: BaseException) -> str:
    """``Type: message`` of an error raised by the model's code."""
    if isinstance(error, _ModelExit):
        return str(error)
    if isinstance(error, SystemExit):
        return f"SystemExit: {error.code}"
    if isinstance(error, KeyboardInterrupt):
        return "KeyboardInterrupt raised by the model (no Ctrl-C reached pcmb)"
    if not isinstance(error, Exception):
        text = str(error)
        return f"{type(error).__name__}: {text}" if text else type(error).__name__
    return f"{type(error).__name__}: {error}"


def _model_code(function: Callable[..., _T], *args: Any) -> _T:
    """``function(*args)``, code of the model: a ``BaseException`` it raises becomes
    :class:`_ModelExit`, unless it is the user's interrupt, which becomes (or stays)
    ``KeyboardInterrupt`` — also when the model swallowed the SIGINT and returned."""
    with _SigintWatch() as watch:
        try:
            result = function(*args)
        except BaseException as error:
            if watch.users(error):
                if isinstance(error, KeyboardInterrupt):
                    raise
                raise KeyboardInterrupt from error
            if isinstance(error, Exception):
                raise
            raise _ModelExit(_describe(error)) from error
    if watch.signalled and watch.interrupts:
        raise KeyboardInterrupt  # the model swallowed the user's Ctrl-C
    return result


# One model per thread of each process (a dask worker may run several threads; MuJoCo data is
# not thread-safe). Building can be expensive (loading a scene), so it happens once per worker.
_MODEL_CACHE = threading.local()


@dataclass(frozen=True)
class _Factory:
    """A model factory as sent to workers: pickled by value, with the sender's import path.

    A worker unpickles it itself, after adding the sender's ``sys.path`` entries it lacks, so
    that a kept worker finds modules the caller made importable after the worker started.
    """

    token: str
    payload: bytes
    path: tuple[str, ...]

    def build(self) -> tuple[Model, Any]:
        """The model, and the factory that built it."""
        missing = [entry for entry in self.path if entry not in sys.path]
        sys.path.extend(missing)
        factory = cloudpickle.loads(self.payload)
        return factory(), factory


def _cached_model(factory: _Factory) -> tuple[Model, float]:
    """The model built by ``factory`` in this thread, and the seconds spent building it now."""
    token = factory.token
    held = getattr(_MODEL_CACHE, "held", None)
    if held is not None and held[0] == token:
        return held[1], 0.0
    _MODEL_CACHE.held = None  # release the previous model before building the next one
    start = time.perf_counter()
    try:
        model, maker = _model_code(factory.build)
    except PcmbError:
        raise
    except Exception as exc:
        raise ModelDefinitionError(f"could not build the model: {_describe(exc)}") from exc
    _MODEL_CACHE.held = (token, model, maker)
    return model, time.perf_counter() - start


def _loaded_files() -> tuple[str, ...]:
    """The files the model this thread holds loaded while it was built (its factory's
    ``loaded_files``): asked when the model is described, not at every build."""
    loaded = getattr(_MODEL_CACHE.held[2], "loaded_files", None)
    return tuple(str(path) for path in loaded()) if callable(loaded) else ()


@dataclass(frozen=True)
class ModelFacts:
    """What a model says about itself, learnt by building it in a worker.

    Attributes
    ----------
    name:
        Its class name.
    outputs:
        The outputs it offers.
    parameters:
        The parameters it takes, when it lists them (``None`` otherwise).
    chunk_size:
        Its preferred nodes per call (model protocol), or ``None``.
    build_seconds:
        Time the build took (each worker builds the model once).
    nominal_from_params:
        Whether its ``parameters`` are exactly the nominal values it was given.
    time_problems:
        ``(key, message)`` of what its ``check_times`` found wrong with the time grid asked
        about (see :func:`describe_model`).
    axes:
        Its ``output_axes`` (model protocol): output name -> its own axis, or ``None`` for a
        scalar; the outputs not listed are on time.
    input_problems:
        ``(key, message)`` of what its ``check_inputs`` found wrong with the uncertain inputs
        asked about (see :func:`describe_model`).
    loaded_files:
        The files it loaded while built, absolute (its factory's ``loaded_files``: a python
        model's own modules), for the resume journal's fingerprint.
    """

    name: str
    outputs: tuple[str, ...]
    parameters: tuple[str, ...] | None
    chunk_size: int | None
    build_seconds: float
    nominal_from_params: bool = False
    time_problems: tuple[tuple[str, str], ...] = ()
    axes: Mapping[str, OutputAxis | None] = dataclasses.field(default_factory=dict)
    input_problems: tuple[tuple[str, str], ...] = ()
    loaded_files: tuple[str, ...] = ()


def _problems(model: Model, check: str, argument: object, key: str) -> tuple[tuple[str, str], ...]:
    """``(key, message)`` of what the model's optional ``check`` method raises as a
    :class:`~pcmb.errors.ConfigError` about ``argument`` (none without the method)."""
    method = getattr(model, check, None)
    if not callable(method):
        return ()
    try:
        _model_code(method, argument)
    except ConfigError as error:
        return tuple((p.path or key, p.message) for p in error.problems)
    return ()


def _model_facts(
    factory: _Factory, times: NDArray[np.float64] | None, inputs: tuple[str, ...]
) -> ModelFacts:
    """Build (or reuse) the model in this process and describe it."""
    model, seconds = _cached_model(factory)
    time_problems = () if times is None else _problems(model, "check_times", times, "time")
    input_problems = _problems(model, "check_inputs", inputs, "inputs") if inputs else ()
    offered = getattr(model, "outputs", None)
    if offered is None or not callable(getattr(model, "simulate", None)):
        raise UsageError(
            [ConfigProblem("model_factory", "must build an object with outputs and simulate()")],
            source="run_nodes",
        )
    parameters = getattr(model, "parameters", None)
    axes = dict(getattr(model, "output_axes", None) or {})
    problems = axis_problems(axes, tuple(offered))
    if problems:
        raise ModelDefinitionError(f"the model's output_axes: {'; '.join(problems)}")
    return ModelFacts(
        name=type(model).__name__,
        outputs=tuple(offered),
        parameters=None if parameters is None else tuple(parameters),
        chunk_size=getattr(model, "chunk_size", None),
        build_seconds=seconds,
        nominal_from_params=bool(getattr(model, "nominal_from_params", False)),
        time_problems=time_problems,
        axes=axes,
        input_problems=input_problems,
        loaded_files=_loaded_files(),
    )


def _factory(model_factory: Callable[[], Model]) -> _Factory:
    """``model_factory`` ready to be sent to workers; the token is its identity (the model
    cached in a worker is reused for the same token)."""
    try:
        payload = cloudpickle.dumps(model_factory)
    except Exception as exc:  # pickling can fail with almost any exception type
        raise UsageError(
            [ConfigProblem("model_factory", f"cannot be sent to worker processes: {exc}")],
            source="run_nodes",
        ) from exc
    return _Factory(hashlib.sha256(payload).hexdigest(), payload, tuple(sys.path))


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
        facts, death = _wait(pool, pool.submit(_model_facts, factory, grid, tuple(inputs)))
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
        result, death = _wait(pool, pool.submit(_with_model, factory, task, args))
        if death is None:
            return result  # type: ignore[return-value]
    raise ModelDefinitionError(f"the model's worker died: {death}")


def _with_model(factory: _Factory, task: Callable[..., _T], args: tuple[Any, ...]) -> _T:
    model, _ = _cached_model(factory)
    return _model_code(task, model, *args)


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


@dataclass(frozen=True)
class _Call:
    """One ``simulate`` call (:func:`_run_batch`).

    Attributes
    ----------
    values:
        (B, W) values.
    messages:
        Per node, why it failed ("" = ok).
    failed:
        Whether the call as a whole failed (it raised or returned a wrong result), so that
        which node made it fail is unknown.
    broken:
        Whether that failure is a break of the protocol (a ``ModelDefinitionError``: a
        failure of the call, which the campaign turns into a model error only if the model
        broke it at every node it tried).
    traceback:
        Where the model's code raised, if it did.
    """

    values: NDArray[np.float64]
    messages: list[str]
    failed: bool = False
    broken: bool = False
    traceback: ModelTraceback | None = None


# The post-mortem debugger of pcmb run --pdb, while it is active in this context (post_mortem).
_DEBUGGER: ContextVar[Callable[[BaseException], None] | None] = ContextVar(
    "pcmb_post_mortem", default=None
)


@contextmanager
def post_mortem() -> Iterator[None]:
    """While the block runs, open pdb's post-mortem debugger at the first error the model's
    code raises in this thread (``pcmb run --pdb``: the in-process backend runs the model
    here), in the frame that raised it. The run goes on when the debugger is left."""
    opened = False

    def debug(error: BaseException) -> None:
        nonlocal opened
        if not opened:
            opened = True
            _debug(model_exception(error))

    token = _DEBUGGER.set(debug)
    try:
        yield
    finally:
        _DEBUGGER.reset(token)


def _debug(error: BaseException) -> None:
    """pdb's post-mortem of ``error``, with the SIGINT handler of before it afterwards (pdb's
    ``continue`` installs its own)."""
    import pdb

    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main else None
    try:
        pdb.post_mortem(error.__traceback__)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _run_batch(
    model: Model, params: Mapping[str, NDArray[np.float64]], layout: Layout, full: bool
) -> _Call:
    """One ``simulate`` call; ``full``: keep the whole traceback of an error of the model's
    code, pcmb's frames included (else the model's frames only)."""
    n = len(next(iter(params.values())))
    values = layout.empty(n)
    try:
        result = _model_code(model.simulate, params, layout.times)
        # Reading the result runs the model's code too (a mapping's lookup, an __array__).
        problem = _model_code(_collect, result, layout, values)
    except ModelDefinitionError as exc:
        return _Call(values, [str(exc)] * n, failed=True, broken=True)
    except Exception as exc:  # the model's own failure, whatever its type, is data here
        found = model_traceback(exc, full)
        debugger = _DEBUGGER.get()
        if debugger is not None and found is not None:  # pdb has nothing to show in pcmb's code
            debugger(exc)
        return _Call(values, [_describe(exc)] * n, failed=True, traceback=found)
    if problem:
        return _Call(values, [problem] * n, failed=True)
    messages = []
    columns = [np.isfinite(part) for part in layout.split(values).values()]
    for i in range(n):
        # The earliest point (time) of any output, as for outputs that share the time grid.
        first = [(int(np.argmin(c[i])), k) for k, c in enumerate(columns) if not c[i].all()]
        if first:
            j, k = min(first)
            messages.append(f"non-finite output {layout.outputs[k]!r}{layout.where(k, j)}")
        else:
            messages.append("")
    return _Call(values, messages)


def _collect(result: object, layout: Layout, values: NDArray[np.float64]) -> str:
    """Copy a ``simulate`` result into (B, W) ``values``; what is wrong, or ""."""
    n = values.shape[0]
    if not isinstance(result, Mapping):
        return f"simulate returned {type(result).__name__}, expected a mapping"
    for name, shape, (a, b) in zip(layout.outputs, layout.shapes, layout.bounds, strict=True):
        if name not in result:
            return f"the model returned no output {name!r}"
        try:
            array = float_array(result[name], f"output {name!r}")
        except ModelError as error:  # not numeric, or complex: nothing may be lost
            return str(error)
        if array.shape != (n, *shape):
            return f"output {name!r} has shape {array.shape}, expected {(n, *shape)}"
        values[:, a:b] = array.reshape(n, b - a)
    return ""


def _execute(
    factory: _Factory,
    params: Mapping[str, NDArray[np.float64]],
    layout: Layout,
    batched: bool,
    retries: int,
    caller: int,
) -> _Outcome:
    """Run one task (in a worker or in-process), narrowing a failed batch down to its nodes.
    ``caller``: the process id of the run; an error of the model's code in that very process
    (the in-process backend, for debugging) keeps its whole traceback.

    A per-point model (one with ``run_point``, see
    :class:`~pcmb.adapters.protocol.PointwiseModel`) is called node by node: its batch is a
    loop over the nodes anyway, and a one-node call raises the node's own reason where a
    batch would only return a NaN row, so each node runs once (``1 + retries`` times if it
    fails) and its failure keeps its message.
    """
    model, _ = _cached_model(factory)
    # Read-only views: a model that writes into its inputs fails the same way in-process and in
    # a worker, instead of corrupting the caller's arrays only when run in-process.
    params = {name: _read_only(array) for name, array in params.items()}
    layout = dataclasses.replace(layout, times=_read_only(layout.times))
    start = time.perf_counter()
    n = len(next(iter(params.values())))
    values = layout.empty(n)
    messages = ["not run"] * n
    full = os.getpid() == caller
    narrow = _Narrowing(
        model, params, layout, retries, full, values, messages, [False] * n, [None] * n
    )
    if batched and n > 1 and not callable(getattr(model, "run_point", None)):
        narrow.batch(0, n)
    else:
        for i in range(n):
            narrow.alone(i)
    return _Outcome(
        values,
        tuple(messages),
        time.perf_counter() - start,
        tuple(narrow.broken),
        tuple(narrow.tracebacks),
    )


@dataclass
class _Narrowing:
    """Runs the nodes of one task into ``values``, ``messages`` and ``tracebacks`` (see
    :func:`_execute`); ``full``: keep whole tracebacks (see :func:`_run_batch`)."""

    model: Model
    params: Mapping[str, NDArray[np.float64]]
    layout: Layout
    retries: int
    full: bool
    values: NDArray[np.float64]
    messages: list[str]
    broken: list[bool]
    tracebacks: list[ModelTraceback | None]

    def alone(self, i: int) -> None:
        """Run node ``i`` in a one-node batch, ``1 + retries`` times at most."""
        single = {name: array[i : i + 1] for name, array in self.params.items()}
        for _ in range(1 + self.retries):
            call = _run_batch(self.model, single, self.layout, self.full)
            if not call.messages[0] or call.broken:  # a break of the protocol is no accident
                break
        self.values[i], self.messages[i] = call.values[0], call.messages[0]
        self.broken[i], self.tracebacks[i] = call.broken, call.traceback

    def batch(self, start: int, stop: int) -> None:
        """Run nodes ``[start, stop)`` in one batched call; narrow it down if it fails.

        A call that fails as a whole (it raised or returned a wrong shape) does not say which
        node made it fail: it is split in halves, each run again the same way, so one bad node
        among B costs about 2 log2(B) more calls instead of B. A node with a non-finite row in
        a call that worked is re-run alone, to name its failure or to succeed alone. The finite
        rows of a batch are kept: nodes interact only through a stacked solver's shared step
        control, and a non-finite node makes that fail the whole call rather than bias the
        other rows.
        """
        if stop - start == 1:
            self.alone(start)
            return
        part = {name: array[start:stop] for name, array in self.params.items()}
        call = _run_batch(self.model, part, self.layout, self.full)
        if call.failed:
            middle = (start + stop) // 2
            self.batch(start, middle)
            self.batch(middle, stop)
            return
        self.values[start:stop], self.messages[start:stop] = call.values, call.messages
        for i in [start + k for k, message in enumerate(call.messages) if message]:
            self.alone(i)


def _read_only(array: NDArray[np.float64]) -> NDArray[np.float64]:
    view = array.view()
    view.flags.writeable = False
    return view


# -- the campaign ----------------------------------------------------------------------------


class _Campaign:
    """The state of one :func:`run_nodes` call: arguments, results so far, journal, progress.

    ``proven``: the model is known to work (see :func:`run_nodes`), so that a break of the
    protocol is never taken for a model error. ``keep_values`` False: the values go to the
    journal only (a streamed study, :mod:`pcmb.run.memory`), the result's arrays have no rows.
    """

    def __init__(
        self,
        factory: _Factory,
        params: dict[str, NDArray[np.float64]],
        times: NDArray[np.float64],
        outputs: tuple[str, ...],
        retries: int,
        journal: Journal | None,
        axes: Mapping[str, OutputAxis | None] | None = None,
        proven: bool = False,
        keep_values: bool = True,
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

    def resume(self, journal: Journal) -> None:
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
        """The arguments of :func:`_execute` for ``task``."""
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
        if self.progress is not None:
            self.progress.advance(task.indices.size)

    def accept_outcome(self, task: _Task, outcome: _Outcome) -> None:
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


def _run_alone(campaign: _Campaign, pool: Pool, task: _Task, limits: _Limits) -> _Outcome | str:
    """Run ``task`` as the only task in the pool: its outcome, or why it did not finish."""
    future = pool.submit(_execute, *campaign.arguments(task))
    outcome, why = _wait(pool, future, limits.deadline(task, 0.0), lambda: limits.message(task))
    return why if outcome is None else outcome


def _isolate(campaign: _Campaign, pool: Pool, task: _Task, limits: _Limits) -> None:
    """Re-run a task whose worker died or overran, alone, down to single nodes."""
    attempts = 1 + campaign.retries if task.indices.size == 1 else 1
    for _ in range(attempts):
        found = _run_alone(campaign, pool, task, limits)
        if isinstance(found, _Outcome):
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
    With ``stop_on_failure``, no task is started once a node has failed; the tasks in flight
    finish (and are journaled), the others stay pending. While the model has broken the
    protocol at every node it tried, no task is started either: if the tasks in flight do
    not show it working somewhere, the loop ends there (a model error, see
    :func:`run_nodes`); if they do, the campaign goes on under the failure policy.
    """
    queue = deque(tasks)
    # One task queued beyond the workers hides the round trip between tasks (no more: loky's
    # queue takes one extra, and a kill must not find tasks waiting outside it). With a
    # timeout each task's clock must start when the task does: no task waits then.
    most = pool.slots + (1 if limits.timeout is None else 0)
    in_flight: dict[Future[_Outcome], tuple[_Task, float]] = {}
    lost: list[_Task] = []
    while queue or in_flight:
        if campaign.broken_everywhere and not in_flight:
            break
        # After a death, feed nothing more: let the chunks in flight finish or fail first.
        if stop_on_failure and campaign.messages:
            queue.clear()
        while queue and not lost and len(in_flight) < most and not campaign.broken_everywhere:
            task = queue.popleft()
            future = pool.submit(_execute, *campaign.arguments(task))
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
            queue.extendleft(t for t, d in reversed(in_flight.values()) if d > now)
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


def _check_arguments(
    params: Mapping[str, ArrayLike],
    times: ArrayLike,
    outputs: Sequence[str],
    jobs: int | None,
    backend: str,
    address: str | None,
    chunk_size: int | None,
    retries: int,
    timeout: float | None = None,
) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.float64], tuple[str, ...]]:
    """Validate the arguments of :func:`run_nodes` as a whole; return them as arrays."""
    problems: list[ConfigProblem] = []

    def integer_at_least(value: object, minimum: int) -> bool:
        return (
            isinstance(value, int | np.integer)
            and not isinstance(value, bool)
            and (value >= minimum)
        )

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
    if jobs is not None and not integer_at_least(jobs, 1):
        problems.append(ConfigProblem("jobs", f"must be a positive integer, got {jobs!r}"))
    if backend not in BACKENDS:
        problems.append(
            ConfigProblem("backend", f"must be one of {', '.join(BACKENDS)}, got {backend!r}")
        )
    elif address is not None and backend != "dask":
        problems.append(ConfigProblem("address", "is only used with backend 'dask'"))
    if chunk_size is not None and not integer_at_least(chunk_size, 1):
        problems.append(
            ConfigProblem("chunk_size", f"must be a positive integer, got {chunk_size!r}")
        )
    if not integer_at_least(retries, 0):
        problems.append(ConfigProblem("retries", f"must be an integer >= 0, got {retries!r}"))
    if timeout is not None and not (
        isinstance(timeout, int | float)
        and not isinstance(timeout, bool)
        and 0 < timeout < math.inf
    ):
        problems.append(ConfigProblem("timeout", f"must be a positive number, got {timeout!r}"))
    elif timeout is not None and backend in BACKENDS and not BACKENDS[backend].kills:
        problems.append(
            ConfigProblem("timeout", f"needs workers pcmb can kill (backend loky), not {backend}")
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


def _check_journal(journal: Journal, n_nodes: int, layout: Layout) -> None:
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
    jobs: int | None = None,
    backend: str = "loky",
    address: str | None = None,
    chunk_size: int | None = None,
    retries: int = 0,
    timeout: float | None = None,
    journal: Journal | None = None,
    progress: bool | None = None,
    stop_on_failure: bool = False,
    pool: Pool | None = None,
    facts: ModelFacts | None = None,
    proven: bool = False,
    keep_values: bool = True,
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
    jobs:
        Worker processes (slots); default: all cores (for dask with ``address``: all threads
        of the cluster).
    backend:
        ``"loky"`` (child processes), ``"dask"``, or ``"inprocess"`` (this process: no
        isolation, for debugging).
    address:
        Scheduler address of a dask cluster; with ``backend="dask"`` and no address a local
        cluster of ``jobs`` processes is started and closed.
    chunk_size:
        Nodes per chunk; default ``min(256, max(1, ceil(N / 16)))``. Results depend on it
        (batched integrators), so a journal fingerprint must include an explicit chunk size.
    retries:
        How many more times a failed node is tried before it is reported.
    timeout:
        Seconds a node may take (a chunk of B nodes: B times that, plus the time a fresh
        worker takes to start and build the model); a node past it is a failed run and its
        worker is killed. Needs a backend whose workers pcmb can kill (``loky``).
    journal:
        Persists every finished chunk; its successful nodes are taken instead of being run.
    progress:
        Progress line on stderr; default: only when stderr is a terminal.
    stop_on_failure:
        Start no more chunks once a node has failed (the policy ``abort``): the chunks in
        flight finish and every failure found in them is reported; the nodes never run stay
        pending (status 0), in the journal too, so a resumed run runs them.
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
    arrays, time_grid, names = _check_arguments(
        params, times, outputs, jobs, backend, address, chunk_size, retries, timeout
    )
    n_nodes = len(next(iter(arrays.values())))
    factory = _factory(model_factory)
    if pool is None:
        with open_pool(backend, jobs, address, tasks=len(chunk_bounds(n_nodes, chunk_size))) as own:
            return run_nodes(
                model_factory,
                arrays,
                time_grid,
                names,
                chunk_size=chunk_size,
                retries=retries,
                timeout=timeout,
                journal=journal,
                progress=progress,
                stop_on_failure=stop_on_failure,
                pool=own,
                proven=proven,
                keep_values=keep_values,
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
    )
    if journal is not None:
        campaign.resume(journal)
    # A model may prefer a chunk size (model protocol); an explicit one wins. Either way the
    # boundaries depend on N, the config and the model class only, never on jobs or backend.
    tasks = campaign.plan(chunk_bounds(n_nodes, chunk_size or facts.chunk_size))
    limits = _Limits(timeout, pool.startup_seconds + 2 * facts.build_seconds)
    show = sys.stderr.isatty() if progress is None else progress
    campaign.progress = Progress(n_nodes, campaign.resumed, sys.stderr if show else None)
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
    future: Future[_Outcome]
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
    arrays, time_grid, names = _check_arguments(
        params, times, outputs, jobs=None, backend="loky", address=None, chunk_size=None, retries=0
    )
    _check_outputs(facts, names)
    campaign = _Campaign(
        _factory(model_factory), arrays, time_grid, names, 0, None, facts.axes, proven=True
    )
    (task,) = campaign.plan([(0, len(next(iter(arrays.values()))))])
    future = pool.submit(_execute, *campaign.arguments(task))
    return PendingRun(campaign, task, future, started)
