"""The python adapter: entry points, the function markers, and factories of Python models.

A Python model is a class (constructed with ``params``), a model object, a
:class:`~pcmb.adapters.protocol.ModelFactory`, or a function marked with :func:`pointwise`
or :func:`batched` (an unmarked function is refused: how to call it cannot be guessed).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import importlib
import importlib.util
import inspect
import modulefinder
import re
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Literal, TypeVar, overload

import numpy as np
from numpy.typing import NDArray

from pcmb.adapters.protocol import (
    Model,
    ModelDefinitionError,
    ModelFactory,
    PointwiseModel,
    check_batch,
    describe_exception,
    float_array,
)
from pcmb.errors import ConfigError, ConfigProblem, ModelError, UsageError
from pcmb.run.tracebacks import installed, installed_folders
from pcmb.wording import did_you_mean

__all__ = [
    "MARKER",
    "BatchFunctionModel",
    "FunctionModel",
    "ObjectModelFactory",
    "PythonModelFactory",
    "as_model",
    "batched",
    "function_kind",
    "is_function_model",
    "load_entry",
    "local_modules",
    "model_factory",
    "pointwise",
    "python_entry_files",
]

#: The attribute :func:`pointwise` and :func:`batched` set on a function: ``"pointwise"`` or
#: ``"batched"``. (They also set ``outputs`` when given.)
MARKER = "pcmb_model"
FunctionKind = Literal["pointwise", "batched"]
F = TypeVar("F", bound=Callable[..., Any])


def _problem(path: str, message: str) -> ConfigError:
    return ConfigError([ConfigProblem(path=path, message=message)])


def _name(obj: object) -> str:
    return getattr(obj, "__qualname__", type(obj).__name__)


# --------------------------------------------------------------------------- markers


def _mark(kind: FunctionKind, func: Any, outputs: Sequence[str] | None) -> Any:
    where = f"pcmb.{kind}"
    if outputs is not None and (
        isinstance(outputs, str) or not all(isinstance(name, str) for name in outputs)
    ):
        raise UsageError(f"outputs: expected a sequence of names, got {outputs!r}", source=where)
    names = None if outputs is None else tuple(outputs)

    def mark(target: F) -> F:
        if not callable(target) or inspect.isclass(target):
            raise UsageError(f"expected a function, got {target!r}", source=where)
        try:
            setattr(target, MARKER, kind)
            if names is not None:
                target.outputs = names  # type: ignore[attr-defined]
        except AttributeError:
            raise UsageError(
                f"cannot mark {target!r}: wrap it in a def first", source=where
            ) from None
        return target

    return mark if func is None else mark(func)


@overload
def pointwise(func: F, /, *, outputs: Sequence[str] | None = None) -> F: ...
@overload
def pointwise(*, outputs: Sequence[str] | None = None) -> Callable[[F], F]: ...
def pointwise(func: Any = None, /, *, outputs: Sequence[str] | None = None) -> Any:
    """Mark a per-point function ``f(params: dict[str, float], times) -> {name: (T,)}``.

    pcmb calls it once per node with every nominal parameter, the node's uncertain inputs
    replaced by the node's values (floats; (m,) arrays for field inputs). Use it as
    ``@pcmb.pointwise(outputs=("y",))`` or ``pcmb.pointwise(f, outputs=("y",))``: it sets
    ``f.pcmb_model = "pointwise"`` (and ``f.outputs``) and returns ``f`` itself, so ``f``
    still pickles by reference.

    Parameters
    ----------
    func:
        The function (omitted when used as ``@pointwise(outputs=...)``).
    outputs:
        Names of the outputs it returns (``None``: named by the config's ``model.outputs``
        or the study's ``outputs``).
    """
    return _mark("pointwise", func, outputs)


@overload
def batched(func: F, /, *, outputs: Sequence[str] | None = None) -> F: ...
@overload
def batched(*, outputs: Sequence[str] | None = None) -> Callable[[F], F]: ...
def batched(func: Any = None, /, *, outputs: Sequence[str] | None = None) -> Any:
    """Mark a batch function ``f(params: Mapping[str, (B,) array], times) -> {name: (B, T)}``.

    pcmb calls it once per batch of B nodes; every numeric nominal parameter arrives as a
    (B,) array (the uncertain inputs with the nodes' values; field inputs (B, m)). Used like
    :func:`pointwise`; sets ``f.pcmb_model = "batched"``.
    """
    return _mark("batched", func, outputs)


def function_kind(obj: object) -> FunctionKind | None:
    """``"pointwise"`` or ``"batched"`` for a marked function, else ``None``."""
    if inspect.isclass(obj) or not callable(obj):
        return None
    kind = getattr(obj, MARKER, None)
    return kind if kind in ("pointwise", "batched") else None


def is_function_model(obj: object) -> bool:
    """Whether ``obj`` is a marked function (per-point or batch).

    Its parameters are exactly the ``params`` it is given, so a study gives every uncertain
    input a default there (its mean) unless the caller did.
    """
    return function_kind(obj) is not None


def _unmarked(obj: object) -> str:
    """Why an unmarked callable is refused, and how to mark it."""
    marks = (
        '@pcmb.pointwise(outputs=("y", ...)) above it if it computes one node, '
        "f(params: dict of floats, times) -> {name: (T,) array}, or "
        '@pcmb.batched(outputs=("y", ...)) if it computes a batch, '
        "f(params: dict of (B,) arrays, times) -> {name: (B, T) array}"
    )
    name = _name(obj)
    if inspect.isroutine(obj) or isinstance(obj, functools.partial):
        return f"{name} is an unmarked function, so pcmb cannot tell how to call it: put {marks}"
    return (
        f"the {name} object is callable but is no model (outputs and simulate), no "
        "pcmb.ModelFactory and no marked function: subclass pcmb.ModelFactory if it builds "
        f"a model, or put {marks}"
    )


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
        raise _problem(
            "model.entry", f"importing {path} failed: {describe_exception(exc)}"
        ) from exc
    return module


def _import_module(name: str, base_dir: Path) -> ModuleType:
    try:
        with _on_sys_path(base_dir):
            return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        raise _problem("model.entry", f"cannot import module {name!r}: {exc}") from exc
    except (Exception, SystemExit) as exc:
        raise _problem(
            "model.entry", f"importing module {name!r} failed: {describe_exception(exc)}"
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
            hint = did_you_mean(part, (name for name in dir(obj) if not name.startswith("_")))
            raise _problem("model.entry", f"{owner} has no attribute {part!r}; {hint}".rstrip("; "))
        obj = getattr(obj, part)
    return obj


def python_entry_files(entry: str, base_dir: str | Path) -> list[Path]:
    """The file of a python entry: ``file.py:Name`` -> that file; ``pkg.mod:Name`` -> the
    module's file once it is imported (in the worker that built the model), else none:
    finding it would import its packages, whose code must not run in pcmb's process."""
    target = entry.rpartition(":")[0]
    if not target:
        return []
    if target.endswith(".py"):
        return [(Path(base_dir) / target).resolve()]
    origin = getattr(sys.modules.get(target), "__file__", None)
    return [] if origin is None else [Path(origin).resolve()]


def local_modules(root: Path, script: Path | None = None, module: str | None = None) -> list[Path]:
    """The files of the modules under the folder ``root`` that the entry imports, directly
    or through its local modules, outside the installed environment (the standard library,
    site-packages, pcmb); none when ``root`` itself is installed.

    Read from the code (:mod:`modulefinder`, imports in function bodies included), not from
    ``sys.modules``: another model built earlier in the same process must not count, or a
    journal would differ from a fresh process's. Give the entry as a ``script`` file or a
    ``module`` name found on ``root``."""
    root = root.resolve()
    environment = installed_folders()
    if installed(root, environment):
        return []
    finder = modulefinder.ModuleFinder(path=[str(root)], excludes=["pcmb"])
    with contextlib.suppress(ImportError, SyntaxError):  # as the import itself reported
        if script is not None:
            finder.run_script(str(script))
        else:
            finder.import_hook(module)
    found = {Path(found.__file__).resolve() for found in finder.modules.values() if found.__file__}
    return sorted(p for p in found if p.is_relative_to(root) and not installed(p, environment))


# --------------------------------------------------------------------------- as_model


def _check_outputs(model: Model, outputs: Sequence[str] | None) -> Model:
    """The model, once every requested output is known to be one of its outputs."""
    offered = tuple(model.outputs)
    label = type(model).__name__
    problems = [
        ConfigProblem(
            f"model.outputs[{i}]",
            f"{name!r} is not an output of {label} (outputs: {', '.join(offered)})",
        )
        for i, name in enumerate(outputs or ())
        if name not in offered
    ]
    if problems:
        raise ConfigError(problems)
    return model


def as_model(obj: object, params: Mapping[str, Any], outputs: Sequence[str] | None = None) -> Model:
    """Turn a Python object into a model.

    Parameters
    ----------
    obj:
        A class (constructed as ``obj(**params)``), a model object (used as is), a
        :class:`~pcmb.adapters.protocol.ModelFactory` (called), or a function marked with
        :func:`pointwise` (wrapped in a :class:`FunctionModel`) or :func:`batched` (in a
        :class:`BatchFunctionModel`).
    params:
        Nominal parameter values (constructor keywords, or a function's parameters).
    outputs:
        Outputs wanted: every one must be an output of the model; for a function they name
        its outputs when it does not declare them.

    Returns
    -------
    Model

    Raises
    ------
    ConfigError
        At ``model.params`` when the constructor rejects the parameters or a built model or
        factory is given parameters; at ``model.entry`` when ``obj`` is no model, class,
        factory or marked function (an unmarked function: the message shows the marker); at
        ``model.outputs`` for outputs the model lacks or a function with no output names.
    """
    name = _name(obj)
    if inspect.isclass(obj):
        try:
            instance = obj(**params)
        except (Exception, SystemExit) as exc:
            raise _problem(
                "model.params", f"{name}(**params) failed: {describe_exception(exc)}"
            ) from exc
        if not isinstance(instance, Model):
            raise _problem(
                "model.entry",
                f"{name} is not a model: its instances need 'outputs' and "
                "'simulate(params, times)'",
            )
        return _check_outputs(instance, outputs)
    kind = function_kind(obj)
    if kind == "pointwise":
        return FunctionModel(obj, params, outputs)  # type: ignore[arg-type]
    if kind == "batched":
        return BatchFunctionModel(obj, params, outputs)  # type: ignore[arg-type]
    if isinstance(obj, ModelFactory | Model):
        if params:
            what = "a model factory" if isinstance(obj, ModelFactory) else "an already built model"
            raise _problem(
                "model.params",
                f"{name} is {what} and takes no params; give a model class to construct it "
                "with these values",
            )
        return _check_outputs(obj() if isinstance(obj, ModelFactory) else obj, outputs)
    if callable(obj):
        raise _problem("model.entry", _unmarked(obj))
    raise _problem(
        "model.entry",
        "expected a model class, a model object, a model factory or a marked function, "
        f"found {type(obj).__name__}",
    )


# --------------------------------------------------------------------------- function models


def _function_outputs(func: Callable[..., Any], outputs: Sequence[str] | None) -> tuple[str, ...]:
    """The outputs of a marked function: those asked for (among the declared ones), else the
    declared ones."""
    declared = getattr(func, "outputs", None)
    name = _name(func)
    kind = function_kind(func) or "pointwise"
    what = "per-point function" if kind == "pointwise" else "batch function"
    for given in (outputs, declared):
        if isinstance(given, str):
            raise _problem("model.outputs", f"expected a list of names, found {given!r}")
    if outputs is not None and declared:
        unknown = [
            ConfigProblem(
                f"model.outputs[{i}]",
                f"{out!r} is not an output of {name} (outputs: {', '.join(declared)})",
            )
            for i, out in enumerate(outputs)
            if out not in declared
        ]
        if unknown:
            raise ConfigError(unknown)
    chosen = outputs if outputs is not None else declared
    if not chosen:
        raise _problem(
            "model.outputs",
            f"the {what} {name} does not declare its outputs: list their names "
            f'(@pcmb.{kind}(outputs=("y", ...)), or model.outputs)',
        )
    return tuple(chosen)


def _definition_error(who: str, message: str) -> ModelDefinitionError:
    return ModelDefinitionError(f"the {who} {message}")


def _returned_mapping(result: object, outputs: Sequence[str], who: str, shape: str) -> Mapping:
    if not isinstance(result, Mapping):
        raise _definition_error(
            who, f"returned a {type(result).__name__}; it must return a dict {{name: {shape}}}"
        )
    missing = [name for name in outputs if name not in result]
    if missing:
        raise _definition_error(
            who,
            f"returned no output(s) {', '.join(map(repr, missing))} "
            f"(it returned: {', '.join(map(str, result)) or 'none'})",
        )
    return result


def _kind_of(value: Any) -> str:
    return f"a {type(value).__name__}" if np.ndim(value) == 0 else f"shape {np.shape(value)}"


class _MarkedFunction:
    """What the two function models share: the function, its outputs and nominal values."""

    nominal_from_params = True
    #: How messages name the function, e.g. "per-point function".
    what = "function"

    def __init__(
        self,
        func: Callable[[dict[str, Any], NDArray[np.float64]], Mapping[str, Any]],
        params: Mapping[str, Any],
        outputs: Sequence[str] | None = None,
    ):
        self.func = func
        self.outputs = _function_outputs(func, outputs)
        self.parameters = dict(params)
        self._who = f"{self.what} {_name(func)}"

    def _call(self, arguments: dict[str, Any], times: NDArray[np.float64], due: str) -> Mapping:
        """The function's result at ``arguments``, checked to be a mapping of the outputs."""
        try:
            result = self.func(arguments, times)
        except Exception as exc:
            raise ModelError(f"{_name(self.func)} raised {describe_exception(exc)}") from exc
        return _returned_mapping(result, self.outputs, self._who, due)

    def _numeric(self, name: str, value: Any) -> NDArray[np.float64]:
        return float_array(value, f"output {name!r} of the {self._who}")


class FunctionModel(_MarkedFunction, PointwiseModel):
    """A per-point function ``f(params: dict, times) -> dict[str, (T,)]`` as a model.

    Parameters
    ----------
    func:
        Called once per node with the nominal ``params`` merged with the node's values.
    params:
        Nominal value of every parameter, including every input that will be uncertain.
    outputs:
        Names of the outputs to take from ``func``'s result (among ``func.outputs`` when it
        declares them); ``None`` takes ``func.outputs``.

    Raises
    ------
    ConfigError
        At ``model.outputs`` when no output names are given or declared, or a given one is
        not declared.
    """

    what = "per-point function"

    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Call the function at one node; see :meth:`PointwiseModel.run_point`.

        A result that no node could get right (not a dict, an output missing, a number or a
        2-D array where a (T,) array is due) raises :class:`ModelDefinitionError`.
        """
        result = self._call({**self.parameters, **values}, times, "(T,) array")
        checked = {}
        for name in self.outputs:
            value = result[name]
            array = self._numeric(name, value)
            if array.ndim != 1:
                raise _definition_error(
                    self._who,
                    f"returned {_kind_of(value)} for output {name!r}; it must return a "
                    "(T,) array, one value per time",
                )
            if array.shape != (times.size,):
                raise ModelError(
                    f"output {name!r} of the {self._who} has shape {array.shape}, "
                    f"expected ({times.size},)"
                )
            checked[name] = array
        return checked


def _batch_value(nominal: Any, batch: int) -> Any:
    """A nominal value as the batch sees it: numbers repeated to (B,), (m,) to (B, m)."""
    if isinstance(nominal, bool):
        return nominal
    try:
        array = np.asarray(nominal)
    except Exception:  # any object may be a parameter of a function
        return nominal
    if array.dtype.kind not in "iuf" or array.ndim > 1:
        return nominal
    return np.repeat(array.astype(float)[None], batch, axis=0)


class BatchFunctionModel(_MarkedFunction):
    """A batch function ``f(params: Mapping[str, (B,)], times) -> {name: (B, T)}`` as a model.

    Parameters
    ----------
    func, params, outputs:
        As for :class:`FunctionModel`; every numeric nominal value in ``params`` reaches
        ``func`` repeated to (B,) ((B, m) for an (m,) value), the uncertain inputs with
        the batch's values.
    """

    what = "batch function"

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Call the function once for the batch (see the model protocol).

        Raises
        ------
        ValueError
            Unknown parameter names, inconsistent batch sizes, or ``times`` not 1-D.
        ModelError
            The function raised.
        ModelDefinitionError
            Its result is not a dict of (B, T) arrays.
        """
        arrays, times, batch = check_batch(params, times, self.parameters)
        full = {
            name: arrays[name] if name in arrays else _batch_value(value, batch)
            for name, value in self.parameters.items()
        }
        result = self._call(full, times, "(B, T) array")
        checked = {}
        for name in self.outputs:
            value = result[name]
            array = self._numeric(name, value)
            if array.shape != (batch, times.size):
                raise _definition_error(
                    self._who,
                    f"returned {_kind_of(value)} for output {name!r} for {batch} node(s) and "
                    f"{times.size} times; it must return a (B, T) array, here "
                    f"{(batch, times.size)}",
                )
            checked[name] = array
        return checked


# --------------------------------------------------------------------------- factories


@dataclass(frozen=True)
class PythonModelFactory(ModelFactory):
    """Builds a model from an entry point (``file.py:Name`` or ``package.module:Name``).

    Picklable with plain pickle; each worker builds its own model.

    Parameters
    ----------
    entry, base_dir:
        See :func:`load_entry`.
    params:
        Nominal parameters (constructor keywords of a class, or a function's defaults).
    outputs:
        Outputs wanted (``None``: every output; for a function, its declared ones).
    files:
        Further files the model reads (data, scripts), relative to ``base_dir``: each must
        exist; their digests go into a resume journal with the entry's and its modules'.
    """

    entry: str
    base_dir: Path
    params: Mapping[str, Any]
    outputs: tuple[str, ...] | None = None
    files: tuple[str, ...] = ()

    def __call__(self) -> Model:
        """Load and build the model (raises ConfigError as :func:`as_model` does, and at
        ``model.files[i]`` for a listed file that does not exist)."""
        missing = [
            ConfigProblem(f"model.files[{i}]", f"file {path} does not exist")
            for i, path in enumerate(self._listed())
            if not path.is_file()
        ]
        if missing:
            raise ConfigError(missing)
        return as_model(load_entry(self.entry, self.base_dir), self.params, self.outputs)

    def _listed(self) -> list[Path]:
        return [(Path(self.base_dir) / name).resolve() for name in self.files]

    def model_files(self) -> list[Path]:
        """The entry's file (:func:`python_entry_files`) and the listed ``files``."""
        return [*python_entry_files(self.entry, self.base_dir), *self._listed()]

    def loaded_files(self) -> list[Path]:
        """The modules of the entry's folder tree that the entry imports (:func:`local_modules`):
        the entry file's folder, or the folder holding a ``package.module`` entry's top package."""
        target = self.entry.rpartition(":")[0]
        found = python_entry_files(self.entry, self.base_dir)
        if not found:
            return []
        if target.endswith(".py"):
            return local_modules(found[0].parent, script=found[0])
        depth = target.count(".") + (found[0].name == "__init__.py")
        return local_modules(found[0].parents[depth], module=target)


# How as_model's config keys read for a Python caller (Study's arguments).
_API_KEYS = {"model.params": "params", "model.outputs": "outputs", "model.entry": "model"}


def _api_key(path: str) -> str:
    for key, argument in _API_KEYS.items():
        if path == key or path.startswith((f"{key}[", f"{key}.")):
            return argument + path[len(key) :]
    return path


@dataclass(frozen=True)
class ObjectModelFactory(ModelFactory):
    """Builds a model from a Python object given to the API (see :func:`model_factory`).

    Works in-process as is; joblib's workers receive it through cloudpickle.

    Parameters
    ----------
    obj, params, outputs:
        See :func:`as_model`.

    Raises
    ------
    UsageError
        What :func:`as_model` reports, named by the caller's argument (``params``,
        ``outputs``, ``model``).
    """

    obj: object
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    outputs: tuple[str, ...] | None = None

    def __call__(self) -> Model:
        """Build the model."""
        try:
            return as_model(self.obj, self.params, self.outputs)
        except ConfigError as exc:
            if not any(_api_key(p.path) != p.path for p in exc.problems):
                raise
            problems = [ConfigProblem(_api_key(p.path), p.message) for p in exc.problems]
            raise UsageError(problems, source="Study") from exc


def model_factory(
    model: object,
    params: Mapping[str, Any] | None = None,
    outputs: Sequence[str] | None = None,
) -> ModelFactory:
    """The factory of any model the Python API accepts; a ModelFactory is returned as is.

    Parameters
    ----------
    model:
        A :class:`~pcmb.adapters.protocol.ModelFactory`, a model class (constructed with
        ``params``), a model object, or a function marked with :func:`pointwise` or
        :func:`batched`.
    params:
        Nominal parameters of a class or a function (ignored for a factory).
    outputs:
        Outputs wanted (ignored for a factory).

    Raises
    ------
    UsageError
        At ``model``: an unmarked function (the message shows the markers) or something that
        is no model; at ``params``: parameters for an already built model.
    """
    if isinstance(model, ModelFactory):
        return model
    params = dict(params or {})
    name = _name(model)

    def usage(key: str, message: str) -> UsageError:
        return UsageError([ConfigProblem(key, message)], source="Study")

    if inspect.isclass(model) or is_function_model(model):
        pass
    elif isinstance(model, Model):
        if params:
            raise usage(
                "params",
                f"{name} is an already built model and takes no params; give its class to "
                "construct it with these values",
            )
    elif callable(model):
        raise usage("model", _unmarked(model))
    else:
        raise usage(
            "model",
            "expected a model factory, a model class, a model object or a marked function, "
            f"found {type(model).__name__}",
        )
    return ObjectModelFactory(model, params, None if outputs is None else tuple(outputs))
