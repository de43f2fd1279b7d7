"""The study config's schema (pydantic v2) and its entry points.

:func:`load_config` reads a YAML file in three steps and collects every problem it finds
into one :class:`~pcmb.errors.ConfigError` (``file:line: key.path: message``): the YAML
(:mod:`.loader`), this schema (:mod:`.messages` locates its errors), then the checks that
need the model (:mod:`.checks`). The ``model:`` sections come from the adapter registry.
"""

from __future__ import annotations

import hashlib
import typing
import warnings
from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    create_model,
    field_validator,
    model_validator,
)

from pcmb.adapters.registry import ADAPTERS
from pcmb.analysis.derived import FIGURES, DerivedOutput, parse_derived
from pcmb.analysis.diagnostics import TOLERANCE
from pcmb.analysis.statistics import MIN_SAMPLES, AnalysisSettings, window_problem
from pcmb.chaos import inputs, process
from pcmb.config.checks import cross_check, model_check
from pcmb.config.loader import parse_yaml
from pcmb.config.messages import KeyPath, located, schema_problems
from pcmb.config.processes import ProcessSpec
from pcmb.config.types import (
    MAX_RUNS,
    MAX_VALUES,
    ModelSection,
    Name,
    NonNegativeInt,
    NonNegativeReal,
    Points,
    PositiveInt,
    PositiveReal,
    Probability,
    Real,
    Section,
    Stop,
    count,
    tagged_by_key,
    unique,
)
from pcmb.designs import MethodSpec
from pcmb.errors import ConfigError, ConfigProblem
from pcmb.run.backends import BACKENDS
from pcmb.run.memory import DEFAULT_MEMORY, parse_memory
from pcmb.sweep.plan import sweep_problems, swept_methods

if TYPE_CHECKING:
    from pcmb.adapters.protocol import ModelFactory

__all__ = [
    "MAX_RUNS",
    "MAX_VALUES",
    "AnalysisSpec",
    "ExecutionSpec",
    "MethodSpec",
    "ModelSpec",
    "StudyConfig",
    "SweepSpec",
    "TimeGridSpec",
    "TimeSpec",
    "TimeValuesSpec",
    "config_json_schema",
    "load_config",
    "validate_config",
]


def _h5_path(value: str) -> str:
    if not value.endswith(".h5"):
        raise ValueError(f"expected a file name ending in .h5, found {value!r}")
    return value


# --------------------------------------------------------------------------- inputs


class _InputSpec(Section, ABC):
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
    low: Real = Field(description="lower end of the support")
    high: Real = Field(description="upper end of the support")

    def _build(self) -> inputs.Distribution:
        return inputs.Uniform(self.low, self.high)


class LogUniformSpec(_InputSpec):
    """``{dist: loguniform, low, high}``: uniform in the logarithm."""

    dist: Literal["loguniform"]
    low: Real = Field(description="lower end of the support (> 0)")
    high: Real = Field(description="upper end of the support")

    def _build(self) -> inputs.Distribution:
        return inputs.LogUniform(self.low, self.high)


class BetaSpec(_InputSpec):
    """``{dist: beta, alpha, beta, low, high}`` in scipy's shape convention."""

    dist: Literal["beta"]
    alpha: Real = Field(description="first shape parameter (scipy's a)")
    beta: Real = Field(description="second shape parameter (scipy's b)")
    low: Real = Field(description="lower end of the support")
    high: Real = Field(description="upper end of the support")

    def _build(self) -> inputs.Distribution:
        return inputs.Beta(self.alpha, self.beta, self.low, self.high)


class NormalSpec(_InputSpec):
    """``{dist: normal, mean, std}``."""

    dist: Literal["normal"]
    mean: Real = Field(description="mean")
    std: Real = Field(description="standard deviation")

    def _build(self) -> inputs.Distribution:
        return inputs.Normal(self.mean, self.std)


class GammaSpec(_InputSpec):
    """``{dist: gamma, shape, scale, loc}``."""

    dist: Literal["gamma"]
    shape: Real = Field(description="shape parameter")
    scale: Real = Field(description="scale")
    loc: Real = Field(default=0.0, description="shift of the support")

    def _build(self) -> inputs.Distribution:
        return inputs.Gamma(self.shape, self.scale, self.loc)


