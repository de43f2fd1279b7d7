"""Study configuration: safe YAML loading, a pydantic schema, and checks before anything runs.

:func:`load_config` reads a YAML file (SPEC §4) in three steps and collects every problem it
finds into one :class:`~pcmb.errors.ConfigError` — ``file:line: key.path: what was
expected, found what`` — so that nothing runs on an invalid config:

1. YAML: parsed with a safe loader that follows the YAML 1.2 core schema for plain scalars
   (``1e5`` is a number, ``no``/``on`` and dates stay text, no sexagesimal or octal
   surprises), rejects duplicate keys and unsupported tags, and remembers the line of every
   key.
2. Schema: :class:`StudyConfig` (pydantic v2, unknown keys forbidden, discriminated unions
   on ``model.kind`` and ``inputs.*.dist``); each distribution is built by :mod:`pcmb.chaos.inputs`
   in an after-validator, so its constructor's checks become located errors.
3. Semantics: cross-section checks (order mapping vs inputs, grid sizes), then the model is
   built exactly as a worker would build it — entry/XML found and loaded, the constructor
   accepts ``model.params`` — and checked: every requested output exists, every uncertain
   input names a model parameter, the model can produce the time grid.

This is the only module that imports the YAML library.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import re
import types
import typing
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from pcmb.adapters.python import (
    CommandModel,
    CommandModelFactory,
    FunctionModel,
    Model,
    PythonModelFactory,
    split_command,
)
from pcmb.analysis.statistics import MIN_SAMPLES, AnalysisSettings, window_problem
from pcmb.chaos import inputs
from pcmb.errors import ConfigError, ConfigProblem

__all__ = [
    "AnalysisSpec",
    "CommandModelSpec",
    "ExecutionSpec",
    "MethodSpec",
    "MujocoModelSpec",
    "PythonModelSpec",
    "StudyConfig",
    "TimeSpec",
    "config_json_schema",
    "load_config",
    "validate_config",
]

#: Largest number of model runs (collocation nodes or samples) a config may ask for.
MAX_RUNS = 10_000_000
#: Largest number of stored values per output (runs x time points): 8 GB of float64.
MAX_VALUES = 1_000_000_000
#: Largest number of YAML nodes in a document (guards against alias bombs).
MAX_YAML_NODES = 100_000

SAMPLING_KINDS = ("montecarlo", "lhs", "sobol")

KeyPath = tuple[str | int, ...]


# =========================================================================== YAML


class _Loader(yaml.SafeLoader):
    """A safe loader whose plain scalars follow the YAML 1.2 core schema."""

    # Own resolver table (PyYAML copies the parent's only when this attribute is missing).
    yaml_implicit_resolvers: typing.ClassVar[dict[str, list[Any]]] = {}


def _construct_int(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int:
    text = str(loader.construct_scalar(node))
    sign = -1 if text.startswith("-") else 1
    digits = text.lstrip("+-")
    base = {"0o": 8, "0x": 16}.get(digits[:2].lower(), 10)
    return sign * int(digits[2:] if base != 10 else digits, base)


def _construct_float(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> float:
    text = str(loader.construct_scalar(node))
    special = {".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, ".nan": math.nan}
    key = text.lower()
    return special[key] if key in special else float(text)


# YAML 1.2 core schema; "" (the empty scalar) resolves to null.
for _tag, _pattern, _first in [
    ("null", r"~|null|Null|NULL|", ["~", "n", "N", ""]),
    ("bool", r"true|True|TRUE|false|False|FALSE", "tTfF"),
    ("int", r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+", "-+0123456789"),
    (
        "float",
        r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?"
        r"|[-+]?\.(inf|Inf|INF)|\.nan|\.NaN|\.NAN",
        "-+.0123456789",
    ),
]:
    _Loader.add_implicit_resolver(
        f"tag:yaml.org,2002:{_tag}", re.compile(rf"^(?:{_pattern})$"), list(_first)
    )
_Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_Loader.add_constructor("tag:yaml.org,2002:float", _construct_float)

_SCALAR_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("str", "int", "float", "bool", "null")}
_INVALID = object()  # stands for a value already reported as a problem


class _YamlReader:
    """Turns a composed YAML node tree into plain data, recording the line of every key.

    Duplicate keys, unsupported tags, complex keys and recursive aliases become problems.
    """

    def __init__(self, loader: _Loader):
        self.loader = loader
        self.lines: dict[KeyPath, int] = {}
        self.problems: list[ConfigProblem] = []
        self._active: set[int] = set()
        self._count = 0

    def _report(self, path: KeyPath, message: str, node: yaml.Node) -> object:
        self.problems.append(ConfigProblem(_format_path(path), message, node.start_mark.line + 1))
        return _INVALID

    def read(self, node: yaml.Node, path: KeyPath = ()) -> Any:
        self.lines.setdefault(path, node.start_mark.line + 1)
        self._count += 1
        if self._count > MAX_YAML_NODES:
            raise _TooLarge
        if isinstance(node, yaml.ScalarNode):
            if node.tag not in _SCALAR_TAGS:
                return self._report(path, f"unsupported YAML tag {node.tag}", node)
            try:
                return self.loader.construct_object(node)
            except (ValueError, yaml.YAMLError) as exc:
                text = node.value if len(node.value) <= 40 else node.value[:37] + "..."
                kind = node.tag.rsplit(":", 1)[-1]
                return self._report(path, f"cannot read {text!r} as {kind}: {exc}", node)
        if id(node) in self._active:
            return self._report(path, "an alias refers to its own ancestor", node)
        expected = "map" if isinstance(node, yaml.MappingNode) else "seq"
        if node.tag != f"tag:yaml.org,2002:{expected}":
            return self._report(path, f"unsupported YAML tag {node.tag}", node)
        self._active.add(id(node))
        try:
            if isinstance(node, yaml.SequenceNode):
                return [self.read(item, (*path, i)) for i, item in enumerate(node.value)]
            return self._read_mapping(node, path)
        finally:
            self._active.discard(id(node))

    def _read_mapping(self, node: yaml.MappingNode, path: KeyPath) -> dict[Any, Any]:
        result: dict[Any, Any] = {}
        first_line: dict[Any, int] = {}
        for key_node, value_node in node.value:
            line = key_node.start_mark.line + 1
            key = self.read(key_node, path) if isinstance(key_node, yaml.ScalarNode) else None
            if key is _INVALID:
                continue
            if not isinstance(key, str | int | float | bool) or key != key:  # NaN is no key
                self._report(path, "keys must be plain names", key_node)
                continue
            if key in first_line:
                self._report(
                    (*path, key),
                    f"duplicate key {key!r} "
                    f"(first at line {first_line[key]}, again at line {line})",
                    key_node,
                )
                continue
            first_line[key] = line
            self.lines[(*path, key)] = line
            result[key] = self.read(value_node, (*path, key))
        return result


class _TooLarge(Exception):
    """The document expands to more than MAX_YAML_NODES nodes."""


def _parse_yaml(text: str, source: str) -> tuple[Any, dict[KeyPath, int], list[ConfigProblem]]:
    """Parse one YAML document into plain data, key lines and problems.

    Raises
    ------
    ConfigError
        Syntax errors, several documents, an empty document, an oversized document.
    """
    try:
        loader = _Loader(text)  # the reader already rejects unprintable characters
        try:
            node = loader.get_single_node()
            if node is None:
                raise ConfigError("the file is empty: expected a mapping of settings", source)
            reader = _YamlReader(loader)
            data = reader.read(node)
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        context = exc.context or ""
        if exc.context_mark is not None and exc.problem_mark is not None and context:
            context += f" (from line {exc.context_mark.line + 1})"
        detail = " ".join(part for part in (context, exc.problem or "") if part)
        line = None if mark is None else mark.line + 1
        raise ConfigError(
            [ConfigProblem("", f"YAML syntax error: {detail}", line)], source
        ) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        problem = ConfigProblem("", f"YAML error: {exc.reason} (found U+{code:04X})", line)
        raise ConfigError([problem], source) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"YAML error: {exc}", source) from None
    except _TooLarge:
        raise ConfigError(f"the document has more than {MAX_YAML_NODES} nodes", source) from None
    except RecursionError:
        raise ConfigError("the document is nested too deeply", source) from None
    return data, reader.lines, reader.problems


# =========================================================================== key paths


def _format_path(path: Sequence[str | int]) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) and not isinstance(part, bool) else f".{part}"
    return text.lstrip(".")


def _parse_path(text: str) -> KeyPath:
    return tuple(
        int(index) if index else key for key, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", text)
    )


def _line_of(path: KeyPath, lines: Mapping[KeyPath, int]) -> int | None:
    """Line of the key at ``path``, or of its nearest ancestor present in the file."""
    for end in range(len(path), -1, -1):
        if path[:end] in lines:
            return lines[path[:end]]
    return None


# =========================================================================== schema types


def _reject_text_and_bool(expected: str) -> Callable[[Any], Any]:
    """A before-validator: numbers must be written as numbers, not ``"1.5"`` or ``true``."""

    def check(value: Any) -> Any:
        if isinstance(value, bool | str):
            raise PydanticCustomError("wrong_type", "expected {expected}", {"expected": expected})
        return value

    return check


def _identifier(value: str) -> str:
    if not value.isidentifier():
        raise ValueError(f"expected a name made of letters, digits and _, found {value!r}")
    return value


def _unique(values: list[Any]) -> list[Any]:
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"listed twice: {', '.join(map(str, repeated))}")
    return values


def _h5_path(value: str) -> str:
    if not value.endswith(".h5"):
        raise ValueError(f"expected a file name ending in .h5, found {value!r}")
    return value


def _split_command(value: Any) -> Any:
    """A command may be written as one string; it is split like a shell would, without one."""
    if isinstance(value, str):
        return split_command(value)
    return value


def _count(**bounds: int) -> Any:
    """An integer type with bounds; the bounds come before the validator so that they
    stay plain JSON Schema keywords (minimum, maximum)."""
    return Annotated[int, Field(**bounds), BeforeValidator(_reject_text_and_bool("an integer"))]


Real = Annotated[float, BeforeValidator(_reject_text_and_bool("a number"))]
PositiveReal = Annotated[float, Field(gt=0), BeforeValidator(_reject_text_and_bool("a number"))]
NonNegativeReal = Annotated[float, Field(ge=0), BeforeValidator(_reject_text_and_bool("a number"))]
Probability = Annotated[
    float, Field(gt=0, lt=1), BeforeValidator(_reject_text_and_bool("a number"))
]
NonNegativeInt = _count(ge=0)
PositiveInt = _count(ge=1)
Axis = _count(ge=0, le=2)
Points = _count(ge=2, le=MAX_RUNS)
Name = Annotated[str, AfterValidator(_identifier)]
NameList = Annotated[list[Name], Field(min_length=1), AfterValidator(_unique)]
Command = Annotated[
    list[str],
    Field(min_length=1),
    BeforeValidator(_split_command, json_schema_input_type=str | list[str]),
]


class _Spec(BaseModel):
    """Base of every config section: unknown keys are errors, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


