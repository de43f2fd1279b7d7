"""MuJoCo scenes as models (``model.kind: mujoco``); the only pcmb module importing mujoco.

Inputs reach a scene as ``{{ name }}`` placeholders (each node compiles its own scene),
``bind`` targets (MjModel fields, ``opt`` fields, initial joint states) or ``init`` values, in
the binding language of :mod:`pcmb.adapters.mujoco.binding`. A batch runs in one
:class:`mujoco.batch.Batch` on MuJoCo's thread pool; a node that diverges is a failed run.
See ``docs/architecture.md`` for how bindings, batching, threads and divergence work.
"""

from __future__ import annotations

import copy
import difflib
import os
import re
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import mujoco
import mujoco.batch
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.adapters.mujoco.binding import (
    FieldBind,
    InitSpec,
    Qpos0Bind,
    QposOutput,
    Qvel0Bind,
    QvelOutput,
    SensorOutput,
    SiteXposOutput,
    XposOutput,
    parse_scene_io,
)
from pcmb.adapters.mujoco.files import mjcf_files
from pcmb.adapters.protocol import ModelFactory
from pcmb.errors import ConfigError, ConfigProblem, ModelError

__all__ = ["MujocoModel", "MujocoModelFactory"]

_EMPTY: Mapping[str, Any] = MappingProxyType({})
BindTarget = FieldBind | Qpos0Bind | Qvel0Bind
OutputSource = QposOutput | QvelOutput | SensorOutput | XposOutput | SiteXposOutput
_PLACEHOLDER = re.compile(r"\{\{\s*([^{}]*?)\s*\}\}")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# Output times closer than this (in timesteps) to a whole step count are on the grid: a
# linspace grid is off by ~1e-16 relative, so 1e-6 steps allows 1e10-step horizons.
_GRID_TOLERANCE = 1e-6

_OBJ = mujoco.mjtObj
# What users call each kind of element, and the MjModel size that counts them.
_KINDS: dict[mujoco.mjtObj, tuple[str, str]] = {
    _OBJ.mjOBJ_BODY: ("body", "nbody"),
    _OBJ.mjOBJ_JOINT: ("joint", "njnt"),
    _OBJ.mjOBJ_GEOM: ("geom", "ngeom"),
    _OBJ.mjOBJ_SITE: ("site", "nsite"),
    _OBJ.mjOBJ_ACTUATOR: ("actuator", "nu"),
    _OBJ.mjOBJ_TENDON: ("tendon", "ntendon"),
    _OBJ.mjOBJ_EQUALITY: ("equality", "neq"),
    _OBJ.mjOBJ_PAIR: ("pair", "npair"),
    _OBJ.mjOBJ_SENSOR: ("sensor", "nsensor"),
}
# Element kind of a model field by its prefix, and the size of the field's first axis:
# dof_* rows are a joint's degrees of freedom, qpos_spring rows its coordinates.
_PREFIXES: dict[str, tuple[mujoco.mjtObj, str]] = {
    "body": (_OBJ.mjOBJ_BODY, "nbody"),
    "jnt": (_OBJ.mjOBJ_JOINT, "njnt"),
    "dof": (_OBJ.mjOBJ_JOINT, "nv"),
    "qpos": (_OBJ.mjOBJ_JOINT, "nq"),
    "geom": (_OBJ.mjOBJ_GEOM, "ngeom"),
    "site": (_OBJ.mjOBJ_SITE, "nsite"),
    "actuator": (_OBJ.mjOBJ_ACTUATOR, "nu"),
    "tendon": (_OBJ.mjOBJ_TENDON, "ntendon"),
    "eq": (_OBJ.mjOBJ_EQUALITY, "neq"),
    "pair": (_OBJ.mjOBJ_PAIR, "npair"),
}
# Fields mj_setConst computes from the others: a binding would be overwritten.
_DERIVED = frozenset(
    {
        "body_subtreemass",
        "body_invweight0",
        "dof_invweight0",
        "dof_M0",
        "tendon_invweight0",
        "tendon_length0",
        "actuator_length0",
        "actuator_acc0",
    }
)
# Geometry the compiler turns into mass, inertia and bounds: set on the MjSpec, then compiled.
_SPEC_FIELDS = {"geom_size": "size", "geom_pos": "pos"}
_JOINT = mujoco.mjtJoint
_ONE_DOF = (int(_JOINT.mjJNT_HINGE), int(_JOINT.mjJNT_SLIDE))
_QPOS_WIDTH = {int(_JOINT.mjJNT_FREE): 7, int(_JOINT.mjJNT_BALL): 4}
_STAGE = mujoco.mjtStage
_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION
# Recorded states per rollout call: long calls, since each is a barrier for the threads.
_RECORD_BYTES = 64 * 2**20


# --------------------------------------------------------------------------- small helpers


def _problem(path: str, message: str) -> ConfigProblem:
    return ConfigProblem(path=path, message=message)


