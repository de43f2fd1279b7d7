"""The model protocol and the adapters that turn existing simulators into models.

A *model* (SPEC §3) is anything with ``outputs`` and ``simulate(params, times)``:

- ``params[name]`` holds only the uncertain inputs of one batch, each (B,) (or (B, m) for a
  field input); every other parameter keeps the nominal value given at construction;
- ``times`` is the (T,) output grid;
- the result maps every name in ``outputs`` to a (B, T) array.

Adapters provided here:

- a Python class (constructed with the config's ``model.params``) or a ready object with
  ``simulate`` is used as is (:func:`load_entry`, :func:`as_model`);
- a per-point function ``f(params: dict, times) -> dict[str, (T,)]`` is looped over the
  batch (:class:`FunctionModel`);
- an external executable is run once per node in its own work directory
  (:class:`CommandModel`).

Model *factories* are small picklable callables that build a model; the executor ships a
factory to each worker, which builds its model once. Problems found while building a
model (missing file, unknown attribute, a constructor that rejects its parameters) raise
:class:`~pcmb.errors.ConfigError` located at the config key they come from (``model.entry``,
``model.params``, ...), so the config validator reports them like any other key.

Pointwise adapters follow the project's batch convention: in a batch of several nodes a
failed node becomes a row of NaN (the executor treats non-finite rows as failed nodes and
keeps the others); a batch of one node raises :class:`~pcmb.errors.ModelError` with the
reason, which is how the executor names the failure.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import importlib
import importlib.util
import inspect
import io
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pcmb.errors import ConfigError, ConfigProblem, ModelError

__all__ = [
    "CommandModel",
    "CommandModelFactory",
    "FunctionModel",
    "Model",
    "ObjectModelFactory",
    "PointwiseModel",
    "PythonModelFactory",
    "as_model",
    "load_entry",
    "split_command",
]

OutputFormat = Literal["csv", "json", "npy", "npz"]
KeepPolicy = Literal["failed", "all", "none"]

_FORMATS: tuple[str, ...] = ("csv", "json", "npy", "npz")
_PLACEHOLDER = re.compile(r"\{\{\s*([^{}]*?)\s*\}\}")
# Template names that describe the output grid; dotted, so no parameter name can clash.
_GRID_NAMES = ("times.start", "times.stop", "times.points")
_PARAMS_FILE = "params.json"
_STDOUT_FILE = "stdout.txt"
_STDERR_FILE = "stderr.txt"
_TAIL_LINES = 15
_TAIL_CHARS = 2000


@runtime_checkable
class Model(Protocol):
    """What pcmb needs from a simulator (SPEC §3).

    Attributes
    ----------
    outputs:
        Names of the observables :meth:`simulate` returns.

    Notes
    -----
    A model may also have ``parameters: Mapping[str, float]``, the nominal value of every
    named parameter; the config validator then checks uncertain inputs against it. A model
    may have ``check_times(times)`` raising :class:`~pcmb.errors.ConfigError` when it
    cannot produce the grid; the config validator calls it before anything runs. A model
    whose ``simulate`` has a large per-call cost (a stacked integrator steps once for the
    whole batch) may state ``chunk_size: int``, the nodes per call it prefers; the executor
    uses it unless the config sets ``execution.chunk_size``.
    """

    outputs: tuple[str, ...]

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> Mapping[str, NDArray[np.float64]]:
        """Run one batch.

        Parameters
        ----------
        params:
            Uncertain inputs only, each (B,) or (B, m).
        times:
            Output grid, (T,).

        Returns
        -------
        Mapping[str, NDArray]
            Every name in ``outputs`` -> (B, T).
        """
        ...


def _problem(path: str, message: str) -> ConfigError:
    return ConfigError([ConfigProblem(path=path, message=message)])


def _describe(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# --------------------------------------------------------------------------- entry points


@contextlib.contextmanager
def _on_sys_path(directory: Path) -> Iterator[None]:
    """Put ``directory`` first on sys.path while importing, as ``python file.py`` would."""
    entry = str(directory)
    sys.path.insert(0, entry)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            sys.path.remove(entry)


def _load_file(path: Path) -> ModuleType:
    if not path.is_file():
        raise _problem("model.entry", f"model file {path} does not exist")
    # A unique module name per file, so two models both called model.py do not collide.
    digest = hashlib.sha256(str(path).encode()).hexdigest()[:12]
    stem = re.sub(r"\W", "_", path.stem)
    name = f"pcmb_entry_{stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise _problem("model.entry", f"{path} cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    # Registered before running it: dataclasses and pickling look modules up by name.
    sys.modules[name] = module
    try:
        with _on_sys_path(path.parent):
            spec.loader.exec_module(module)
    except (Exception, SystemExit) as exc:
        del sys.modules[name]
        raise _problem("model.entry", f"importing {path} failed: {_describe(exc)}") from exc
    return module


def _import_module(name: str, base_dir: Path) -> ModuleType:
    try:
        with _on_sys_path(base_dir):
            return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        raise _problem("model.entry", f"cannot import module {name!r}: {exc}") from exc
    except (Exception, SystemExit) as exc:
        raise _problem(
            "model.entry", f"importing module {name!r} failed: {_describe(exc)}"
        ) from exc


def load_entry(entry: str, base_dir: Path) -> object:
    """Load the object named by an entry point.

    Parameters
    ----------
    entry:
        ``path/to/file.py:Name`` (relative paths resolve against ``base_dir``) or
        ``package.module:Name`` (imported with ``base_dir`` first on ``sys.path``).
        ``Name`` may be dotted (``Outer.Inner``).
    base_dir:
        Folder of the config file.

    Returns
    -------
    object
        The class, function or object found.

    Raises
    ------
    ConfigError
        At ``model.entry``: malformed entry, missing file, failed import (with the original
        message), missing attribute.
    """
    target, sep, attribute = entry.rpartition(":")
    parts = attribute.split(".")
    if not sep or not target or not all(part.isidentifier() for part in parts):
        raise _problem(
            "model.entry",
            f"expected 'path/to/file.py:Name' or 'package.module:Name', found {entry!r}",
        )
    if target.endswith(".py"):
        module = _load_file((Path(base_dir) / target).resolve())
    else:
        module = _import_module(target, Path(base_dir).resolve())
    obj: object = module
    for depth, part in enumerate(parts):
        if not hasattr(obj, part):
            owner = ".".join([target, *parts[:depth]])
            raise _problem("model.entry", f"{owner} has no attribute {part!r}")
        obj = getattr(obj, part)
    return obj


def as_model(obj: object, params: Mapping[str, Any], outputs: Sequence[str] | None = None) -> Model:
    """Turn a class, a model object or a per-point function into a model.

    Parameters
    ----------
    obj:
        A class (constructed as ``obj(**params)``), an object with ``outputs`` and
        ``simulate`` (used as is), or a per-point function ``f(params, times) -> dict``
        (wrapped in a :class:`FunctionModel`).
    params:
        Nominal parameter values.
    outputs:
        Output names of a per-point function (ignored for classes and objects, which
        declare their own).

    Returns
    -------
    Model

    Raises
    ------
    ConfigError
        At ``model.params`` when the constructor rejects the parameters or an already built
        object is given parameters; at ``model.entry`` when ``obj`` is neither a class, a
        model nor a callable, or a class whose instances lack ``outputs``/``simulate``; at
        ``model.outputs`` for a function with no declared outputs.
    """
    name = getattr(obj, "__qualname__", type(obj).__name__)
    if inspect.isclass(obj):
        try:
            instance = obj(**params)
        except Exception as exc:
            raise _problem("model.params", f"{name}(**params) failed: {_describe(exc)}") from exc
        if not isinstance(instance, Model):
            raise _problem(
                "model.entry",
                f"{name} is not a model: its instances need 'outputs' and "
                "'simulate(params, times)'",
            )
        return instance
    if isinstance(obj, Model):
        if params:
            raise _problem(
                "model.params",
                f"{name} is an already constructed model and takes no params; "
                "give its class to construct it with these values",
            )
        return obj
    if callable(obj):
        return FunctionModel(obj, params, outputs)
    raise _problem(
        "model.entry",
        f"expected a model class, a model object or a function, found {type(obj).__name__}",
    )


# --------------------------------------------------------------------------- pointwise models


def split_command(text: str) -> list[str]:
    """Split a command line like a shell would (without running one).

    ``{{ name }}`` placeholders stay whole arguments, whatever spaces they hold.

    Raises
    ------
    ValueError
        Unbalanced quotes.
    """
    return shlex.split(_PLACEHOLDER.sub(lambda m: "{{" + m.group(1) + "}}", text))


def _float_array(value: Any, what: str) -> NDArray[np.float64]:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{what} is not numeric: {_describe(exc)}") from exc


def _check_point_result(
    result: object, outputs: Sequence[str], n_times: int, where: str
) -> dict[str, NDArray[np.float64]]:
    """Validate one node's outputs: a mapping with every output as a (T,) float array."""
    if not isinstance(result, Mapping):
        raise ModelError(f"{where} is a {type(result).__name__}, expected a dict of outputs")
    missing = [name for name in outputs if name not in result]
    if missing:
        raise ModelError(f"output(s) {', '.join(map(repr, missing))} missing from {where}")
    checked = {}
    for name in outputs:
        values = _float_array(result[name], f"output {name!r} in {where}")
        if values.shape != (n_times,):
            raise ModelError(
                f"output {name!r} in {where} has shape {values.shape}, expected ({n_times},)"
            )
        checked[name] = values
    return checked