# --------------------------------------------------------------------------- inputs


class _InputSpec(_Spec, ABC):
    """An uncertain input; :attr:`distribution` is the :mod:`pcmb.chaos.inputs` object."""

    _distribution: inputs.Distribution = PrivateAttr()

    @property
    def distribution(self) -> inputs.Distribution:
        """The distribution built from this spec."""
        return self._distribution

    @abstractmethod
    def _build(self) -> inputs.Distribution:
        """The distribution this spec describes (its constructor validates)."""

    @model_validator(mode="after")
    def _construct(self) -> _InputSpec:
        # The constructor's ValueError becomes a validation error located at this input.
        self._distribution = self._build()
        return self


class UniformSpec(_InputSpec):
    """``{dist: uniform, low, high}``."""

    dist: Literal["uniform"]
    low: Real
    high: Real

    def _build(self) -> inputs.Distribution:
        return inputs.Uniform(self.low, self.high)


class BetaSpec(_InputSpec):
    """``{dist: beta, alpha, beta, low, high}`` in scipy's shape convention."""

    dist: Literal["beta"]
    alpha: Real
    beta: Real
    low: Real
    high: Real

    def _build(self) -> inputs.Distribution:
        return inputs.Beta(self.alpha, self.beta, self.low, self.high)


class NormalSpec(_InputSpec):
    """``{dist: normal, mean, std}``."""

    dist: Literal["normal"]
    mean: Real
    std: Real

    def _build(self) -> inputs.Distribution:
        return inputs.Normal(self.mean, self.std)