class ScipySpec(_InputSpec):
    """``{dist: scipy, name: lognorm, params: {s: 0.25, scale: 2.0}, germ: normal}``."""

    dist: Literal["scipy"]
    name: str = Field(description="a scipy.stats continuous distribution")
    params: dict[str, Real] = Field(
        default_factory=dict, description="its shape, loc and scale arguments"
    )
    germ: Literal["uniform", "normal"] = Field(
        default="normal", description="germ family of the chaos basis"
    )

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


DistributionSpec = Annotated[
    UniformSpec | LogUniformSpec | BetaSpec | NormalSpec | GammaSpec | ScipySpec,
    Field(discriminator="dist"),
]
#: An input: a distribution (``dist: ...``) or a random process (``process: kl``).
InputSpec = tagged_by_key(
    DistributionSpec,
    ProcessSpec,
    error="expected a distribution (a dist key) or a random process (a process key)",
)


# --------------------------------------------------------------------------- models

# One member per registered adapter kind, tagged by model.kind.
_MODEL_SECTIONS = tuple(entry.spec_class() for entry in ADAPTERS.values())
ModelSpec = Annotated[
    typing.Union[_MODEL_SECTIONS],  # noqa: UP007 (a runtime tuple of members)
    Field(discriminator="kind"),
]


# --------------------------------------------------------------------------- other sections


class TimeGridSpec(Section):
    """A grid of ``points`` output times from ``start`` to ``stop``: evenly spaced
    (``numpy.linspace``) or evenly spaced in the logarithm (``spacing: log``,
    ``numpy.geomspace``)."""

    start: Real = Field(default=0.0, description="first output time (> 0 for spacing: log)")
    stop: Stop = Field(description="last output time (> start)")
    points: Points = Field(description="number of output times")
    spacing: Literal["linear", "log"] = Field(
        default="linear", description="even steps (linear) or even ratios (log)"
    )

    @field_validator("spacing")
    @classmethod
    def _positive_for_log(cls, spacing: str, info: ValidationInfo) -> str:
        start = info.data.get("start")
        if spacing == "log" and start is not None and not start > 0:
            raise ValueError(f"spacing: log needs start > 0, found start = {start!r}")
        return spacing

    def grid(self) -> NDArray[np.float64]:
        """The output times, (points,)."""
        spaced = np.geomspace if self.spacing == "log" else np.linspace
        return spaced(self.start, self.stop, self.points)

    def describe(self) -> str:
        spacing = ", log-spaced" if self.spacing == "log" else ""
        return f"{self.start} .. {self.stop}, {self.points} points{spacing}"


class TimeValuesSpec(Section):
    """The output times listed one by one (measured data's own times), strictly
    increasing."""

    values: Annotated[list[Real], Field(min_length=2, max_length=MAX_RUNS)] = Field(
        description="the output times, strictly increasing"
    )

    @field_validator("values")
    @classmethod
    def _increasing(cls, values: list[float]) -> list[float]:
        steps = np.diff(values)
        if np.any(steps <= 0):
            at = int(np.argmax(steps <= 0)) + 1
            raise ValueError(
                f"expected strictly increasing times, found {values[at]!r} after "
                f"{values[at - 1]!r} (entry {at})"
            )
        return values

    @property
    def points(self) -> int:
        return len(self.values)

    def grid(self) -> NDArray[np.float64]:
        """The output times, (points,)."""
        return np.asarray(self.values, dtype=float)

    def describe(self) -> str:
        return f"{self.values[0]} .. {self.values[-1]}, {self.points} given times"


#: The output times: a grid (``stop`` and ``points``) or a list (``values``).
TimeSpec = tagged_by_key(
    TimeGridSpec,
    TimeValuesSpec,
    error="expected a grid (stop, points and optionally start, spacing) or a list (values)",
)


def _memory(value: int | str) -> int | str:
    parse_memory(value)
    return value


