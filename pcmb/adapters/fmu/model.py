"""Functional Mock-up Units as models (``model.kind: fmu``); the only pcmb module importing fmpy.

The FMU's ``modelDescription.xml`` is read and checked at construction (variable names,
causalities, units, aliases), its archive extracted (once per user, into a private cache
checked before every use: :mod:`pcmb.adapters.fmu.cache`) and one instance made: a worker
builds the model once and runs every node of its chunks on that instance, resetting it
between nodes.
Co-simulation FMUs are stepped from one output time to the next (``fmi*DoStep`` exactly onto
the grid); model-exchange FMUs are integrated by FMPy's CVode. An FMI error, discard or fatal
status, or a solver failure, is a failed run of that node. See ``docs/models.md``.
"""

from __future__ import annotations

import contextlib
import difflib
import math
import weakref
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from fmpy import platform, supported_platforms
from fmpy.model_description import ModelDescription, ScalarVariable, read_model_description
from fmpy.simulation import instantiate_fmu, settable_in_instantiated, simulate_fmu
from numpy.typing import ArrayLike, NDArray

from pcmb.adapters.fmu.cache import CacheError, extracted
from pcmb.adapters.protocol import PointwiseModel, describe_exception
from pcmb.errors import ConfigError, ConfigProblem, ModelDefinitionError, ModelError

if TYPE_CHECKING:
    from pcmb.adapters.fmu.factory import Interface  # the factory builds this model

__all__ = ["FmuModel"]

_EMPTY: Mapping[str, Any] = MappingProxyType({})
# FMI type -> (what a value must be, suffix of FMPy's get*/set* for it), for FMI 2.0 and 3.0.
_FMI2_TYPES = {
    "Real": ("real", "Real"),
    "Integer": ("integer", "Integer"),
    "Enumeration": ("integer", "Integer"),
    "Boolean": ("boolean", "Boolean"),
}
_FMI3_TYPES = {
    "Float64": ("real", "Float64"),
    "Float32": ("real", "Float32"),
    **{f"{s}Int{n}": ("integer", f"{s}Int{n}") for s in ("", "U") for n in (8, 16, 32, 64)},
    "Enumeration": ("integer", "Int64"),
    "Boolean": ("boolean", "Boolean"),
}
_INTERFACE_TYPES = {"co-simulation": "CoSimulation", "model-exchange": "ModelExchange"}
# Log messages of the FMU kept for the error message of a failed node.
_LOG_LINES = 5
_STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")
_DEFAULT_RTOL = 1e-6


def _problem(path: str, message: str) -> ConfigProblem:
    return ConfigProblem(path=path, message=message)


def _listing(names: Sequence[str], limit: int = 20) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f", ... ({len(names)} in all)" if len(names) > limit else "") or "none"


def _is_number(value: object) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


class _Log:
    """The FMU's last log messages (FMI 2.0 and 3.0 logger callbacks share the last three
    arguments: status, category, message)."""

    def __init__(self) -> None:
        self.lines: deque[str] = deque(maxlen=_LOG_LINES)

    def __call__(self, *args: Any) -> None:
        status, message = args[-3], args[-1]
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        label = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
        self.lines.append(f"[{label}] {text.strip()}")

    def take(self) -> str:
        """The messages since the last call, on one line each (empty if none)."""
        text = "; ".join(self.lines)
        self.lines.clear()
        return text