class GammaSpec(_InputSpec):
    """``{dist: gamma, shape, scale, loc}``."""

    dist: Literal["gamma"]
    shape: Real
    scale: Real
    loc: Real = 0.0

    def _build(self) -> inputs.Distribution:
        return inputs.Gamma(self.shape, self.scale, self.loc)


class ScipySpec(_InputSpec):
    """``{dist: scipy, name: lognorm, params: {s: 0.25, scale: 2.0}, germ: normal}``."""

    dist: Literal["scipy"]
    name: str
    params: dict[str, Real] = Field(default_factory=dict)
    germ: Literal["uniform", "normal"] = "normal"

    def _build(self) -> inputs.Distribution:
        import scipy.stats  # deferred: ~1 s of import that only this input kind needs

        law = getattr(scipy.stats, self.name, None) if not self.name.startswith("_") else None
        if not isinstance(law, scipy.stats.rv_continuous):
            raise ValueError(f"scipy.stats has no continuous distribution named {self.name!r}")
        shapes = [s.strip() for s in (law.shapes or "").split(",") if s.strip()]
        allowed = [*shapes, "loc", "scale"]
        unknown = sorted(set(self.params) - set(allowed))
        missing = [s for s in shapes if s not in self.params]
        if unknown or missing:
            raise ValueError(
                f"scipy.stats.{self.name} takes params {', '.join(allowed)}"
                + (f"; unknown: {', '.join(unknown)}" if unknown else "")
                + (f"; missing: {', '.join(missing)}" if missing else "")
            )
        target = law(**self.params)
        # scipy reports invalid parameters as a NaN support rather than an error.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            support = np.asarray(target.support(), dtype=float)
        if np.isnan(support).any():
            raise ValueError(f"scipy.stats.{self.name} rejects params {dict(self.params)}")
        return inputs.Transformed(target, self.germ)


InputSpec = Annotated[
    UniformSpec | BetaSpec | NormalSpec | GammaSpec | ScipySpec, Field(discriminator="dist")
]


# --------------------------------------------------------------------------- models