class ExecutionSpec(Section):
    """Where and how the nodes run."""

    jobs: PositiveInt | None = Field(default=None, description="default: all cores")
    backend: Literal[tuple(BACKENDS)] = Field(
        default="loky", description="where workers run (a registered backend)"
    )
    address: str | None = Field(
        default=None,
        description="address of a running dask scheduler, e.g. tcp://HOST:8786 (backend dask "
        "only; docs/clusters.md)",
    )
    on_failure: Literal["abort", "retry", "regress"] = Field(
        default="abort",
        description="abort; retry failed nodes `retries` times; regress: refit on survivors",
    )
    retries: NonNegativeInt = Field(
        default=1, description="extra attempts per failed node (on_failure: retry)"
    )
    chunk_size: PositiveInt | None = Field(
        default=None,
        description="nodes per model call (default: the model's choice, else ~N/16, 1 to 256)",
    )
    nominal_run: bool = Field(
        default=True, description="make the deterministic run at the nominal parameters"
    )
    timeout: PositiveReal | None = Field(
        default=None,
        description="seconds a node may take before its worker is killed (backend loky)",
    )
    memory: Annotated[int | str, BeforeValidator(_memory)] = Field(
        default=DEFAULT_MEMORY,
        description="memory pcmb's process may use: a size (2GB, 512MiB, bytes) or a share of "
        "the memory available (80%); a sampling study over it streams its runs to the file",
    )

    @field_validator("timeout")
    @classmethod
    def _killable(cls, timeout: float | None, info: ValidationInfo) -> float | None:
        backend = info.data.get("backend")
        if timeout is not None and backend in BACKENDS and not BACKENDS[backend].kills:
            raise ValueError(
                f"a timeout needs workers pcmb can kill (backend: loky), found backend {backend!r}"
            )
        return timeout

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


class DiagnosticsSpec(Section):
    """When a chaos expansion is called unreliable (see ``docs/diagnostics.md``)."""

    tolerance: Annotated[float, Field(gt=0, lt=1)] = Field(
        default=TOLERANCE,
        description="accepted error, relative to the output's largest standard deviation",
    )
    outputs: Annotated[list[Name], AfterValidator(unique)] | None = Field(
        default=None,
        description="outputs the verdict covers (default: all; leave out a residual that is "
        "zero to round-off)",
    )