def _one_line(exc: BaseException) -> str:
    """MuJoCo's multi-line message (error, then element and line) on one line."""
    return "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())


def _is_number(value: object) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _render(text: str, values: Mapping[str, float]) -> str:
    """The template with every placeholder replaced by its value's exact ``repr``."""
    return _PLACEHOLDER.sub(lambda m: repr(float(values[m.group(1)])), text)


def _worker_threads() -> int:
    """Threads this process may use: ``OMP_NUM_THREADS`` when set, else its CPUs."""
    budget = os.environ.get("OMP_NUM_THREADS", "")
    if budget.isdigit() and int(budget) > 0:
        return int(budget)
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity else os.cpu_count() or 1


def _structure(model: mujoco.MjModel) -> tuple[tuple[str, int], ...]:
    """Every size of a model (``nq``, ``nbody``, ...): what a template must not change."""
    sizes = ((name, getattr(model, name)) for name in dir(model) if name.startswith("n"))
    return tuple((name, value) for name, value in sizes if type(value) is int)


class _QuietMujocoLog:
    """Keep MuJoCo's log off the console and out of ``MUJOCO_LOG.TXT`` in the current folder.

    The log settings are global, so threads running models (a dask worker may run several)
    share one quiet period, from the first entry to the last exit.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._saved: mujoco.MjLogConfig | None = None

    def __enter__(self) -> None:
        with self._lock:
            if self._users == 0:
                self._saved = mujoco.MjLogConfig.get()
                quiet = mujoco.MjLogConfig.get()
                quiet.logto_console = False
                quiet.logto_file = False
                quiet.set()
            self._users += 1

    def __exit__(self, *exc_info: object) -> None:
        with self._lock:
            self._users -= 1
            if self._users == 0 and self._saved is not None:
                self._saved.set()


_MUJOCO_LOG_OFF = _QuietMujocoLog()


def _step_counts(times: NDArray[np.float64], timestep: float) -> NDArray[np.int64] | None:
    """Whole timesteps from 0 to each output time, or ``None`` if a time is off the grid."""
    steps = times / timestep
    counts = np.rint(steps)
    if np.any(np.abs(steps - counts) > _GRID_TOLERANCE):
        return None
    return counts.astype(np.int64)


def _grid_message(times: NDArray[np.float64], timestep: float) -> str:
    steps = times / timestep
    k = int(np.argmax(np.abs(steps - np.rint(steps))))
    return (
        f"time {times[k]:.9g} s is {steps[k]:.6f} timesteps of {timestep!r} s: every output "
        "time must be a whole number of the scene's timesteps (change the grid or the "
        "timestep)"
    )


# --------------------------------------------------------------------------- resolved specs


@dataclass(frozen=True)
class _FieldTarget:
    """One entry of a compiled model's array field (or of an ``opt`` field)."""

    field: str
    entry: int
    inertia_body: int | None = None  # body_mass: the body whose inertia scales with it

    def apply(self, model: mujoco.MjModel, value: float) -> None:
        if self.field.startswith("opt."):
            name = self.field[4:]
            current = getattr(model.opt, name)
            if isinstance(current, np.ndarray):
                current.reshape(-1)[self.entry] = value
            else:
                setattr(model.opt, name, value)
            return
        array = getattr(model, self.field).reshape(-1)
        if self.inertia_body is not None and array[self.entry] > 0:
            model.body_inertia[self.inertia_body] *= value / array[self.entry]
        array[self.entry] = value

    def read(self, model: mujoco.MjModel) -> float:
        if self.field.startswith("opt."):
            return float(np.ravel(getattr(model.opt, self.field[4:]))[self.entry])
        return float(getattr(model, self.field).reshape(-1)[self.entry])


@dataclass(frozen=True)
class _SpecTarget:
    """One entry of a geom attribute in the scene's ``MjSpec``."""

    geom: str
    attribute: str
    entry: int

    def apply(self, spec: mujoco.MjSpec, value: float) -> None:
        getattr(spec.geom(self.geom), self.attribute)[self.entry] = value


@dataclass(frozen=True)
class _StateTarget:
    """One coordinate of the initial ``qpos`` or ``qvel``."""

    state: str  # "qpos" or "qvel"
    address: int


@dataclass(frozen=True)
class _Output:
    """Where an output is read: a column of an ``MjData`` field, current after ``stage``."""

    field: str
    column: int
    stage: int


# --------------------------------------------------------------------------- the model