class PythonModelSpec(_Spec):
    """``kind: python``: a class, model object or per-point function from an entry point."""

    kind: Literal["python"]
    entry: str = Field(description="path/to/file.py:Name (relative to the config) or pkg.mod:Name")
    params: dict[Name, Any] = Field(default_factory=dict)
    outputs: NameList | None = Field(default=None, description="outputs to keep (default: all)")


class FieldBind(_Spec):
    """An input that sets a compiled MjModel field: ``{field: body_mass, name: bob}``."""

    field: str
    name: str | None = None
    index: NonNegativeInt | None = None


class Qpos0Bind(_Spec):
    """An input that sets the initial position of a joint."""

    qpos0: str


class Qvel0Bind(_Spec):
    """An input that sets the initial velocity of a joint."""

    qvel0: str


class QposOutput(_Spec):
    """``{qpos: joint}``."""

    qpos: str


class QvelOutput(_Spec):
    """``{qvel: joint}``."""

    qvel: str


class SensorOutput(_Spec):
    """``{sensor: name}``, with ``index`` for a sensor of several values."""

    sensor: str
    index: NonNegativeInt | None = None


class XposOutput(_Spec):
    """``{xpos: body, axis}``."""

    xpos: str
    axis: Axis


class SiteXposOutput(_Spec):
    """``{site_xpos: site, axis}``."""

    site_xpos: str
    axis: Axis


def _tagged_by_key(*variants: type[_Spec], error: str) -> Any:
    """A union whose member is chosen by which of the members' first keys is present.

    Tags contain a colon, so they can never be confused with a key of the config.
    """
    first_keys = {next(iter(v.model_fields)): v for v in variants}

    def tag(value: Any) -> str | None:
        if isinstance(value, BaseModel):
            return f"key:{next(iter(type(value).model_fields))}"
        if isinstance(value, Mapping):
            return next((f"key:{k}" for k in first_keys if k in value), None)
        return None

    members = tuple(Annotated[v, Tag(f"key:{k}")] for k, v in first_keys.items())
    return Annotated[
        typing.Union[members],  # noqa: UP007 (a runtime tuple of members)
        Discriminator(tag, custom_error_type="no_variant", custom_error_message=error),
    ]


BindEntry = _tagged_by_key(
    FieldBind,
    Qpos0Bind,
    Qvel0Bind,
    error="expected {field: ..., name: ..., index: ...}, {qpos0: joint} or {qvel0: joint}",
)
MujocoOutput = _tagged_by_key(
    QposOutput,
    QvelOutput,
    SensorOutput,
    XposOutput,
    SiteXposOutput,
    error="expected one of {qpos: joint}, {qvel: joint}, {sensor: name}, "
    "{xpos: body, axis: 0-2}, {site_xpos: site, axis: 0-2}",
)


class InitSpec(_Spec):
    """Fixed initial state by joint name."""

    qpos: dict[str, Real] = Field(default_factory=dict)
    qvel: dict[str, Real] = Field(default_factory=dict)


class MujocoModelSpec(_Spec):
    """``kind: mujoco``: an MJCF scene (SPEC §4)."""

    kind: Literal["mujoco"]
    xml: str = Field(description="MJCF file, relative to the config; may hold {{ name }}")
    params: dict[Name, Real] = Field(default_factory=dict)
    bind: dict[Name, Annotated[list[BindEntry], Field(min_length=1)]] = Field(default_factory=dict)
    init: InitSpec = Field(default_factory=InitSpec)
    outputs: Annotated[dict[Name, MujocoOutput], Field(min_length=1)]


class CommandOutputSpec(_Spec):
    """The file an external command writes in its work directory."""

    file: str
    format: Literal["csv", "json", "npy", "npz"] | None = Field(
        default=None, description="default: from the file extension"
    )
    time_column: str = Field(default="time", description="checked against the grid if present")


class CommandModelSpec(_Spec):
    """``kind: command``: an external executable run once per node (SPEC §3)."""

    kind: Literal["command"]
    command: Command = Field(description="argv list, or a string split like a shell would")
    params: dict[Name, Real] = Field(default_factory=dict)
    outputs: NameList
    output: CommandOutputSpec
    templates: list[str] = Field(default_factory=list, description="files rendered per node")
    files: list[str] = Field(default_factory=list, description="files linked into each node dir")
    timeout: PositiveReal | None = Field(default=None, description="seconds per run")
    run_dir: str | None = Field(default=None, description="parent of node dirs (default: temp)")
    keep: Literal["failed", "all", "none"] = "failed"


ModelSpec = Annotated[
    PythonModelSpec | MujocoModelSpec | CommandModelSpec, Field(discriminator="kind")
]

# Tags of the two discriminated unions, by discriminator key.
_UNION_TAGS = {
    "kind": ("python", "mujoco", "command"),
    "dist": ("uniform", "beta", "normal", "gamma", "scipy"),
}


# --------------------------------------------------------------------------- other sections


