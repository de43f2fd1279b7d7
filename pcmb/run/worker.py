"""What runs in a worker process (or in-process with the ``inprocess`` backend): the model
built once per worker thread and kept, described, and run on one task's nodes, a failed batch
narrowed down to its nodes. :mod:`pcmb.run.executor` sends these tasks from the parent.

Whatever the model's code raises while it builds or simulates is a failure of the nodes it was
running, described by type and message, with the model's part of the traceback
(:mod:`pcmb.run.tracebacks`) — ``BaseException`` s included: ``sys.exit()`` in a
model is ``SystemExit: 0`` at its node, never an exit of pcmb. The one exception is the user's
Ctrl-C: a ``KeyboardInterrupt`` (or anything else) raised while a SIGINT reached the process
stops the run, as does a SIGINT the model swallowed (see :class:`_SigintWatch`).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import cloudpickle
import numpy as np
from numpy.typing import NDArray

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
from pcmb.run.status import ModelTraceback
from pcmb.run.tracebacks import model_exception, model_traceback

if TYPE_CHECKING:
    from pcmb.adapters.protocol import Model

__all__ = [
    "Layout",
    "ModelFacts",
    "Outcome",
    "SentFactory",
    "model_facts",
    "post_mortem",
    "run_task",
    "with_model",
]

_T = TypeVar("_T")


# -- what a task returns, and how its outputs sit --------------------------------------------


@dataclass(frozen=True)
class Outcome:
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
class SentFactory:
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


def _cached_model(factory: SentFactory) -> tuple[Model, float]:
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
        about (see :func:`~pcmb.run.executor.describe_model`).
    axes:
        Its ``output_axes`` (model protocol): output name -> its own axis, or ``None`` for a
        scalar; the outputs not listed are on time.
    input_problems:
        ``(key, message)`` of what its ``check_inputs`` found wrong with the uncertain inputs
        asked about (see :func:`~pcmb.run.executor.describe_model`).
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


def model_facts(
    factory: SentFactory, times: NDArray[np.float64] | None, inputs: tuple[str, ...]
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


def with_model(factory: SentFactory, task: Callable[..., _T], args: tuple[Any, ...]) -> _T:
    model, _ = _cached_model(factory)
    return _model_code(task, model, *args)


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


def run_task(
    factory: SentFactory,
    params: Mapping[str, NDArray[np.float64]],
    layout: Layout,
    batched: bool,
    retries: int,
    caller: int,
) -> Outcome:
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
    return Outcome(
        values,
        tuple(messages),
        time.perf_counter() - start,
        tuple(narrow.broken),
        tuple(narrow.tracebacks),
    )


@dataclass
class _Narrowing:
    """Runs the nodes of one task into ``values``, ``messages`` and ``tracebacks`` (see
    :func:`run_task`); ``full``: keep whole tracebacks (see :func:`_run_batch`)."""

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