class PointwiseModel(ABC):
    """A model that runs one node at a time; :meth:`simulate` loops over the batch.

    Subclasses set ``outputs`` and ``parameters`` and implement :meth:`run_point`.
    """

    outputs: tuple[str, ...]
    parameters: Mapping[str, Any]

    @abstractmethod
    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run one node.

        Parameters
        ----------
        values:
            The node's uncertain inputs (floats, or (m,) arrays for field inputs).
        times:
            Output grid, (T,).

        Returns
        -------
        dict[str, NDArray]
            Every name in ``outputs`` -> (T,).

        Raises
        ------
        ModelError
            The run failed; the message says how.
        """

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run a batch node by node.

        Parameters
        ----------
        params:
            Uncertain inputs, each (B,) or (B, m); names must be in ``parameters``.
        times:
            Output grid, (T,).

        Returns
        -------
        dict[str, NDArray]
            Every output -> (B, T); rows of failed nodes are NaN when B > 1.

        Raises
        ------
        ValueError
            Unknown parameter names, inconsistent batch sizes, or ``times`` not 1-D.
        ModelError
            The single node of a batch of one failed.
        """
        times = np.asarray(times, dtype=float)
        if times.ndim != 1:
            raise ValueError(f"times must be 1-D, got shape {times.shape}")
        unknown = sorted(set(params) - set(self.parameters))
        if unknown:
            raise ValueError(
                f"unknown parameter(s) {', '.join(unknown)}; "
                f"known: {', '.join(self.parameters) or 'none'}"
            )
        arrays = {name: np.asarray(value) for name, value in params.items()}
        sizes = {len(a) if a.ndim in (1, 2) else -1 for a in arrays.values()}
        if len(sizes) > 1 or -1 in sizes:
            shapes = {name: a.shape for name, a in arrays.items()}
            raise ValueError(f"params must all be (B,) or (B, m) with one B, got {shapes}")
        batch = sizes.pop() if sizes else 1
        out = {name: np.full((batch, times.size), np.nan) for name in self.outputs}
        for i in range(batch):
            values = {name: a[i] if a.ndim == 2 else float(a[i]) for name, a in arrays.items()}
            try:
                result = self.run_point(values, times)
            except ModelError:
                if batch == 1:
                    raise
                continue
            for name in self.outputs:
                out[name][i] = result[name]
        return out