class TimeSpec(_Spec):
    """The output grid ``numpy.linspace(start, stop, points)``."""

    start: Real = 0.0
    stop: Real
    points: Points

    @field_validator("stop")
    @classmethod
    def _after_start(cls, stop: float, info: ValidationInfo) -> float:
        start = info.data.get("start")
        if start is not None and not stop > start:
            raise ValueError(f"expected stop > start = {start!r}, found {stop!r}")
        return stop


def _order_tag(value: Any) -> str:
    return "order:mapping" if isinstance(value, Mapping) else "order:int"


# Tagged by the value's type, so an error names the form the user wrote (an int or a mapping)
# instead of listing how the value fails both.
OrderSpec = Annotated[
    Annotated[NonNegativeInt, Tag("order:int")]
    | Annotated[dict[Name, NonNegativeInt], Tag("order:mapping")],
    Discriminator(_order_tag),
]


class MethodSpec(_Spec):
    """How nodes are chosen and coefficients recovered."""

    kind: Literal["collocation", "montecarlo", "lhs", "sobol"]
    fit: Literal["none", "regression"] = Field(
        default="none", description="regression: least-squares chaos fit on sampled nodes"
    )
    order: OrderSpec | None = Field(
        default=None, validate_default=True, description="int, or a mapping input -> int"
    )
    basis: Literal["tensor", "total"] = "tensor"
    samples: PositiveInt | None = Field(default=None, validate_default=True)
    seed: NonNegativeInt = 0

    @field_validator("order")
    @classmethod
    def _order_needed(cls, order: Any, info: ValidationInfo) -> Any:
        kind, fit = info.data.get("kind"), info.data.get("fit")
        if order is None and (kind == "collocation" or fit == "regression"):
            need = "kind collocation" if kind == "collocation" else "fit regression"
            raise PydanticCustomError(
                "missing", "required key is missing (needed by {need})", {"need": need}
            )
        return order

    @field_validator("samples")
    @classmethod
    def _samples_needed(cls, samples: int | None, info: ValidationInfo) -> int | None:
        kind = info.data.get("kind")
        if samples is None and kind in SAMPLING_KINDS:
            raise PydanticCustomError(
                "missing", "required key is missing (needed by kind {kind})", {"kind": kind}
            )
        return samples


class ExecutionSpec(_Spec):
    """Where and how the nodes run."""

    jobs: PositiveInt | None = Field(default=None, description="default: all cores")
    backend: Literal["loky", "dask"] = "loky"
    address: str | None = Field(default=None, description="dask scheduler (backend dask only)")
    on_failure: Literal["abort", "retry", "regress"] = "abort"
    retries: NonNegativeInt = 1
    chunk_size: PositiveInt | None = None

    @field_validator("address")
    @classmethod
    def _dask_only(cls, address: str | None, info: ValidationInfo) -> str | None:
        backend = info.data.get("backend")
        if address is not None and backend != "dask":
            raise ValueError(
                f"an address is only used with backend: dask, found backend {backend!r}"
            )
        return address


def _window(value: str) -> str:
    problem = window_problem(value)
    if problem is not None:
        raise ValueError(problem)
    return value


class AnalysisSpec(_Spec):
    """What to compute beyond mean, std and Sobol' indices (see :mod:`pcmb.analysis.statistics`)."""

    psd: Annotated[list[Name], AfterValidator(_unique)] | None = Field(
        default=None, description="outputs whose PSD is stored (default: all; [] for none)"
    )
    window: Annotated[str, AfterValidator(_window)] = Field(
        default="hann", description="scipy.signal window of every spectrum"
    )
    pdf_times: list[Real] | None = Field(
        default=None, description="times of the stored PDFs (default: the final time)"
    )
    pdf_freqs: list[NonNegativeReal] | None = Field(
        default=None, description="frequencies (Hz) of the PSD PDFs (default: the PSD peak)"
    )
    quantiles: Annotated[list[Probability], AfterValidator(_unique)] = Field(
        default_factory=lambda: [0.05, 0.95], description="levels of the quantile bands"
    )
    samples: _count(ge=MIN_SAMPLES) = Field(
        default=100_000, description="surrogate draws for PDFs and quantiles"
    )
    seed: NonNegativeInt = 0
    units: dict[Name, str] = Field(default_factory=dict, description="output -> unit, for figures")
    time_unit: str = Field(default="", description="unit of time, for figures")

    def settings(self) -> AnalysisSettings:
        """The :class:`pcmb.analysis.statistics.AnalysisSettings` this section describes."""
        return AnalysisSettings(**self.model_dump())


