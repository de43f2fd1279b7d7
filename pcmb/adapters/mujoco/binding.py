"""The MuJoCo binding language: what reaches a scene (``bind``, ``init``) and what is read
from it (``outputs``).

Defined once: the config section (:mod:`.spec`) validates with these classes, and
:class:`~pcmb.adapters.mujoco.model.MujocoModel` parses a Python caller's plain dicts through
them (:func:`parse_scene_io`). This module does not import mujoco.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import BeforeValidator, Field, ValidationError

from pcmb.config.messages import schema_problems
from pcmb.config.types import (
    Name,
    NonNegativeInt,
    Real,
    Section,
    reject_text_and_bool,
    tagged_by_key,
)
from pcmb.errors import ConfigError

__all__ = [
    "BindEntry",
    "FieldBind",
    "InitSpec",
    "MujocoOutput",
    "Qpos0Bind",
    "QposOutput",
    "Qvel0Bind",
    "QvelOutput",
    "SceneIO",
    "SensorOutput",
    "SiteXposOutput",
    "XposOutput",
    "parse_scene_io",
]

Axis = Annotated[Literal[0, 1, 2], BeforeValidator(reject_text_and_bool("0, 1 or 2"))]


# --------------------------------------------------------------------------- inputs


class FieldBind(Section):
    """An input that sets a compiled MjModel field: ``{field: body_mass, name: bob}``."""

    field: str = Field(description="MjModel field (body_mass, dof_damping, opt.gravity, ...)")
    name: str | None = Field(
        default=None, description="element of the field (omit for opt.* fields)"
    )
    index: NonNegativeInt | None = Field(
        default=None, description="component of a multi-valued field"
    )


class Qpos0Bind(Section):
    """An input that sets the initial position of a joint: ``{qpos0: joint}``."""

    qpos0: str = Field(description="joint whose initial position the input sets")
    state: ClassVar[str] = "qpos"

    @property
    def joint(self) -> str:
        return self.qpos0


class Qvel0Bind(Section):
    """An input that sets the initial velocity of a joint: ``{qvel0: joint}``."""

    qvel0: str = Field(description="joint whose initial velocity the input sets")
    state: ClassVar[str] = "qvel"

    @property
    def joint(self) -> str:
        return self.qvel0


BindEntry = tagged_by_key(
    FieldBind,
    Qpos0Bind,
    Qvel0Bind,
    error="expected {field: ..., name: ..., index: ...}, {qpos0: joint} or {qvel0: joint}",
)


class InitSpec(Section):
    """Fixed initial state by joint name (hinge and slide joints)."""

    qpos: dict[str, Real] = Field(
        default_factory=dict, description="joint -> fixed initial position"
    )
    qvel: dict[str, Real] = Field(
        default_factory=dict, description="joint -> fixed initial velocity"
    )


# --------------------------------------------------------------------------- outputs


class QposOutput(Section):
    """``{qpos: joint}``."""

    qpos: str = Field(description="joint whose position is recorded")
    source: ClassVar[str] = "qpos"


class QvelOutput(Section):
    """``{qvel: joint}``."""

    qvel: str = Field(description="joint whose velocity is recorded")
    source: ClassVar[str] = "qvel"


class SensorOutput(Section):
    """``{sensor: name}``, with ``index`` for a sensor of several values."""

    sensor: str = Field(description="sensor recorded")
    index: NonNegativeInt | None = Field(
        default=None, description="component of a multi-valued sensor"
    )
    source: ClassVar[str] = "sensor"


class XposOutput(Section):
    """``{xpos: body, axis}``."""

    xpos: str = Field(description="body whose world position is recorded")
    axis: Axis = Field(description="coordinate: 0 x, 1 y, 2 z")
    source: ClassVar[str] = "xpos"


class SiteXposOutput(Section):
    """``{site_xpos: site, axis}``."""

    site_xpos: str = Field(description="site whose world position is recorded")
    axis: Axis = Field(description="coordinate: 0 x, 1 y, 2 z")
    source: ClassVar[str] = "site_xpos"


MujocoOutput = tagged_by_key(
    QposOutput,
    QvelOutput,
    SensorOutput,
    XposOutput,
    SiteXposOutput,
    error="expected one of {qpos: joint}, {qvel: joint}, {sensor: name}, "
    "{xpos: body, axis: 0-2}, {site_xpos: site, axis: 0-2}",
)

Bindings = dict[Name, Annotated[list[BindEntry], Field(min_length=1)]]
Outputs = Annotated[dict[Name, MujocoOutput], Field(min_length=1)]


# ------------------------------------------------------------------ a scene's inputs and outputs


class SceneIO(Section):
    """What reaches a scene and what is read from it: ``bind``, ``init``, ``outputs``."""

    bind: Bindings = Field(
        default_factory=dict, description="input -> the MjModel fields or initial states it sets"
    )
    init: InitSpec = Field(default_factory=InitSpec)
    outputs: Outputs = Field(description="output name -> what it reads from the simulation")


def parse_scene_io(bind: Any, init: Any, outputs: Any) -> SceneIO:
    """Plain dicts (or parsed entries) in the binding language, validated.

    Raises
    ------
    ConfigError
        Every problem, at its config key path (``model.bind.m[0].name``, ...).
    """
    try:
        return SceneIO.model_validate({"bind": bind, "init": init, "outputs": outputs})
    except ValidationError as exc:
        raise ConfigError(schema_problems(exc, SceneIO, prefix=("model",))) from None