class FunctionModel(PointwiseModel):
    """A per-point function ``f(params: dict, times) -> dict[str, (T,)]`` as a model.

    Parameters
    ----------
    func:
        Called once per node with the nominal ``params`` merged with the node's values.
    params:
        Nominal value of every parameter, including every input that will be uncertain.
    outputs:
        Names of the outputs to take from ``func``'s result; ``None`` uses
        ``func.outputs`` when the function declares it.

    Raises
    ------
    ConfigError
        At ``model.outputs`` when no output names are given or declared.
    """

    def __init__(
        self,
        func: Callable[[dict[str, Any], NDArray[np.float64]], Mapping[str, Any]],
        params: Mapping[str, Any],
        outputs: Sequence[str] | None = None,
    ):
        declared = outputs if outputs is not None else getattr(func, "outputs", None)
        name = getattr(func, "__qualname__", repr(func))
        if isinstance(declared, str):
            raise _problem("model.outputs", f"expected a list of names, found {declared!r}")
        if not declared:
            raise _problem(
                "model.outputs",
                f"the function {name} does not declare its outputs: list their names",
            )
        self.func = func
        self.outputs = tuple(declared)
        self.parameters = dict(params)
        self._who = name

    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Call the function at one node; see :meth:`PointwiseModel.run_point`."""
        try:
            result = self.func({**self.parameters, **values}, times)
        except Exception as exc:
            raise ModelError(f"{self._who} raised {_describe(exc)}") from exc
        return _check_point_result(result, self.outputs, times.size, f"the result of {self._who}")


# --------------------------------------------------------------------------- command models


@dataclass(frozen=True)
class _Template:
    name: str
    text: str


def _format_value(value: Any) -> str:
    """Exact text of a parameter: repr of a float round-trips bit for bit."""
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        return repr(float(array))
    return " ".join(repr(float(x)) for x in array.ravel())


def _jsonable(value: Any) -> Any:
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array.tolist()


def _tail(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    lines = text.rstrip().splitlines()[-_TAIL_LINES:]
    return "\n".join(lines)[-_TAIL_CHARS:]


def _wait_unreaped(pid: int, timeout: float | None) -> bool:
    """Wait for ``pid`` to exit without reaping it; True if it exited in time.

    Leaving the zombie in place keeps its process-group id reserved, so the group can be
    killed afterwards without any risk of signalling an unrelated process.
    """
    deadline = None if timeout is None else time.monotonic() + timeout
    delay = 0.0005
    while True:
        try:
            if os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
                return True
        except ChildProcessError:  # already reaped (SIGCHLD ignored): it has exited
            return True
        if deadline is not None and time.monotonic() >= deadline:
            return False
        # Poll quickly at first (short commands), then every 10 ms (negligible CPU).
        delay = min(2 * delay, 0.01)
        time.sleep(delay)


class CommandModel(PointwiseModel):
    """An external executable as a model, run once per node (SPEC §3 ``command``).

    Per node: a fresh work directory; template files rendered into it (``{{ name }}`` ->
    the exact float text, ``repr``; ``{{ times.start }}``, ``{{ times.stop }}`` and
    ``{{ times.points }}`` describe the grid); the listed ``files`` symlinked into it;
    ``params.json`` written (``{"params": {name: value}, "times": [...]}``); the command
    run there in its own process group, with ``timeout`` killing the whole group; the
    output file parsed.

    Parameters
    ----------
    command:
        The argv (a list, or a string split like a shell would, without running a shell).
        Arguments may contain placeholders too. A program given with a ``/`` resolves
        against ``base_dir``; a bare name is looked up on PATH.
    params:
        Nominal value of every parameter (all numbers), including every uncertain input.
    outputs:
        Output names to read from the output file.
    output_file:
        File the command writes in its work directory.
    output_format:
        ``csv`` (header row of names, one row per time), ``json`` (``{name: [...]}``),
        ``npy`` ((T,) for one output or (T, k) with columns in ``outputs`` order) or
        ``npz`` (arrays by name); ``None`` infers it from the file extension.
    templates:
        Template files (relative to ``base_dir``), rendered into the work directory under
        their own file name.
    files:
        Files linked into every work directory (the simulator script, a mesh...).
    base_dir:
        Folder relative paths resolve against (the config file's folder).
    timeout:
        Seconds before a run is killed (``None``: no limit).
    run_dir:
        Folder that receives the per-node work directories (default: the system temp dir).
    keep:
        Which work directories survive: ``failed`` (default; their path is in the error
        message), ``all`` or ``none``.
    time_column:
        Name of an optional time column/key in the output; when present it must match the
        requested grid.

    Raises
    ------
    ConfigError
        Located at the ``model.*`` key at fault: program not found, missing template or
        file, a placeholder naming no parameter, an unknown output format, clashing names.

    Notes
    -----
    Processes the command leaves behind are killed with its process group when it ends.
    """

    def __init__(
        self,
        command: str | Sequence[str],
        *,
        params: Mapping[str, float],
        outputs: Sequence[str],
        output_file: str,
        output_format: OutputFormat | None = None,
        templates: Sequence[str] = (),
        files: Sequence[str] = (),
        base_dir: Path | None = None,
        timeout: float | None = None,
        run_dir: Path | None = None,
        keep: KeepPolicy = "failed",
        time_column: str = "time",
    ):
        base_dir = Path.cwd() if base_dir is None else Path(base_dir).resolve()
        try:
            argv = split_command(command) if isinstance(command, str) else list(command)
        except ValueError as exc:
            raise _problem("model.command", f"cannot split the command: {exc}") from exc
        if not argv:
            raise _problem("model.command", "the command is empty")
        self.argv = (self._resolve_program(argv[0], base_dir), *argv[1:])
        try:
            self.parameters = {k: float(v) for k, v in params.items()}
        except (TypeError, ValueError) as exc:
            raise _problem("model.params", f"a command model takes numbers: {exc}") from exc
        if timeout is not None and not timeout > 0:
            raise _problem(
                "model.timeout", f"expected a positive number of seconds, found {timeout}"
            )
        if keep not in ("failed", "all", "none"):
            raise _problem("model.keep", f"expected 'failed', 'all' or 'none', found {keep!r}")
        self.outputs = tuple(outputs)
        if not self.outputs:
            raise _problem("model.outputs", "a command model must list the outputs it reads")
        if time_column in self.outputs:
            raise _problem("model.outputs", f"{time_column!r} is the time column, not an output")
        self.output_file = output_file
        self.output_format = self._resolve_format(output_file, output_format)
        self.timeout = timeout
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.keep = keep
        self.time_column = time_column
        self.templates = tuple(
            self._read_template(base_dir, name, f"model.templates[{i}]")
            for i, name in enumerate(templates)
        )
        self.files = tuple(
            self._resolve_file(base_dir, name, f"model.files[{i}]") for i, name in enumerate(files)
        )
        self._check_placeholders()
        self._check_names()

    # -- construction checks

    @staticmethod
    def _resolve_program(program: str, base_dir: Path) -> str:
        if os.sep in program:
            path = (base_dir / program).resolve()
            if not path.is_file() or not os.access(path, os.X_OK):
                raise _problem(
                    "model.command", f"program {path} does not exist or is not executable"
                )
            return str(path)
        found = shutil.which(program)
        if found is None:
            raise _problem("model.command", f"program {program!r} not found on PATH")
        return found

    @staticmethod
    def _resolve_format(output_file: str, output_format: str | None) -> str:
        if Path(output_file).name != output_file or output_file in ("", ".", ".."):
            raise _problem(
                "model.output.file", f"expected a plain file name, found {output_file!r}"
            )
        fmt = output_format or Path(output_file).suffix.lstrip(".").lower()
        if fmt not in _FORMATS:
            raise _problem(
                "model.output.format",
                f"expected one of {', '.join(_FORMATS)} (or an output file with such an "
                f"extension), found {fmt!r}",
            )
        return fmt

    @staticmethod
    def _resolve_file(base_dir: Path, name: str, key: str) -> Path:
        path = (base_dir / name).resolve()
        if not path.is_file():
            raise _problem(key, f"file {path} does not exist")
        return path

    def _read_template(self, base_dir: Path, name: str, key: str) -> _Template:
        path = self._resolve_file(base_dir, name, key)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise _problem(key, f"cannot read template {path}: {_describe(exc)}") from exc
        return _Template(path.name, text)

    def _check_placeholders(self) -> None:
        known = set(self.parameters) | set(_GRID_NAMES)
        hint = f"known: {', '.join([*self.parameters, *_GRID_NAMES])}"
        for i, template in enumerate(self.templates):
            for match in _PLACEHOLDER.finditer(template.text):
                if match.group(1) not in known:
                    line = template.text.count("\n", 0, match.start()) + 1
                    raise _problem(
                        f"model.templates[{i}]",
                        f"{template.name} line {line}: placeholder {match.group(0)!r} names "
                        f"no parameter ({hint})",
                    )
        for arg in self.argv[1:]:
            for match in _PLACEHOLDER.finditer(arg):
                if match.group(1) not in known:
                    raise _problem(
                        "model.command",
                        f"placeholder {match.group(0)!r} names no parameter ({hint})",
                    )

    def _check_names(self) -> None:
        """Everything placed in a work directory needs its own name."""
        names = [
            _PARAMS_FILE,
            _STDOUT_FILE,
            _STDERR_FILE,
            self.output_file,
            *(t.name for t in self.templates),
            *(f.name for f in self.files),
        ]
        clashes = sorted({n for n in names if names.count(n) > 1})
        if clashes:
            raise _problem(
                "model",
                f"work-directory file name(s) used twice: {', '.join(clashes)} "
                f"({_PARAMS_FILE}, {_STDOUT_FILE} and {_STDERR_FILE} are reserved)",
            )

    # -- one node

    def _render(self, text: str, context: Mapping[str, str]) -> str:
        return _PLACEHOLDER.sub(lambda m: context[m.group(1)], text)

    def _prepare(
        self, workdir: Path, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> list[str]:
        context = {name: _format_value(v) for name, v in values.items()}
        context.update(
            {
                "times.start": repr(float(times[0])),
                "times.stop": repr(float(times[-1])),
                "times.points": str(times.size),
            }
        )
        for template in self.templates:
            (workdir / template.name).write_text(self._render(template.text, context), "utf-8")
        for path in self.files:
            (workdir / path.name).symlink_to(path)
        document = {
            "params": {name: _jsonable(v) for name, v in values.items()},
            "times": times.tolist(),
        }
        (workdir / _PARAMS_FILE).write_text(json.dumps(document, indent=1), "utf-8")
        return [self.argv[0], *(self._render(arg, context) for arg in self.argv[1:])]

    def _execute(self, workdir: Path, argv: list[str]) -> None:
        with (
            open(workdir / _STDOUT_FILE, "wb") as stdout,
            open(workdir / _STDERR_FILE, "wb") as stderr,
        ):
            try:
                process = subprocess.Popen(
                    argv,
                    cwd=workdir,
                    stdin=subprocess.DEVNULL,
                    stdout=stdout,
                    stderr=stderr,
                    start_new_session=True,
                )
            except OSError as exc:
                raise ModelError(f"cannot start {argv[0]}: {_describe(exc)}") from exc
            try:
                finished = _wait_unreaped(process.pid, self.timeout)
            finally:
                # The leader is not reaped yet, so its group id cannot have been reused.
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                code = process.wait()
        tail = _tail(workdir / _STDERR_FILE) or _tail(workdir / _STDOUT_FILE)
        detail = f"; last output:\n{tail}" if tail else " (no output)"
        if not finished:
            raise ModelError(f"timed out after {self.timeout:g} s (process group killed){detail}")
        if code < 0:
            name = signal.Signals(-code).name if -code in signal.valid_signals() else "?"
            raise ModelError(f"killed by signal {-code} ({name}){detail}")
        if code > 0:
            raise ModelError(f"exited with code {code}{detail}")

    def _read_outputs(
        self, workdir: Path, times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        path = workdir / self.output_file
        if not path.is_file():
            raise ModelError(f"the command succeeded but wrote no output file {self.output_file}")
        try:
            columns = _READERS[self.output_format](path, self.outputs)
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, csv.Error) as exc:
            raise ModelError(
                f"cannot parse {self.output_file} as {self.output_format}: {_describe(exc)}"
            ) from exc
        if self.time_column in columns:
            self._check_time_column(columns[self.time_column], times)
        result = _check_point_result(columns, self.outputs, times.size, self.output_file)
        for name, values in result.items():
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ModelError(
                    f"output {name!r} in {self.output_file} is not finite at "
                    f"{bad.size} time(s), first at t={times[bad[0]]:g}"
                )
        return result

    def _check_time_column(self, column: Any, times: NDArray[np.float64]) -> None:
        file_times = _float_array(column, f"{self.time_column!r} in {self.output_file}")
        # A simulator may print times with few digits; a row must still be unmistakably its
        # grid time, i.e. within a small fraction of the grid step.
        step = np.min(np.diff(times)) if times.size > 1 else max(1.0, abs(float(times[0])))
        if file_times.shape != times.shape or not np.allclose(
            file_times, times, rtol=0, atol=1e-3 * step
        ):
            raise ModelError(
                f"the {self.time_column!r} column of {self.output_file} does not match the "
                f"requested grid ({times.size} points from {times[0]:g} to {times[-1]:g})"
            )

    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run the command for one node; see :meth:`PointwiseModel.run_point`.

        The ModelError message says what failed (exit code, signal, timeout, missing or
        unparseable output, wrong length, non-finite values) with the tail of the
        command's output, and where the kept work directory is.
        """
        times = np.asarray(times, dtype=float)
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix="pcmb-node-", dir=self.run_dir))
        succeeded = False
        try:
            argv = self._prepare(workdir, {**self.parameters, **values}, times)
            self._execute(workdir, argv)
            result = self._read_outputs(workdir, times)
            succeeded = True
            return result
        except ModelError as exc:
            if self.keep != "none":
                raise ModelError(f"{exc} [work directory kept: {workdir}]") from exc
            raise
        finally:
            if self.keep == "none" or (self.keep == "failed" and succeeded):
                shutil.rmtree(workdir, ignore_errors=True)