class StudyConfig(_Spec):
    """A validated study configuration (SPEC §4).

    Built by :func:`load_config` (which also runs the semantic checks and keeps the source
    text); ``StudyConfig.model_validate(data)`` alone checks the schema only.
    """

    name: Annotated[str, Field(min_length=1)]
    model: ModelSpec
    time: TimeSpec
    inputs: Annotated[dict[Name, InputSpec], Field(min_length=1)] = Field(
        description="ordered: the order is the germ order"
    )
    method: MethodSpec
    execution: ExecutionSpec = Field(default_factory=ExecutionSpec)
    analysis: AnalysisSpec | None = Field(
        default=None, description="quantile bands, PDFs and spectra to store"
    )
    output: Annotated[str, AfterValidator(_h5_path)] | None = Field(
        default=None, description="result file, relative to the current directory"
    )

    _source_text: str | None = PrivateAttr(default=None)
    _path: Path | None = PrivateAttr(default=None)
    _base_dir: Path | None = PrivateAttr(default=None)

    @property
    def source_text(self) -> str | None:
        """The YAML text the config was loaded from (``None`` if built from data)."""
        return self._source_text

    @property
    def path(self) -> Path | None:
        """The config file, if any."""
        return self._path

    @property
    def base_dir(self) -> Path:
        """Folder that relative model paths resolve against (the config file's folder)."""
        return self._base_dir if self._base_dir is not None else Path.cwd()

    @property
    def sha256(self) -> str:
        """SHA-256 of the source text (of the canonical JSON dump when built from data)."""
        text = self._source_text if self._source_text is not None else self.model_dump_json()
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    @property
    def times(self) -> NDArray[np.float64]:
        """The output grid, (T,)."""
        return np.linspace(self.time.start, self.time.stop, self.time.points)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Input names in germ order."""
        return tuple(self.inputs)

    @property
    def distributions(self) -> list[inputs.Distribution]:
        """The input distributions in germ order."""
        return [spec.distribution for spec in self.inputs.values()]

    @property
    def orders(self) -> tuple[int, ...] | None:
        """Chaos order per input in germ order (``None`` when the method has none)."""
        order = self.method.order
        if order is None:
            return None
        if isinstance(order, int):
            return (order,) * len(self.inputs)
        return tuple(order[name] for name in self.inputs)

    @property
    def analysis_settings(self) -> AnalysisSettings | None:
        """The analysis to run after recovery (``None`` without an ``analysis:`` section)."""
        return None if self.analysis is None else self.analysis.settings()

    @property
    def output_names(self) -> tuple[str, ...] | None:
        """Outputs to keep (``None``: every output of the model)."""
        outputs = self.model.outputs
        return None if outputs is None else tuple(outputs)

    def model_factory(self) -> Callable[[], Model]:
        """A picklable callable that builds the model (once per worker)."""
        spec = self.model
        base_dir = self.base_dir
        if isinstance(spec, PythonModelSpec):
            outputs = None if spec.outputs is None else tuple(spec.outputs)
            return PythonModelFactory(spec.entry, base_dir, dict(spec.params), outputs)
        if isinstance(spec, CommandModelSpec):
            return CommandModelFactory(
                command=tuple(spec.command),
                params=dict(spec.params),
                outputs=tuple(spec.outputs),
                output_file=spec.output.file,
                output_format=spec.output.format,
                templates=tuple(spec.templates),
                files=tuple(spec.files),
                base_dir=base_dir,
                timeout=spec.timeout,
                run_dir=None if spec.run_dir is None else Path(spec.run_dir).resolve(),
                keep=spec.keep,
                time_column=spec.output.time_column,
            )
        # Imported here: mujoco is heavy and only needed for this kind.
        from pcmb.adapters.mujoco.model import MujocoModelFactory

        return MujocoModelFactory(
            xml=(base_dir / spec.xml).resolve(),
            params=dict(spec.params),
            bind={
                name: [entry.model_dump(exclude_none=True) for entry in entries]
                for name, entries in spec.bind.items()
            },
            init=spec.init.model_dump(),
            outputs={name: out.model_dump(exclude_none=True) for name, out in spec.outputs.items()},
        )


def config_json_schema() -> dict[str, Any]:
    """The JSON Schema of a config file, for editors (``pcmb schema``).

    Returns
    -------
    dict
        A JSON Schema (draft 2020-12) document.
    """
    schema = StudyConfig.model_json_schema(mode="validation")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "pcmb study configuration",
        **{k: v for k, v in schema.items() if k != "title"},
    }


# =========================================================================== error messages

_EXPECTED = {
    "int_type": "expected an integer",
    "int_parsing": "expected an integer",
    "int_from_float": "expected an integer",
    "float_type": "expected a number",
    "float_parsing": "expected a number",
    "finite_number": "expected a finite number",
    "string_type": "expected a string",
    "bool_type": "expected true or false",
    "dict_type": "expected a mapping",
    "model_type": "expected a mapping",
    "model_attributes_type": "expected a mapping",
    "list_type": "expected a list",
}
_BOUNDS = {
    "greater_than_equal": (">=", "ge"),
    "greater_than": (">", "gt"),
    "less_than_equal": ("<=", "le"),
    "less_than": ("<", "lt"),
}


def _show(value: Any) -> str:
    """How a found value is named in a message."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list | tuple):
        return "a list"
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"the text {text}" if isinstance(value, str) else text