class AnalysisSpec(Section):
    """What to compute beyond mean, std and Sobol' indices (see :mod:`pcmb.analysis.statistics`)."""

    psd: Annotated[list[Name], AfterValidator(unique)] | None = Field(
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
    quantiles: Annotated[list[Probability], AfterValidator(unique)] = Field(
        default_factory=lambda: [0.05, 0.95], description="levels of the quantile bands"
    )
    samples: count(ge=MIN_SAMPLES) = Field(
        default=100_000, description="surrogate draws for PDFs and quantiles"
    )
    seed: NonNegativeInt = Field(default=0, description="seed of the surrogate draws")
    units: dict[Name, str] = Field(default_factory=dict, description="output -> unit, for figures")
    time_unit: str = Field(default="", description="unit of time, for figures")

    def settings(self) -> AnalysisSettings:
        """The :class:`pcmb.analysis.statistics.AnalysisSettings` this section describes."""
        return AnalysisSettings(**self.model_dump())


class SweepSpec(Section):
    """``pcmb sweep``: the methods run at rising cost and the reference they are measured
    against (see ``docs/sweep.md``)."""

    methods: Annotated[list[dict[Name, Any]], Field(min_length=1)] = Field(
        description="method blocks, each with at most one key given as a list of values"
    )
    reference: dict[Name, Any] | None = Field(
        default=None,
        description="method block of the reference run (default: give --reference REF.h5)",
    )
    outputs: Annotated[list[Name], AfterValidator(unique)] | None = Field(
        default=None,
        description="outputs whose errors are measured (default: diagnostics.outputs, else all)",
    )
    replicates: PositiveInt = Field(
        default=1, description="seeds per setting of a seeded method (sampling, regression)"
    )


#: One ``derived:`` entry: one figure kind (:data:`pcmb.analysis.derived.FIGURES`) naming a
#: time output, with that figure's options; built from the registry.
DerivedSpec = create_model(
    "DerivedSpec",
    __base__=Section,
    __doc__="A figure of merit: one figure key naming a time output, and its options.",
    **{
        kind: (Name | None, Field(default=None, description=f"{figure.summary}: the output"))
        for kind, figure in FIGURES.items()
    },
    **{
        option: (Real | None, Field(default=None, description=text))
        for figure in FIGURES.values()
        for option, text in figure.descriptions.items()
    },
)


class StudyConfig(Section):
    """A validated study configuration.

    Built by :func:`load_config` (which also runs the semantic checks and keeps the source
    text); ``StudyConfig.model_validate(data)`` alone checks the schema only.
    """

    name: Annotated[str, Field(min_length=1)] = Field(
        description="study name, stored in the result file"
    )
    model: ModelSpec = Field(description="the simulator: one section per model.kind")
    time: TimeSpec = Field(description="the output times: a grid (stop, points) or a list (values)")
    inputs: Annotated[dict[Name, InputSpec], Field(min_length=1)] = Field(
        description="ordered: the order is the germ order"
    )
    method: MethodSpec = Field(description="how nodes are made: one section per method.kind")
    execution: ExecutionSpec = Field(default_factory=ExecutionSpec)
    diagnostics: DiagnosticsSpec = Field(default_factory=DiagnosticsSpec)
    analysis: AnalysisSpec | None = Field(
        default=None, description="quantile bands, PDFs and spectra to store"
    )
    output: Annotated[str, AfterValidator(_h5_path)] | None = Field(
        default=None, description="result file, relative to the current directory"
    )
    derived: dict[Name, DerivedSpec] = Field(
        default_factory=dict,
        description="figures of merit of time outputs, each stored as a scalar output",
    )
    sweep: SweepSpec | None = Field(
        default=None, description="pcmb sweep: methods at rising cost against a reference"
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
        return self.time.grid()

    @property
    def study_inputs(self) -> dict[str, inputs.Distribution | process.RandomProcess]:
        """What the model receives by name: distributions and random processes (expanded)."""
        return {
            name: spec.expansion if isinstance(spec, ProcessSpec) else spec.distribution
            for name, spec in self.inputs.items()
        }

    @property
    def input_names(self) -> tuple[str, ...]:
        """Input names in germ order (a process's germs ``name[k]`` in its place)."""
        return tuple(process.germ_inputs(self.study_inputs))

    @property
    def distributions(self) -> list[inputs.Distribution]:
        """The input distributions in germ order."""
        return list(process.germ_inputs(self.study_inputs).values())

    @property
    def orders(self) -> tuple[int, ...] | Literal["auto"] | None:
        """Chaos order per input in germ order (``None`` when the method has none, ``"auto"``
        for order refinement)."""
        order = getattr(self.method, "order", None)
        if order is None or order == "auto":
            return order
        names = self.input_names
        if isinstance(order, int):
            return (order,) * len(names)
        order = process.per_germ(order, self.study_inputs)
        return tuple(order[name] for name in names)

    @property
    def analysis_settings(self) -> AnalysisSettings | None:
        """The analysis to run after recovery (``None`` without an ``analysis:`` section)."""
        return None if self.analysis is None else self.analysis.settings()

    @property
    def derived_outputs(self) -> dict[str, DerivedOutput]:
        """The ``derived:`` figures (raises ConfigError at their keys; checked on loading)."""
        return parse_derived(
            {name: spec.model_dump(exclude_none=True) for name, spec in self.derived.items()}
        )

    @property
    def output_names(self) -> tuple[str, ...] | None:
        """Outputs to keep (``None``: every output of the model)."""
        return self.model.output_names

    def model_factory(self) -> ModelFactory:
        """A picklable factory that builds the model (once per worker)."""
        section: ModelSection = self.model
        return section.factory(self.base_dir)


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


# --------------------------------------------------------------------------- entry points


def _validate(
    data: Any,
    source: str | None,
    base_dir: Path,
    lines: Mapping[KeyPath, int],
    problems: list[ConfigProblem],
    check_sweep: bool = True,
) -> StudyConfig:
    try:
        config = StudyConfig.model_validate(data)
    except ValidationError as exc:
        problems = problems + schema_problems(exc, StudyConfig, lines)
        config = None
    if config is not None and not problems:
        config._base_dir = base_dir
        problems = located(cross_check(config), lines)
        if check_sweep:
            problems += located(sweep_problems(config), lines)
        swept = swept_methods(config) if check_sweep else ()
        problems += located(model_check(config, swept), lines)
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
        Name used in messages (default ``<config>``).

    Returns
    -------
    StudyConfig

    Raises
    ------
    ConfigError
        Every problem found, each with its key path.
    """
    base = Path.cwd() if base_dir is None else Path(base_dir).resolve()
    return _validate(data, source or "<config>", base, {}, [])


def load_config(
    path: str | Path, *, text: str | None = None, check_sweep: bool = True
) -> StudyConfig:
    """Load, validate and check a YAML study config before anything runs.

    Parameters
    ----------
    path:
        The config file; its folder is where relative model paths resolve.
    text:
        The YAML text, when it is already in memory (``path`` then only names it).
    check_sweep:
        Also check the ``sweep:`` section's settings: each one's design (the quarter car's
        sweep builds 35), and the intrusive ones against the model in a worker (Galerkin
        needs its polynomial form). A plain run, which ignores that section, skips these;
        the section's keys (the schema) are checked either way.

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
    data, lines, problems = parse_yaml(text, source)
    config = _validate(data, source, path.resolve().parent, lines, problems, check_sweep)
    config._source_text = text
    config._path = path
    return config