class _SolverGuard:
    """The FMU instance as FMPy's CVode sees it.

    FMPy calls the FMU's derivatives and event indicators from inside CVode's C callbacks,
    where an exception cannot pass: an FMI error there would leave CVode with garbage and
    crash the process. Here the first such error is kept instead, the callbacks get NaN
    (which makes CVode stop with an error) and the FMU is not called again during the run;
    :attr:`error` is then the node's reason.
    """

    #: Methods CVode's callbacks reach, and whether they fill an array (pointer, size).
    _GUARDED: ClassVar[dict[str, bool]] = {
        "getDerivatives": True,
        "getContinuousStateDerivatives": True,
        "getEventIndicators": True,
        "getContinuousStates": True,
        "setContinuousStates": False,
        "setTime": False,
    }

    def __init__(self, instance: Any) -> None:
        self._instance = instance
        self.error: Exception | None = None

    def __getattr__(self, name: str) -> Any:
        method = getattr(self._instance, name)
        if name not in self._GUARDED:
            return method
        fills = self._GUARDED[name]

        def guarded(*args: Any) -> Any:
            if self.error is None:
                try:
                    return method(*args)
                except Exception as exc:
                    self.error = exc
            if fills:  # (pointer to the solver's array, its size)
                np.ctypeslib.as_array(args[0], (args[1],))[:] = np.nan
            return None

        return guarded