class MujocoModel:
    """An MJCF scene as a pcmb model: one MuJoCo run per node, batched on threads.

    The scene is loaded and checked once, at construction (``docs/architecture.md`` says how
    inputs, outputs, threads and divergence are handled).

    Parameters
    ----------
    xml:
        The MJCF file; with ``{{ name }}`` placeholders it is a template.
    params:
        Nominal values: one for every placeholder, and optionally for bound inputs.
    bind:
        In the binding language of :mod:`pcmb.adapters.mujoco.binding` (plain dicts or its
        parsed entries), as are ``init`` and ``outputs``.
        Input name -> list of targets: ``{field: body_mass, name: bob}``,
        ``{field: geom_friction, name: foot, index: 0}``, ``{field: opt.gravity, index: 2}``,
        ``{qpos0: hinge}``, ``{qvel0: hinge}``.
    init:
        Fixed initial state: ``{qpos: {joint: value}, qvel: {joint: value}}`` (hinge and
        slide joints); joints not named start at the scene's ``qpos0`` and at rest.
    outputs:
        Output name -> source: ``{qpos: joint}``, ``{qvel: joint}``, ``{sensor: name}``
        (``index`` for a sensor of several values), ``{xpos: body, axis: 0-2}``,
        ``{site_xpos: site, axis: 0-2}``.

    Attributes
    ----------
    outputs:
        Output names, in the order given.
    parameters:
        Every input this model accepts, with its nominal value: placeholders first, then
        bound inputs (a bound input without a nominal in ``params`` reports the value of its
        first target in the compiled scene).

    Raises
    ------
    ConfigError
        If the file cannot be read, MuJoCo cannot load it (its message and line), a
        placeholder has no nominal value, or a binding, initial state or output names an
        element, field or index the scene does not have. Paths are config key paths
        (``model.bind.m[0].name``); every problem found is reported at once.
    """

    def __init__(
        self,
        *,
        xml: Path,
        params: Mapping[str, float] = _EMPTY,
        bind: Mapping[str, Sequence[Mapping[str, Any] | BindTarget]] = _EMPTY,
        init: Mapping[str, Mapping[str, float]] | InitSpec = _EMPTY,
        outputs: Mapping[str, Mapping[str, Any] | OutputSource],
    ) -> None:
        self._xml = Path(xml)
        try:
            text = self._xml.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError([_problem("model.xml", f"cannot read {self._xml}: {exc}")]) from exc
        scene_io = parse_scene_io(bind, init, outputs)
        problems: list[ConfigProblem] = []
        placeholders = self._placeholders(text, problems)
        self._template = text if placeholders else None
        self._nominal = self._check_params(params, placeholders, scene_io.bind, problems)
        if problems:  # without every nominal value the scene cannot be compiled
            raise ConfigError(problems)

        with _MUJOCO_LOG_OFF:
            try:
                if self._template is None:
                    self._spec = mujoco.MjSpec.from_file(str(self._xml))
                else:
                    self._spec = self._parse(_render(text, self._nominal))
                self._base = self._spec.compile()
            except (ValueError, mujoco.FatalError) as exc:
                raise ConfigError(
                    [_problem("model.xml", f"MuJoCo cannot load {self._xml}: {_one_line(exc)}")]
                ) from exc

            self._field_targets: list[tuple[str, _FieldTarget]] = []
            self._spec_targets: list[tuple[str, _SpecTarget]] = []
            self._state_targets: list[tuple[str, _StateTarget]] = []
            self._resolve_bind(scene_io.bind, problems)
            self._init = self._resolve_init(scene_io.init, problems)
            self._outputs = self._resolve_outputs(scene_io.outputs, problems)
            if problems:
                raise ConfigError(problems)
            # body_mass first, so that an explicit body_inertia binding wins over its scaling
            self._field_targets.sort(key=lambda item: item[1].inertia_body is None)
            try:
                self._nominal_model = self._build(self._nominal)
            except (ValueError, mujoco.FatalError) as exc:
                raise ConfigError(
                    [
                        _problem(
                            "model.params", f"MuJoCo rejects the nominal values: {_one_line(exc)}"
                        )
                    ]
                ) from exc

        self._structure = _structure(self._nominal_model)
        self.outputs: tuple[str, ...] = tuple(self._outputs)
        self.parameters: Mapping[str, float] = MappingProxyType(
            {name: self._nominal_value(name) for name in (*placeholders, *scene_io.bind)}
        )

    # -- construction: what the config says --------------------------------------------------

    @staticmethod
    def _placeholders(text: str, problems: list[ConfigProblem]) -> tuple[str, ...]:
        names: dict[str, None] = {}
        for match in _PLACEHOLDER.finditer(text):
            name = match.group(1)
            if _NAME.fullmatch(name):
                names[name] = None
            else:
                line = text.count("\n", 0, match.start()) + 1
                problems.append(
                    _problem(
                        "model.xml",
                        f"line {line}: placeholder {match.group(0)!r} must name an input "
                        "(letters, digits and _)",
                    )
                )
        return tuple(names)

    @staticmethod
    def _check_params(
        params: Mapping[str, float],
        placeholders: Sequence[str],
        bind: Mapping[str, object],
        problems: list[ConfigProblem],
    ) -> dict[str, float]:
        nominal: dict[str, float] = {}
        for name, value in params.items():
            path = f"model.params.{name}"
            if name not in placeholders and name not in bind:
                problems.append(
                    _problem(
                        path,
                        f"{name!r} is neither a {{{{ {name} }}}} placeholder in the "
                        "XML nor an input under model.bind",
                    )
                )
            elif not _is_number(value) or not np.isfinite(value):
                problems.append(_problem(path, f"expected a finite number, got {value!r}"))
            else:
                nominal[name] = float(value)
        for name in placeholders:
            if name in bind:
                problems.append(
                    _problem(
                        f"model.bind.{name}",
                        f"{name!r} is also a placeholder in the "
                        "XML: an input enters either way, not both",
                    )
                )
            elif name not in params:
                problems.append(
                    _problem(
                        "model.params",
                        f"no nominal value for the placeholder "
                        f"{{{{ {name} }}}} in the XML: add {name} to model.params",
                    )
                )
        return nominal

    def _parse(self, text: str) -> mujoco.MjSpec:
        spec = mujoco.MjSpec.from_string(text)
        spec.modelfiledir = str(self._xml.parent)  # meshes and textures resolve beside the file
        return spec

    def _element(
        self, obj: mujoco.mjtObj, name: object, path: str, problems: list[ConfigProblem]
    ) -> int | None:
        """The id of the element of type ``obj`` called ``name``, or a problem."""
        label, size = _KINDS[obj]
        found = mujoco.mj_name2id(self._base, obj, name) if isinstance(name, str) else -1
        if found < 0:
            names = [
                mujoco.mj_id2name(self._base, obj, i) for i in range(getattr(self._base, size))
            ]
            names = [n for n in names if n]
            known = ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
            problems.append(
                _problem(path, f"no {label} named {name!r} in the scene ({known or 'none named'})")
            )
            return None
        return found

    def _joint(self, name: object, path: str, problems: list[ConfigProblem]) -> int | None:
        """A hinge or slide joint's id, or a problem."""
        joint = self._element(_OBJ.mjOBJ_JOINT, name, path, problems)
        if joint is not None and int(self._base.jnt_type[joint]) not in _ONE_DOF:
            kind = mujoco.mjtJoint(self._base.jnt_type[joint]).name[6:].lower()
            problems.append(
                _problem(
                    path,
                    f"joint {name!r} is a {kind} joint: only hinge and slide joints "
                    "have one coordinate (use a sensor for others)",
                )
            )
            return None
        return joint

    @staticmethod
    def _index(
        index: int | None, size: int, what: str, path: str, problems: list[ConfigProblem]
    ) -> int | None:
        """An entry's ``index`` into ``size`` values (may be omitted when size is 1)."""
        if index is None:
            if size == 1:
                return 0
            problems.append(
                _problem(f"{path}.index", f"{what} has {size} values: give an index 0-{size - 1}")
            )
        elif not 0 <= index < size:
            problems.append(
                _problem(
                    f"{path}.index",
                    f"expected an integer 0-{size - 1} ({what} has {size} values), got {index!r}",
                )
            )
        else:
            return int(index)
        return None

    def _resolve_bind(
        self, bind: Mapping[str, Sequence[BindTarget]], problems: list[ConfigProblem]
    ) -> None:
        for name, entries in bind.items():
            for i, entry in enumerate(entries):
                path = f"model.bind.{name}[{i}]"
                if isinstance(entry, FieldBind):
                    if entry.field.startswith("opt."):
                        self._resolve_option(name, entry, path, problems)
                    else:
                        self._resolve_model_field(name, entry, path, problems)
                    continue
                joint = self._joint(entry.joint, f"{path}.{entry.state}0", problems)
                if joint is not None:
                    adr = self._base.jnt_qposadr if entry.state == "qpos" else self._base.jnt_dofadr
                    self._state_targets.append((name, _StateTarget(entry.state, int(adr[joint]))))

    def _resolve_option(
        self, name: str, entry: FieldBind, path: str, problems: list[ConfigProblem]
    ) -> None:
        field = entry.field
        option = field[4:]
        current = None if option.startswith("_") else getattr(self._base.opt, option, None)
        if current is None or callable(current) or np.asarray(current).dtype.kind != "f":
            problems.append(
                _problem(
                    f"{path}.field",
                    f"{field!r} is not a real-valued MuJoCo option "
                    "(e.g. opt.gravity, opt.timestep, opt.wind, opt.viscosity)",
                )
            )
        elif entry.name is not None:
            problems.append(_problem(f"{path}.name", f"{field} belongs to no element: drop name"))
        else:
            index = self._index(entry.index, int(np.size(current)), field, path, problems)
            if index is not None:
                self._field_targets.append((name, _FieldTarget(field, index)))

    def _resolve_model_field(
        self, name: str, entry: FieldBind, path: str, problems: list[ConfigProblem]
    ) -> None:
        field = entry.field
        prefix = field.split("_", 1)[0]
        array = None if field.startswith("_") else getattr(self._base, field, None)
        obj, size = _PREFIXES.get(prefix, (None, ""))
        if (
            field in _DERIVED
            or field == "qpos0"
            or obj is None
            or not isinstance(array, np.ndarray)
            or array.dtype.kind != "f"
            or array.shape[:1] != (getattr(self._base, size),)
        ):
            if field in _DERIVED:
                why = "MuJoCo computes it from other fields"
            elif field == "qpos0":
                why = "it is the reference pose; bind an initial position with {qpos0: joint}"
            else:
                why = "not a real-valued per-element MjModel field, nor opt.<option>"
            close = difflib.get_close_matches(field, dir(self._base), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            problems.append(_problem(f"{path}.field", f"cannot bind {field!r}: {why}{hint}"))
            return
        element = self._element(obj, entry.name, f"{path}.name", problems)
        if element is None:
            return
        # the element's rows of the field: one, or a joint's dofs / coordinates
        if prefix == "dof":
            rows = np.flatnonzero(self._base.dof_jntid == element)
        elif prefix == "qpos":
            start = self._base.jnt_qposadr[element]
            rows = np.arange(start, start + _QPOS_WIDTH.get(int(self._base.jnt_type[element]), 1))
        else:
            rows = np.array([element])
        width = array[0].size
        what = f"{field} of {_KINDS[obj][0]} {entry.name!r}"
        index = self._index(entry.index, rows.size * width, what, path, problems)
        if index is None:
            return
        if field in _SPEC_FIELDS:
            if not np.isnan(self._spec.geom(entry.name).fromto[0]):
                problems.append(
                    _problem(
                        f"{path}.field",
                        f"geom {entry.name!r} is given by fromto, from which MuJoCo computes "
                        "its size and pos: put a placeholder in fromto instead",
                    )
                )
            else:
                target = _SpecTarget(str(entry.name), _SPEC_FIELDS[field], index)
                self._spec_targets.append((name, target))
            return
        entry_index = int(rows[0]) * width + index
        scaled = element if field == "body_mass" else None
        self._field_targets.append((name, _FieldTarget(field, entry_index, scaled)))

    def _resolve_init(
        self, init: InitSpec, problems: list[ConfigProblem]
    ) -> list[tuple[_StateTarget, float]]:
        writes: list[tuple[_StateTarget, float]] = []
        for state, values in (("qpos", init.qpos), ("qvel", init.qvel)):
            adr = self._base.jnt_qposadr if state == "qpos" else self._base.jnt_dofadr
            for joint_name, value in values.items():
                joint = self._joint(joint_name, f"model.init.{state}.{joint_name}", problems)
                if joint is not None:
                    writes.append((_StateTarget(state, int(adr[joint])), float(value)))
        return writes

    def _resolve_outputs(
        self, outputs: Mapping[str, OutputSource], problems: list[ConfigProblem]
    ) -> dict[str, _Output]:
        resolved: dict[str, _Output] = {}
        for name, source in outputs.items():
            output = self._resolve_output(source, f"model.outputs.{name}", problems)
            if output is not None:
                resolved[name] = output
        return resolved

    def _resolve_output(
        self, source: OutputSource, path: str, problems: list[ConfigProblem]
    ) -> _Output | None:
        base = self._base
        if isinstance(source, QposOutput | QvelOutput):
            kind = source.source
            joint = self._joint(getattr(source, kind), f"{path}.{kind}", problems)
            if joint is None:
                return None
            adr = base.jnt_qposadr if kind == "qpos" else base.jnt_dofadr
            return _Output(kind, int(adr[joint]), int(_STAGE.mjSTAGE_NONE))
        if isinstance(source, SensorOutput):
            sensor = self._element(_OBJ.mjOBJ_SENSOR, source.sensor, f"{path}.sensor", problems)
            if sensor is None:
                return None
            what = f"sensor {source.sensor!r}"
            size = int(base.sensor_dim[sensor])
            index = self._index(source.index, size, what, path, problems)
            if index is None:
                return None
            column = int(base.sensor_adr[sensor]) + index
            return _Output("sensordata", column, int(base.sensor_needstage[sensor]))
        kind = source.source
        obj = _OBJ.mjOBJ_BODY if kind == "xpos" else _OBJ.mjOBJ_SITE
        element = self._element(obj, getattr(source, kind), f"{path}.{kind}", problems)
        if element is None:
            return None
        return _Output(kind, 3 * element + int(source.axis), int(_STAGE.mjSTAGE_POS))

    def _nominal_value(self, name: str) -> float:
        if name in self._nominal:
            return self._nominal[name]
        for bound, target in self._field_targets:
            if bound == name:
                return target.read(self._nominal_model)
        for bound, spec_target in self._spec_targets:
            if bound == name:
                geom = self._spec.geom(spec_target.geom)
                return float(getattr(geom, spec_target.attribute)[spec_target.entry])
        state = next(target for bound, target in self._state_targets if bound == name)
        fixed = {target: value for target, value in self._init}
        if state in fixed:
            return fixed[state]
        return float(self._nominal_model.qpos0[state.address]) if state.state == "qpos" else 0.0

    # -- one node's scene --------------------------------------------------------------------

    def _build(self, values: Mapping[str, float]) -> mujoco.MjModel:
        """The compiled scene for one node's input values.

        Raises
        ------
        ValueError, mujoco.FatalError
            MuJoCo's message when the scene does not compile with these values.
        """
        if self._template is not None:
            spec: mujoco.MjSpec | None = self._parse(_render(self._template, values))
        else:
            spec = self._spec if self._spec_targets else None
        if spec is not None:
            for name, spec_target in self._spec_targets:
                if name in values:
                    spec_target.apply(spec, values[name])
            model = spec.compile()
        else:
            model = self._base
        edits = [(target, values[name]) for name, target in self._field_targets if name in values]
        if edits:
            if model is self._base:
                model = copy.copy(model)
            for target, value in edits:
                target.apply(model, value)
            mujoco.mj_setConst(model, mujoco.MjData(model))
        return model

    # -- the protocol ------------------------------------------------------------------------

    def check_times(self, times: ArrayLike) -> None:
        """Check that the scene can report at ``times``.

        Parameters
        ----------
        times:
            Output grid, (T,) seconds from the initial state.

        Raises
        ------
        ConfigError
            At ``time``, if the grid is not 1-D, finite, non-negative and increasing, or a
            time is not a whole number of the scene's timesteps.
        """
        grid = self._grid(times)
        timestep = self._nominal_model.opt.timestep
        if _step_counts(grid, timestep) is None:
            raise ConfigError([_problem("time", _grid_message(grid, timestep))])

    @staticmethod
    def _grid(times: ArrayLike) -> NDArray[np.float64]:
        grid = np.asarray(times, dtype=np.float64)
        if grid.ndim != 1 or grid.size == 0:
            message = f"the output grid must be a non-empty 1-D array, got shape {grid.shape}"
        elif not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            message = "the output grid must be finite, start at or after 0 and increase strictly"
        else:
            return grid
        raise ConfigError([_problem("time", message)])

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run one MuJoCo simulation per node, all on one thread pool.

        Parameters
        ----------
        params:
            The uncertain inputs of this batch, each (B,); the others keep their nominal
            values. Empty: one run at the nominal values.
        times:
            Output grid, (T,) seconds, each a whole number of timesteps.

        Returns
        -------
        dict
            Every name in :attr:`outputs` -> (B, T) values; the rows of a failed node (scene
            not compiling with its values, divergence) are NaN when B > 1.

        Raises
        ------
        ConfigError
            If an input is not one of :attr:`parameters`, the inputs are not (B,) arrays of
            one length, or the grid is not reachable with the nominal timestep.
        ModelError
            If B == 1 and the run failed, with the reason.
        """
        grid = self._grid(times)
        self.check_times(grid)
        nodes = self._node_values(params)
        n_nodes = len(nodes)
        values = {name: np.full((n_nodes, grid.size), np.nan) for name in self.outputs}
        failures: dict[int, str] = {}
        with _MUJOCO_LOG_OFF:
            models: dict[int, mujoco.MjModel] = {}
            for i, node in enumerate(nodes):
                try:
                    models[i] = self._node_model(node)
                except (ValueError, mujoco.FatalError) as exc:
                    failures[i] = f"MuJoCo cannot build the scene: {_one_line(exc)}"
            if models:
                self._run(models, nodes, grid, values, failures)
        if failures and n_nodes == 1:
            raise ModelError(failures[0])
        for i in failures:
            for array in values.values():
                array[i] = np.nan
        return values

    def _node_values(self, params: Mapping[str, NDArray[np.float64]]) -> list[dict[str, float]]:
        """Each node's input values: the nominal ones updated with the node's."""
        arrays = {}
        problems = []
        for name, value in params.items():
            array = np.asarray(value, dtype=np.float64)
            if name not in self.parameters:
                problems.append(
                    _problem(
                        f"inputs.{name}",
                        f"{name!r} is not a parameter of this scene "
                        f"(parameters: {', '.join(self.parameters) or 'none'})",
                    )
                )
            elif array.ndim != 1:
                problems.append(
                    _problem(
                        f"inputs.{name}",
                        f"expected one value per node, (B,), got shape {array.shape}",
                    )
                )
            else:
                arrays[name] = array
        sizes = {array.size for array in arrays.values()}
        if len(sizes) > 1:
            problems.append(_problem("inputs", f"inputs of different lengths: {sorted(sizes)}"))
        if problems:
            raise ConfigError(problems)
        n_nodes = sizes.pop() if sizes else 1
        return [
            {**self._nominal, **{name: float(a[i]) for name, a in arrays.items()}}
            for i in range(n_nodes)
        ]

    def _node_model(self, values: Mapping[str, float]) -> mujoco.MjModel:
        model = self._build(values)
        if _structure(model) != self._structure:
            changed = [
                f"{name} {a} -> {b}"
                for (name, a), (_, b) in zip(self._structure, _structure(model), strict=False)
                if a != b
            ]
            raise ValueError(
                "the placeholders changed the scene's structure from the nominal one "
                f"({', '.join(changed[:5])}): they may change values, not sizes"
            )
        return model

    def _run(
        self,
        models: Mapping[int, mujoco.MjModel],
        nodes: Sequence[Mapping[str, float]],
        times: NDArray[np.float64],
        values: dict[str, NDArray[np.float64]],
        failures: dict[int, str],
    ) -> None:
        """Run the nodes in ``models`` (node index -> scene), recording into ``values``."""
        rows = np.fromiter(models, dtype=np.intp)
        run = _BatchRun(self._nominal_model, [models[i] for i in rows], times, self._outputs)
        for target, value in self._init:
            run.set_state(target, np.full(rows.size, value))
        for name, target in self._state_targets:
            if name in nodes[0]:  # every node has the same names: the nominal ones and params
                run.set_state(target, np.array([nodes[i][name] for i in rows]))
        record, messages = run.run()
        for name in self.outputs:
            values[name][rows] = record[name]
        failures.update({int(rows[j]): message for j, message in messages.items()})


class _BatchRun:
    """The scenes of one batch stepped together on a thread pool, one per simulation.

    Each ``Batch.rollout`` call advances the simulations by many output intervals at once,
    recording their full state at every substep (at most ``_RECORD_BYTES``): a call is a
    barrier for the threads, and on a loaded machine one descheduled thread stalls them all,
    so calls are made as long as memory allows. Positions and velocities are read from the
    recorded states; derived outputs (``xpos``, sensors) are computed from the states at the
    output times by a forward pass.

    Parameters
    ----------
    layout:
        A model with the scenes' sizes.
    models:
        One compiled scene per simulation.
    times:
        Output grid, (T,).
    outputs:
        Where each output is read.
    """

    def __init__(
        self,
        layout: mujoco.MjModel,
        models: Sequence[mujoco.MjModel],
        times: NDArray[np.float64],
        outputs: Mapping[str, _Output],
    ) -> None:
        n_sims = len(models)
        self.times = times
        self.outputs = outputs
        self.messages: dict[int, str] = {}
        self.alive = np.ones(n_sims, dtype=bool)
        self.timestep = np.array([model.opt.timestep for model in models])
        self.counts = np.zeros((n_sims, times.size), dtype=np.int64)
        for j, timestep in enumerate(self.timestep):
            counts = _step_counts(times, timestep)
            if counts is None:  # only an input bound to opt.timestep gets here
                self._fail(j, _grid_message(times, timestep))
            else:
                self.counts[j] = counts
        # simulations that step alike advance together
        schedules: dict[bytes, list[int]] = {}
        for j in np.flatnonzero(self.alive):
            schedules.setdefault(self.counts[j].tobytes(), []).append(int(j))
        self.groups = [np.array(sims, dtype=np.int32) for sims in schedules.values()]

        self.batch = mujoco.batch.Batch(layout, nsim=n_sims, nthread=min(n_sims, _worker_threads()))
        self.batch.set_models(list(models))
        # state rows in mj_getState order: time (1 number), qpos (nq), qvel (nv), ...
        self.rows = self.batch.state
        self.offset = {"qpos": 1, "qvel": 1 + layout.nq}
        self.n_physical = layout.nq + layout.nv
        self.derived = {n: out for n, out in outputs.items() if out.field not in self.offset}
        self.stage = max((out.stage for out in self.derived.values()), default=0)
        # bound before the first call: a derived field bound between calls reads zero
        self.fields = {out.field: self.batch.bind(out.field) for out in self.derived.values()}
        self.batch.reset(stage=_STAGE.mjSTAGE_NONE)

    def set_state(self, target: _StateTarget, values: NDArray[np.float64]) -> None:
        """Set one initial coordinate of every simulation, (n_sims,)."""
        self.rows[:, self.offset[target.state] + target.address] = values

    def run(self) -> tuple[dict[str, NDArray[np.float64]], dict[int, str]]:
        """Step through the grid; return each output, (n_sims, T), and the failures."""
        n_sims = self.alive.size
        record = {name: np.full((n_sims, self.times.size), np.nan) for name in self.outputs}
        for group in self.groups:
            self._run_group(group, record)
        return record, self.messages

    def _run_group(self, sims: NDArray[np.int32], record: dict[str, NDArray[np.float64]]) -> None:
        counts = self.counts[sims[0]]
        done, k = 0, 0
        if counts[0] == 0:  # the initial state is the first output
            self._record(sims, 0, self.rows[sims].copy(), record)
            k = 1
        while k < counts.size and self.alive[sims].any():
            sims = sims[self.alive[sims]]
            budget = max(1, _RECORD_BYTES // (sims.size * self.rows.shape[1] * 8))
            if counts[k] - done > budget:  # far to the next output: get there unrecorded
                skip = int(counts[k] - done - 1)
                self._call(self.batch.step, sims, nstep=skip)
                done += skip
                sims = sims[self.alive[sims]]
                if not sims.size:
                    return
            # the last output time within budget (at least the next one)
            last = max(k, int(np.searchsorted(counts, done + budget, side="right")) - 1)
            nstep = int(counts[last] - done)
            states = np.empty((sims.size, nstep, self.rows.shape[1]))
            self._call(
                self.batch.rollout,
                nstep,
                record=[_INTEGRATION],
                ids=sims,
                out={_INTEGRATION: states},
            )
            end = self.rows[sims].copy()
            at_outputs = states[:, counts[k : last + 1] - done - 1]  # (sims, outputs, nstate)
            for j in range(k, last + 1):
                self._record(sims, j, at_outputs[:, j - k], record)
            self.rows[sims] = end  # the derived pass moved the rows to the output states
            self._check(sims, at_outputs, counts[k : last + 1], k)
            done, k = int(counts[last]), last + 1

    def _call(self, method: Callable[..., object], *args: Any, **kwargs: Any) -> None:
        """Call a batch method; fail the simulations in which MuJoCo raised an error."""
        try:
            method(*args, **kwargs)
        except mujoco.batch.SimulationError as exc:
            for sim in exc.ids:
                self._fail(int(sim), f"MuJoCo raised an error: {self.batch.error(int(sim))}")

    def _record(
        self,
        sims: NDArray[np.int32],
        k: int,
        states: NDArray[np.float64],
        record: dict[str, NDArray[np.float64]],
    ) -> None:
        """Record output time ``k`` of ``sims`` from their states there, (sims, nstate)."""
        for name, out in self.outputs.items():
            if out.field in self.offset:
                record[name][sims, k] = states[:, self.offset[out.field] + out.column]
        if not self.derived:
            return
        self.rows[sims] = states
        self._call(self.batch.forward, sims, stage=self.stage)
        n_sims = self.alive.size
        for name, out in self.derived.items():
            record[name][sims, k] = self.fields[out.field].reshape(n_sims, -1)[sims, out.column]

    def _fail(self, sim: int, message: str) -> None:
        if self.alive[sim]:
            self.alive[sim] = False
            self.messages[sim] = message

    def _check(
        self,
        sims: NDArray[np.int32],
        states: NDArray[np.float64],
        counts: NDArray[np.int64],
        first: int,
    ) -> None:
        """Fail the simulations that diverged before the output times ``first`` + 0, 1, ...

        ``states`` (sims, outputs, nstate) are their recorded states at those times, which
        ``counts`` steps from the start reach.
        """
        warning = self.batch.warning  # (n_sims, mjNWARNING, [lastinfo, number])
        raised = warning[sims, :, 1] > 0
        timestep = self.timestep[sims][:, None]
        late = np.abs(states[:, :, 0] - counts * timestep) > timestep / 2
        physical = states[:, :, 1 : 1 + self.n_physical]
        bad = late | ~np.isfinite(physical).all(axis=2)  # (sims, outputs)
        for i in np.flatnonzero(raised.any(axis=1) | bad.any(axis=1)):
            sim = int(sims[i])
            when = self.times[first + int(np.argmax(bad[i]))] if bad[i].any() else None
            if raised[i].any():
                kind = int(np.flatnonzero(raised[i])[0])
                text = mujoco.mju_warningText(kind, int(warning[sim, kind, 0]))
                why = f"{text} [{mujoco.mjtWarning(kind).name}]"
            elif not late[i].any():
                why = "the state is not finite"
            else:
                j = int(np.argmax(late[i]))
                why = f"MuJoCo's clock stopped at {states[i, j, 0]:.9g} s"
            where = (
                f"by t = {when:.6g} s"
                if when is not None
                else f"before t = {self.times[first + counts.size - 1]:.6g} s"
            )
            self._fail(sim, f"the MuJoCo run diverged {where}: {why}")


@dataclass(frozen=True)
class MujocoModelFactory(ModelFactory):
    """Builds a :class:`MujocoModel` (plain-picklable; the executor builds one per worker).

    Attributes
    ----------
    xml, params, bind, init, outputs:
        As for :class:`MujocoModel`.
    """

    xml: Path
    params: dict[str, float]
    bind: dict[str, list[dict[str, Any]]]
    init: dict[str, dict[str, float]]
    outputs: dict[str, dict[str, Any]]

    def __call__(self) -> MujocoModel:
        """Load and check the scene.

        Raises
        ------
        ConfigError
            As :class:`MujocoModel`.
        """
        return MujocoModel(
            xml=self.xml, params=self.params, bind=self.bind, init=self.init, outputs=self.outputs
        )

    def model_files(self) -> list[Path]:
        """The scene, its includes and its asset files (:func:`mjcf_files`)."""
        return mjcf_files(self.xml)