def _is_union_tag(node: Any, element: Any) -> bool:
    """Whether a validation-error location element names a union member, not a key."""
    if not isinstance(element, str):
        return False
    if isinstance(node, Mapping):
        for key, tags in _UNION_TAGS.items():
            if element in tags and node.get(key) == element:
                return True
        if element in node:
            return False
    # Member tags of the key-tagged unions contain a colon; "[key]" marks a bad dict key.
    return ":" in element or element == "[key]"


def _key_path(loc: Sequence[Any], data: Any) -> KeyPath:
    """The config key path of a pydantic error location (union member tags removed)."""
    path: list[str | int] = []
    node = data
    for element in loc:
        if _is_union_tag(node, element):
            continue
        path.append(element)
        in_mapping = isinstance(node, Mapping) and element in node
        in_list = isinstance(node, list) and isinstance(element, int) and 0 <= element < len(node)
        node = node[element] if in_mapping or in_list else None
    return tuple(path)


def _unwrap(annotation: Any) -> Any:
    while typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _tagged_member(union: Any, element: Any) -> Any:
    """The member of a union that the location element ``element`` tags, if any."""
    for member in typing.get_args(union):
        if any(
            isinstance(m, Tag) and m.tag == element for m in getattr(member, "__metadata__", ())
        ):
            return member
        model = _unwrap(member)
        if isinstance(model, type) and issubclass(model, BaseModel):
            for key in _UNION_TAGS:
                field = model.model_fields.get(key)
                if field is not None and element in typing.get_args(field.annotation):
                    return model
    return None


def _single_member(union: Any) -> Any:
    members = [a for a in typing.get_args(union) if a is not type(None)]
    return members[0] if len(members) == 1 else None


def _descend(annotation: Any, element: Any) -> Any:
    """The annotation found one location element below ``annotation`` (None if unknown)."""
    annotation = _unwrap(annotation)
    if _is_union(annotation):
        member = _tagged_member(annotation, element)
        if member is not None:
            return member
        single = _single_member(annotation)
        return None if single is None else _descend(single, element)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        field = annotation.model_fields.get(element)
        return None if field is None else field.annotation
    origin = typing.get_origin(annotation)
    if origin is dict:
        return typing.get_args(annotation)[1]
    if origin is list:
        return typing.get_args(annotation)[0]
    return None


def _allowed_keys(loc: Sequence[Any]) -> list[str]:
    """Keys of the config section at a location, found by walking the schema's annotations."""
    annotation: Any = StudyConfig
    for element in loc:
        annotation = _descend(annotation, element)
        if annotation is None:
            return []
    annotation = _unwrap(annotation)
    if _is_union(annotation):
        annotation = _unwrap(_single_member(annotation))
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return list(annotation.model_fields)
    return []