class FmuModel(PointwiseModel):
    """An FMU (FMI 2.0 or 3.0, co-simulation or model exchange) as a pcmb model.

    Parameters
    ----------
    fmu:
        The ``.fmu`` file (or a folder holding an extracted FMU).
    params:
        FMU variable name -> value (its start value for this study). Also the nominal value of
        a ``bind`` input, by the input's name.
    bind:
        Input name -> the FMU variables it sets (e.g. ``{"k0": ("k[0]",)}``), for variables
        whose names are not plain names or for one input setting several variables. An input
        not bound sets the variable of its own name.
    outputs:
        FMU variable names to record (default: every variable of causality output).
    units:
        FMU variable name -> the unit the study means; each must be the FMU's declared unit.
    interface:
        ``"co-simulation"`` or ``"model-exchange"`` (default: co-simulation when the FMU
        offers it).
    rtol:
        Relative tolerance: of CVode for model exchange (absolute tolerance: ``rtol`` times
        each state's nominal value), passed to the FMU as its tolerance for co-simulation.
        Default: the FMU's default experiment's, else 1e-6 (model exchange) or none.

    Attributes
    ----------
    outputs:
        The recorded variable names.
    parameters:
        Every input name the model takes -> nominal value: the bound inputs, and every
        settable real variable whose name is a plain name (its start value, or ``params``').

    Raises
    ------
    ConfigError
        At its ``model.*`` key: an unreadable FMU, no binary for this platform, an
        interface it lacks, a name that is no variable, a variable that cannot be set
        (causality, variability) or read, a value of the wrong type, a unit that differs.
    """

    def __init__(
        self,
        *,
        fmu: Path,
        params: Mapping[str, float | int | bool] = _EMPTY,
        bind: Mapping[str, Sequence[str]] = _EMPTY,
        outputs: Sequence[str] | None = None,
        units: Mapping[str, str] = _EMPTY,
        interface: Interface | None = None,
        rtol: float | None = None,
    ) -> None:
        self._path = Path(fmu)
        self._md = self._read(self._path)
        self._fmi3 = self._md.fmiVersion.startswith("3.")
        self._types = _FMI3_TYPES if self._fmi3 else _FMI2_TYPES
        self._variables = {v.name: v for v in self._md.modelVariables}
        self.interface = self._interface(interface)
        experiment = self._md.defaultExperiment
        default_rtol = None if experiment is None else experiment.tolerance
        if rtol is None and default_rtol is not None:
            rtol = float(default_rtol)
        if rtol is None and self.interface == "model-exchange":
            rtol = _DEFAULT_RTOL
        self.rtol = rtol

        problems: list[ConfigProblem] = []
        self._fixed = self._check_params(params, bind, problems)
        self._bind = self._check_bind(bind, problems)
        self.outputs: tuple[str, ...] = self._check_outputs(outputs, problems)
        self._check_units(units, problems)
        if problems:
            raise ConfigError(problems)
        self._params = tuple(params)
        problems = self._aliases(self._params, ())
        if problems:
            raise ConfigError(problems)
        self._inputs_checked: set[frozenset[str]] = set()

        self.parameters: Mapping[str, float] = MappingProxyType(self._nominal(params))
        self._getters = self._group([self._variables[name] for name in self.outputs], "get")
        # output positions in the order the grouped reads return them
        self._read_order = np.concatenate([positions for _, _, positions in self._getters])
        self._log = _Log()
        self._unzipdir = self._extract(self._path)
        #: FMU instances this model has made: 1, plus one for each that could not go on.
        self.instantiations = 0
        self._abandoned: list[Any] = []
        try:
            instance = self._new_instance()
        except RuntimeError as exc:
            raise ConfigError([_problem("model.fmu", str(exc))]) from exc
        self._own(instance)

    # -- construction: what the config says ------------------------------------------------

    @staticmethod
    def _read(path: Path) -> ModelDescription:
        if not path.exists():
            raise ConfigError([_problem("model.fmu", f"file {path} does not exist")])
        try:
            md = read_model_description(str(path), validate=True)
        except Exception as exc:  # FMPy raises plain Exceptions for every kind of problem
            raise ConfigError(
                [_problem("model.fmu", f"cannot read {path} as an FMU: {describe_exception(exc)}")]
            ) from exc
        if not (md.fmiVersion == "2.0" or md.fmiVersion.startswith("3.")):
            raise ConfigError(
                [_problem("model.fmu", f"FMI {md.fmiVersion} is not supported (FMI 2.0 or 3.0)")]
            )
        try:
            platforms = supported_platforms(str(path))
        except Exception as exc:
            raise ConfigError(
                [_problem("model.fmu", f"cannot list the binaries of {path}: {exc}")]
            ) from exc
        if platform not in platforms:
            raise ConfigError(
                [
                    _problem(
                        "model.fmu",
                        f"{path.name} has no binary for this platform ({platform}); it has: "
                        f"{', '.join(platforms) or 'none'}",
                    )
                ]
            )
        return md

    def _interface(self, interface: Interface | None) -> Interface:
        offered: list[Interface] = []
        if self._md.coSimulation is not None:
            offered.append("co-simulation")
        if self._md.modelExchange is not None:
            offered.append("model-exchange")
        if interface is None and offered:
            return offered[0]
        if interface in offered:
            return interface
        raise ConfigError(
            [
                _problem(
                    "model.interface",
                    f"the FMU has no {interface or 'co-simulation or model-exchange'} "
                    f"interface (it has: {', '.join(offered) or 'none pcmb can run'})",
                )
            ]
        )

    def _unknown(self, name: object, path: str) -> ConfigProblem:
        names = list(self._variables)
        close = difflib.get_close_matches(str(name), names, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        return _problem(
            path, f"{name!r} is not a variable of the FMU{hint}; variables are {_listing(names)}"
        )

    def _typed(self, variable: ScalarVariable, path: str) -> ConfigProblem | None:
        """A problem if the variable has no type pcmb reads and writes, or is an array."""
        if variable.type not in self._types:
            return _problem(
                path,
                f"{variable.name!r} is a {variable.type} variable: pcmb reads and sets "
                "real, integer, enumeration and boolean variables",
            )
        if getattr(variable, "dimensions", None):
            return _problem(
                path,
                f"{variable.name!r} is an FMI 3 array variable: pcmb reads and sets "
                "scalar variables only",
            )
        return None

    def _settable(self, name: str, path: str) -> ConfigProblem | None:
        """A problem if ``name`` is not a variable whose value a study may set."""
        variable = self._variables.get(name)
        if variable is None:
            return self._unknown(name, path)
        typed = self._typed(variable, path)
        if typed is not None:
            return typed
        if not settable_in_instantiated(variable):
            return _problem(
                path,
                f"{name!r} cannot be set: its causality is {variable.causality}, variability "
                f"{variable.variability}, initial {variable.initial} (a study sets parameters, "
                "inputs and start values: variables with initial exact or approx)",
            )
        return None

    def _check_params(
        self,
        params: Mapping[str, Any],
        bind: Mapping[str, Sequence[str]],
        problems: list[ConfigProblem],
    ) -> dict[str, float | int | bool]:
        fixed: dict[str, float | int | bool] = {}
        for name, value in params.items():
            path = f"model.params.{name}"
            if name in bind:
                targets = [self._variables.get(t) for t in bind[name]]
                if not _is_number(value) or not math.isfinite(value):
                    problems.append(_problem(path, f"expected a finite number, got {value!r}"))
                elif all(
                    t is not None and self._types.get(t.type, ("",))[0] == "real" for t in targets
                ):
                    fixed.update({target: float(value) for target in bind[name]})
                continue  # bind's own check reports its targets
            problem = self._settable(name, path)
            if problem is not None:
                problems.append(problem)
                continue
            kind = self._types[self._variables[name].type][0]
            checked = self._value(value, kind)
            if checked is None:
                problems.append(
                    _problem(path, f"{name!r} is a {kind} variable of the FMU, got {value!r}")
                )
            else:
                fixed[name] = checked
        return fixed

    @staticmethod
    def _value(value: Any, kind: str) -> float | int | bool | None:
        """``value`` as the FMU variable's kind wants it, or ``None`` if it is not one."""
        if kind == "boolean":
            return value if isinstance(value, bool) else None
        if not _is_number(value) or not math.isfinite(value):
            return None
        if kind == "integer":
            return int(value) if float(value).is_integer() else None
        return float(value)

    def _check_bind(
        self, bind: Mapping[str, Sequence[str]], problems: list[ConfigProblem]
    ) -> dict[str, tuple[str, ...]]:
        for name, targets in bind.items():
            if name in self._variables:
                problems.append(
                    _problem(
                        f"model.bind.{name}",
                        f"{name!r} is a variable of the FMU: an input of that name sets it, "
                        "so bind it under another name",
                    )
                )
            for i, target in enumerate(targets):
                path = f"model.bind.{name}[{i}]"
                problem = self._settable(target, path)
                if problem is None and self._types[self._variables[target].type][0] != "real":
                    problem = _problem(
                        path,
                        f"{target!r} is a {self._variables[target].type} variable: an uncertain "
                        "input sets real variables",
                    )
                if problem is not None:
                    problems.append(problem)
        return {name: tuple(targets) for name, targets in bind.items()}

    def _value_of(self, variable: ScalarVariable) -> tuple[object, ...]:
        """What identifies a variable's value: its value reference, per FMI 2.0 base type
        (FMI 3.0 references are unique across types). Aliases share it."""
        if self._fmi3:
            return (variable.valueReference,)
        return (self._types[variable.type][1], variable.valueReference)

    def _aliases(self, params: Sequence[str], inputs: Sequence[str]) -> list[ConfigProblem]:
        """Problems where two names of the study (``model.params`` keys, uncertain inputs)
        set one value of the FMU through different (aliased) variables: the last one set
        would silently win. With inputs, only the clashes involving one are reported."""
        setters = {name: f"model.params.{name}" for name in params}
        setters.update({name: f"inputs.{name}" for name in inputs})
        first: dict[tuple[object, ...], tuple[str, str]] = {}
        problems = []
        for name, path in setters.items():
            for target in self._bind.get(name, (name,)):
                variable = self._variables.get(target)
                if variable is None or variable.type not in self._types:
                    continue  # reported by the other checks
                owner, aliased = first.setdefault(self._value_of(variable), (name, target))
                if owner == name or (inputs and name not in inputs and owner not in inputs):
                    continue
                problems.append(
                    _problem(
                        path,
                        f"{name!r} and {owner!r} ({setters[owner]}) set one value of the FMU "
                        f"({target!r} and {aliased!r} share valueReference "
                        f"{variable.valueReference}), so they cannot vary independently; "
                        "keep one of them",
                    )
                )
        return problems

    def check_inputs(self, names: Sequence[str]) -> None:
        """Check that the uncertain inputs ``names`` set independent values of the FMU.

        Raises
        ------
        ConfigError
            At ``inputs.<name>``: two of them, or one and a ``model.params`` entry, set one
            value through aliased variables (variables sharing a value reference).
        """
        problems = self._aliases(self._params, [n for n in names if n in self.parameters])
        if problems:
            raise ConfigError(problems)

    def _check_outputs(
        self, outputs: Sequence[str] | None, problems: list[ConfigProblem]
    ) -> tuple[str, ...]:
        if outputs is None:
            found = tuple(
                v.name
                for v in self._md.modelVariables
                if v.causality == "output" and self._typed(v, "") is None
            )
            if not found:
                problems.append(
                    _problem("model.outputs", "the FMU has no output variable: list variables")
                )
            return found
        for i, name in enumerate(outputs):
            path = f"model.outputs[{i}]"
            variable = self._variables.get(name)
            if variable is None:
                problems.append(self._unknown(name, path))
                continue
            problem = self._typed(variable, path)
            if problem is not None:
                problems.append(problem)
            elif "/" in name:
                problems.append(_problem(path, f"{name!r}: an output name cannot contain '/'"))
        return tuple(outputs)

    def _check_units(self, units: Mapping[str, str], problems: list[ConfigProblem]) -> None:
        for name, unit in units.items():
            path = f"model.units.{name}"
            variable = self._variables.get(name)
            if variable is None:
                problems.append(self._unknown(name, path))
                continue
            declared = variable.unit
            if declared is None and variable.declaredType is not None:
                declared = variable.declaredType.unit
            if declared != unit:
                what = f"in {declared!r}" if declared else "without a unit"
                problems.append(
                    _problem(path, f"the FMU declares {name!r} {what}, not in {unit!r}")
                )

    def _nominal(self, params: Mapping[str, Any]) -> dict[str, float]:
        """Input name -> nominal value, for every input the model takes."""
        nominal: dict[str, float] = {}
        for variable in self._md.modelVariables:
            if (
                variable.name.isidentifier()
                and settable_in_instantiated(variable)
                and self._types.get(variable.type, ("",))[0] == "real"
                and not getattr(variable, "dimensions", None)
            ):
                value = self._fixed.get(variable.name, variable.start)
                nominal[variable.name] = float("nan") if value is None else float(value)
        for name, targets in self._bind.items():
            first = self._variables[targets[0]]
            value = params.get(name, first.start)
            nominal[name] = float("nan") if value is None else float(value)
        return nominal

    def _group(
        self, variables: Sequence[ScalarVariable], verb: str
    ) -> list[tuple[str, list[int], NDArray[np.intp]]]:
        """``(FMPy method, value references, positions)`` per FMI type of ``variables``."""
        groups: dict[str, tuple[list[int], list[int]]] = {}
        for position, variable in enumerate(variables):
            method = verb + self._types[variable.type][1]
            references, positions = groups.setdefault(method, ([], []))
            references.append(variable.valueReference)
            positions.append(position)
        return [(m, refs, np.array(pos, dtype=np.intp)) for m, (refs, pos) in groups.items()]

    @staticmethod
    def _extract(path: Path) -> str:
        """The folder of the extracted FMU: ``path`` itself, or the FMU's folder in this
        user's cache, checked before use (:mod:`pcmb.adapters.fmu.cache`)."""
        if path.is_dir():
            return str(path)
        try:
            return str(extracted(path))
        except CacheError as exc:
            raise ConfigError([_problem("model.fmu", str(exc))]) from exc

    def _new_instance(self) -> Any:
        """A new FMPy instance of the FMU.

        Raises
        ------
        RuntimeError
            FMPy's or the FMU's reason, with the FMU's log.
        """
        try:
            return instantiate_fmu(
                self._unzipdir,
                self._md,
                fmi_type=_INTERFACE_TYPES[self.interface],
                logger=self._log,
            )
        except Exception as exc:
            log = self._log.take()
            raise RuntimeError(
                f"cannot instantiate {self._path.name}: {describe_exception(exc)}"
                + (f"; the FMU logged: {log}" if log else "")
            ) from exc

    def _replace_instance(self, *, fatal: bool) -> None:
        """Swap in a new instance for one that cannot go on.

        After a fatal status FMI allows no further call into the instance, not even to free
        it (freeing one that a Python exception made fatal crashes pythonfmu's FMUs), so it
        is abandoned as it is; any other instance is freed once its successor exists (the
        new one first, so that the FMU's library stays loaded).

        Raises
        ------
        ModelDefinitionError
            No new instance can be made: no node can run any more.
        """
        try:
            instance = self._new_instance()
        except RuntimeError as exc:
            raise ModelDefinitionError(str(exc)) from exc
        if fatal:
            self._free.detach()
            self._abandoned.append(self._instance)  # its callbacks must outlive it
        else:
            self._free()
        self._own(instance)

    def _own(self, instance: Any) -> None:
        self._instance = instance
        self.instantiations += 1
        # freed when the model goes (or at exit)
        self._free = weakref.finalize(self, _free, instance)

    # -- the protocol ------------------------------------------------------------------------

    def check_times(self, times: ArrayLike) -> None:
        """Check the grid: increasing; evenly spaced for model exchange (FMPy's output interval).

        Raises
        ------
        ConfigError
            At ``time``.
        """
        grid = np.asarray(times, dtype=float)
        if grid.ndim != 1 or grid.size < 1 or np.any(np.diff(grid) <= 0):
            raise ConfigError([_problem("time", "the output grid must increase strictly")])
        if self.interface == "model-exchange":
            steps = np.diff(grid)
            if steps.size == 0 or np.ptp(steps) > 1e-9 * steps.mean():
                raise ConfigError(
                    [
                        _problem(
                            "time", "a model-exchange FMU needs an evenly spaced grid of 2+ times"
                        )
                    ]
                )

    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run one node from ``times[0]`` to ``times[-1]`` on the model's instance.

        Parameters
        ----------
        values:
            The node's uncertain inputs (floats), by input name.
        times:
            Output grid, (T,); ``times[0]`` is the FMU's start time.

        Returns
        -------
        dict[str, NDArray]
            Every output -> (T,).

        Raises
        ------
        ModelError
            An FMI call returned error, discard or fatal, the solver failed, or the FMU
            ended the simulation early; the message says which call at which time, with
            the FMU's last log messages.
        """
        key = frozenset(values)
        if key not in self._inputs_checked:  # the same at every node: checked once
            try:
                self.check_inputs(tuple(values))
            except ConfigError as error:
                raise ModelDefinitionError(str(error)) from error
            self._inputs_checked.add(key)
        times = np.asarray(times, dtype=float)
        start = dict(self._fixed)
        for name, value in values.items():
            for target in self._bind.get(name, (name,)):
                start[target] = float(value)
        self._log.take()
        clock = [float(times[0])]
        try:
            if self.interface == "co-simulation":
                record = self._cosimulate(start, times, clock)
            else:
                record = self._integrate(start, times, clock)
        except Exception as exc:
            log = self._log.take()
            self._recover(fatal=getattr(exc, "status", None) == _STATUS.index("fatal"))
            raise ModelError(
                f"the FMU failed at t = {clock[0]:.6g}: {describe_exception(exc)}"
                + (f"; the FMU logged: {log}" if log else "")
            ) from exc
        self._recover(terminated=True)
        return {name: record[j] for j, name in enumerate(self.outputs)}

    def _set(self, start: Mapping[str, float | int | bool]) -> None:
        variables = [self._variables[name] for name in start]
        values = list(start.values())
        for method, references, positions in self._group(variables, "set"):
            getattr(self._instance, method)(references, [values[p] for p in positions])

    def _reader(self) -> Callable[[], list[Any]]:
        """A call that returns every output's current value, grouped by FMI type (the
        order of ``self._read_order``): one FMPy call per type, nothing else per step."""
        calls = [
            (getattr(self._instance, method), references) for method, references, _ in self._getters
        ]
        if len(calls) == 1:
            getter, references = calls[0]
            return lambda: getter(references)
        return lambda: [value for getter, references in calls for value in getter(references)]

    def _cosimulate(
        self,
        start: Mapping[str, float | int | bool],
        times: NDArray[np.float64],
        clock: list[float],
    ) -> NDArray[np.float64]:
        """Step exactly from each output time to the next; (n_outputs, T)."""
        fmu = self._instance
        t0, t1 = float(times[0]), float(times[-1])
        if self._fmi3:
            self._set(start)
            fmu.enterInitializationMode(tolerance=self.rtol, startTime=t0, stopTime=t1)
        else:
            fmu.setupExperiment(tolerance=self.rtol, startTime=t0, stopTime=t1)
            self._set(start)
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        read, grid = self._reader(), times.tolist()
        step = fmu.doStep
        rows = [read()]
        for k in range(1, len(grid)):
            now = clock[0] = grid[k - 1]
            result = step(now, grid[k] - now)
            if self._fmi3 and result[1]:  # terminateSimulation
                raise ModelError(f"the FMU ended the simulation at t = {result[3]:.6g}")
            rows.append(read())
        clock[0] = grid[-1]
        record = np.empty((len(self.outputs), len(grid)))
        record[self._read_order] = np.array(rows, dtype=float).T
        return record

    def _integrate(
        self,
        start: Mapping[str, float | int | bool],
        times: NDArray[np.float64],
        clock: list[float],
    ) -> NDArray[np.float64]:
        """Integrate by FMPy's CVode, sampled at the grid; (n_outputs, T)."""

        def reached(time: float, _recorder: object) -> bool:
            clock[0] = time  # for the message of a failure
            return True

        guard = _SolverGuard(self._instance)
        try:
            result = simulate_fmu(
                self._unzipdir,
                validate=False,
                start_time=float(times[0]),
                stop_time=float(times[-1]),
                solver="CVode",
                relative_tolerance=self.rtol,
                output_interval=(float(times[-1]) - float(times[0])) / (times.size - 1),
                record_events=False,
                fmi_type="ModelExchange",
                start_values=dict(start),
                output=list(self.outputs),
                model_description=self._md,
                fmu_instance=guard,
                step_finished=reached,
            )
        except Exception:
            if guard.error is not None:  # the FMU's error made the solver stop
                raise guard.error from None
            raise
        sampled = np.asarray(result["time"], dtype=float)
        if sampled.size != times.size:
            last = float(sampled[-1]) if sampled.size else float(times[0])
            raise ModelError(f"the FMU ended the simulation at t = {last:.6g}")
        step = float(times[1] - times[0])
        if np.abs(sampled - times).max() > 1e-6 * step:
            raise ModelError("FMPy sampled the model off the output grid")
        return np.array([result[name] for name in self.outputs], dtype=float)

    def _recover(self, *, terminated: bool = False, fatal: bool = False) -> None:
        """Bring the instance back to its state after instantiation for the next node."""
        fmu = self._instance
        if fatal:
            self._replace_instance(fatal=True)
            return
        try:
            if not terminated:
                with contextlib.suppress(Exception):  # a failed instance may refuse it
                    fmu.terminate()
            elif self.interface == "co-simulation":
                fmu.terminate()  # FMPy's model-exchange loop has terminated already
            fmu.reset()
        except Exception:  # an instance that cannot be reset is replaced
            self._replace_instance(fatal=False)


def _free(instance: Any) -> None:
    """Free an FMU instance (FMPy also unloads the library when it is the last one)."""
    with contextlib.suppress(Exception):
        instance.freeInstance()