def _read_csv(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    text = path.read_text(encoding="utf-8", errors="replace")
    rows = [row for row in csv.reader(io.StringIO(text)) if row]
    if not rows:
        raise ValueError("the file is empty")
    header = [cell.strip() for cell in rows[0]]
    table = np.empty((len(rows) - 1, len(header)))
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(f"line {number} has {len(row)} fields, the header has {len(header)}")
        for j, cell in enumerate(row):
            try:
                table[number - 2, j] = float(cell)
            except ValueError:
                raise ValueError(f"line {number}: {cell.strip()!r} is not a number") from None
    return {name: table[:, j] for j, name in enumerate(header)}


def _read_json(path: Path, outputs: Sequence[str]) -> dict[str, Any]:
    document = json.loads(path.read_text(encoding="utf-8", errors="replace"))
    if not isinstance(document, dict):
        raise ValueError(f"expected an object {{name: [values]}}, found {type(document).__name__}")
    return document


def _read_npy(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    array = np.load(path, allow_pickle=False)
    if array.ndim == 1 and len(outputs) == 1:
        return {outputs[0]: array}
    if array.ndim != 2 or array.shape[1] != len(outputs):
        raise ValueError(f"expected shape (T, {len(outputs)}), found {array.shape}")
    return {name: array[:, j] for j, name in enumerate(outputs)}


def _read_npz(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    with np.load(path, allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


_READERS: dict[str, Callable[[Path, Sequence[str]], Mapping[str, Any]]] = {
    "csv": _read_csv,
    "json": _read_json,
    "npy": _read_npy,
    "npz": _read_npz,
}


# --------------------------------------------------------------------------- factories


@dataclass(frozen=True)
class PythonModelFactory:
    """Builds a model from an entry point (``file.py:Name`` or ``package.module:Name``).

    Picklable with plain pickle; each worker builds its own model.

    Parameters
    ----------
    entry, base_dir:
        See :func:`load_entry`.
    params:
        Nominal parameters (constructor keywords of a class, or a function's defaults).
    outputs:
        Output names of a per-point function (``None``: declared by the function).
    """

    entry: str
    base_dir: Path
    params: Mapping[str, Any]
    outputs: tuple[str, ...] | None = None

    def __call__(self) -> Model:
        """Load and build the model (raises ConfigError as :func:`as_model` does)."""
        return as_model(load_entry(self.entry, self.base_dir), self.params, self.outputs)


@dataclass(frozen=True)
class ObjectModelFactory:
    """Builds a model from a Python object: a class, a model instance or a function.

    Works in-process as is; joblib's workers receive it through cloudpickle.

    Parameters
    ----------
    obj, params, outputs:
        See :func:`as_model`.
    """

    obj: object
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    outputs: tuple[str, ...] | None = None

    def __call__(self) -> Model:
        """Build the model (raises ConfigError as :func:`as_model` does)."""
        return as_model(self.obj, self.params, self.outputs)


@dataclass(frozen=True)
class CommandModelFactory:
    """Builds a :class:`CommandModel`; the fields are its constructor's arguments."""

    command: tuple[str, ...]
    params: Mapping[str, float]
    outputs: tuple[str, ...]
    output_file: str
    output_format: OutputFormat | None = None
    templates: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    base_dir: Path | None = None
    timeout: float | None = None
    run_dir: Path | None = None
    keep: KeepPolicy = "failed"
    time_column: str = "time"

    def __call__(self) -> CommandModel:
        """Build the model (raises ConfigError as :class:`CommandModel` does)."""
        arguments = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return CommandModel(arguments.pop("command"), **arguments)