def _message(error: Mapping[str, Any]) -> tuple[str, str | None]:
    """Message of one pydantic error, and the key to append to its path (if any)."""
    kind, ctx, found = error["type"], error.get("ctx", {}), _show(error["input"])
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        key = str(ctx["discriminator"]).strip("'")
        expected = ", ".join(_UNION_TAGS.get(key, ()))
        if kind == "union_tag_not_found":
            return f"required key is missing (one of {expected})", key
        return f"expected one of {expected}, found {_show(ctx['tag'])}", key
    if kind == "missing":
        # pydantic's own 'missing' has no context; the validators' ones explain the need.
        return (error["msg"] if ctx else "required key is missing"), None
    if kind == "extra_forbidden":
        key = str(error["loc"][-1])
        allowed = _allowed_keys(error["loc"][:-1])
        close = difflib.get_close_matches(key, allowed, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        listing = f" (allowed: {', '.join(allowed)})" if allowed else ""
        return f"unknown key{listing}{hint}", None
    if kind == "value_error":
        return str(ctx.get("error", error["msg"])), None
    if kind == "literal_error":
        return f"expected {ctx['expected']}, found {found}", None
    if kind in _BOUNDS:
        symbol, name = _BOUNDS[kind]
        return f"expected a value {symbol} {ctx[name]}, found {found}", None
    if kind == "too_short":
        return f"expected at least {ctx['min_length']} entry, found {ctx['actual_length']}", None
    if kind in _EXPECTED:
        return f"{_EXPECTED[kind]}, found {found}", None
    text = str(error["msg"])
    return f"{text[:1].lower()}{text[1:]}, found {found}", None


def _schema_problems(
    exc: ValidationError, data: Any, lines: Mapping[KeyPath, int]
) -> list[ConfigProblem]:
    problems = []
    for error in exc.errors():
        if error["input"] is _INVALID:
            continue  # already reported while reading the YAML
        message, extra_key = _message(error)
        path = _key_path(error["loc"], data)
        if extra_key is not None:
            path = (*path, extra_key)
        problems.append(ConfigProblem(_format_path(path), message, _line_of(path, lines)))
    return problems


# =========================================================================== semantic checks


def _cross_check(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Checks across sections, as (key path, message)."""
    method, names = config.method, config.input_names
    if isinstance(method.order, dict):
        unknown = [key for key in method.order if key not in config.inputs]
        for key in unknown:
            yield f"method.order.{key}", f"names no input (inputs: {', '.join(names)})"
        missing = [name for name in names if name not in method.order]
        if missing:
            yield "method.order", f"no order given for input(s) {', '.join(missing)}"
        if unknown or missing:
            return
    if method.kind == "collocation" and config.orders is not None:
        runs = math.prod(p + 1 for p in config.orders)
        key, what = "method.order", "the tensor grid has"
    elif method.kind in SAMPLING_KINDS and method.samples is not None:
        runs, key, what = method.samples, "method.samples", "the study asks for"
    else:
        return
    if runs > MAX_RUNS:
        yield key, f"{what} {runs:.3g} nodes, more than the limit of {MAX_RUNS:.0e} runs"
    elif runs * config.time.points > MAX_VALUES:
        yield (
            key,
            (
                f"{what} {runs} nodes x {config.time.points} time points = "
                f"{runs * config.time.points:.3g} values per output, more than {MAX_VALUES:.0e}"
            ),
        )


def _model_check(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Build the model as a worker would, then check it against the config."""
    try:
        model = config.model_factory()()
    except ConfigError as exc:
        for problem in exc.problems:
            yield problem.path, problem.message
        return
    spec = config.model
    label = type(model).__name__
    if isinstance(spec, PythonModelSpec) and spec.outputs and not isinstance(model, FunctionModel):
        for i, name in enumerate(spec.outputs):
            if name not in model.outputs:
                yield (
                    f"model.outputs[{i}]",
                    f"{name!r} is not an output of {label} (outputs: {', '.join(model.outputs)})",
                )
    declared = getattr(model, "parameters", None)
    if declared is None or isinstance(model, FunctionModel | CommandModel):
        known = set(spec.params) | set(getattr(spec, "bind", {}))
        why = (
            f"{label} does not declare its parameters"
            if declared is None
            else f"a {spec.kind} model takes every nominal value from model.params"
        )
        for name in config.inputs:
            if name not in known:
                yield (
                    f"inputs.{name}",
                    f"{name!r} has no nominal value in model.params ({why}): add it there",
                )
    else:
        for name in config.inputs:
            if name not in declared:
                yield (
                    f"inputs.{name}",
                    f"{name!r} is not a parameter of {label} (parameters: {', '.join(declared)})",
                )
    if config.analysis is not None:
        kept = config.output_names or tuple(model.outputs)
        yield from config.analysis.settings().problems(config.times, kept)
    check_times = getattr(model, "check_times", None)
    if callable(check_times):
        try:
            check_times(config.times)
        except ConfigError as exc:
            for problem in exc.problems:
                yield problem.path or "time", problem.message


# =========================================================================== entry points


def _validate(
    data: Any,
    source: str | None,
    base_dir: Path,
    lines: Mapping[KeyPath, int],
    problems: list[ConfigProblem],
) -> StudyConfig:
    def located(found: Iterator[tuple[str, str]]) -> list[ConfigProblem]:
        return [ConfigProblem(p, m, _line_of(_parse_path(p), lines)) for p, m in found]

    try:
        config = StudyConfig.model_validate(data)
    except ValidationError as exc:
        problems = problems + _schema_problems(exc, data, lines)
        config = None
    if config is not None and not problems:
        config._base_dir = base_dir
        problems = located(_cross_check(config)) + located(_model_check(config))
    if problems:
        raise ConfigError(sorted(problems, key=lambda p: (p.line or 0, p.path)), source)
    return config


def validate_config(
    data: Mapping[str, Any], *, base_dir: Path | None = None, source: str | None = None
) -> StudyConfig:
    """Validate config data (as YAML would give it) and check the model.

    Parameters
    ----------
    data:
        The config as a mapping of plain values.
    base_dir:
        Folder relative model paths resolve against (default: the current directory).
    source:
        Name used in messages.

    Returns
    -------
    StudyConfig

    Raises
    ------
    ConfigError
        Every problem found, each with its key path.
    """
    base = Path.cwd() if base_dir is None else Path(base_dir).resolve()
    return _validate(data, source, base, {}, [])


def load_config(path: str | Path, *, text: str | None = None) -> StudyConfig:
    """Load, validate and check a YAML study config before anything runs.

    Parameters
    ----------
    path:
        The config file; its folder is where relative model paths resolve.
    text:
        The YAML text, when it is already in memory (``path`` then only names it).

    Returns
    -------
    StudyConfig
        With ``source_text``, ``path``, ``base_dir`` and ``sha256`` available.

    Raises
    ------
    ConfigError
        Every problem found — unreadable file, YAML syntax, duplicate keys, schema
        violations, semantic problems — each as ``file:line: key.path: message``.
    """
    path = Path(path)
    source = str(path)
    if text is None:
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigError("cannot read the config: no such file", source) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"cannot read the config: {exc}", source) from None
    data, lines, problems = _parse_yaml(text, source)
    config = _validate(data, source, path.resolve().parent, lines, problems)
    config._source_text = text
    config._path = path
    return config
