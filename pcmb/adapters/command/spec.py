"""The ``model:`` section of ``kind: command``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BeforeValidator, Field, model_validator

from pcmb.adapters.command.model import (
    CommandModelFactory,
    KeepPolicy,
    OutputFormat,
    split_command,
)
from pcmb.axes import OutputAxis
from pcmb.config.types import ModelSection, Name, NameList, Points, PositiveReal, Real, Section

__all__ = ["CommandModelSpec", "CommandOutputSpec"]


def _split_command(value: Any) -> Any:
    """A command may be written as one string; it is split like a shell would, without one."""
    if isinstance(value, str):
        try:
            return split_command(value)
        except ValueError as exc:
            raise ValueError(f"cannot split the command: {exc}") from None
    if not isinstance(value, list):
        raise ValueError(f"expected a list of strings or one string, found {value!r}")
    return value


Command = Annotated[
    list[str],
    Field(min_length=1),
    BeforeValidator(_split_command, json_schema_input_type=str | list[str]),
]


class CommandAxisSpec(Section):
    """The outputs' own axis (an AC sweep's frequencies), read from a column of the file."""

    name: Name = Field(default="frequency", description="the axis's name (its dimension)")
    column: str = Field(description="column (key) of the output file holding its points")
    unit: str = Field(default="", description="unit text; Hz, kHz, rad/s... draw log axes")
    start: Real = Field(description="first point")
    stop: Real = Field(description="last point (> start)")
    points: Points = Field(description="number of points")
    spacing: Literal["linear", "log"] = Field(
        default="linear", description="linear or log (geometric, start > 0) spacing"
    )

    @model_validator(mode="after")
    def _grid(self) -> CommandAxisSpec:
        if not self.stop > self.start:
            raise ValueError(f"stop ({self.stop}) must exceed start ({self.start})")
        if self.spacing == "log" and not self.start > 0:
            raise ValueError(f"a log spacing needs start > 0, found {self.start}")
        return self

    def axis(self) -> OutputAxis:
        """The axis: ``points`` from ``start`` to ``stop``, as the file must hold them."""
        spread = np.geomspace if self.spacing == "log" else np.linspace
        return OutputAxis(self.name, spread(self.start, self.stop, self.points), self.unit)


class CommandOutputSpec(Section):
    """The file an external command writes in its work directory."""

    file: str = Field(description="file the command writes in its work directory")
    format: OutputFormat | None = Field(
        default=None,
        description="table: whitespace-separated columns; default: from the extension "
        "(.csv, .json, .npy, .npz)",
    )
    time_column: str = Field(default="time", description="checked against the grid if present")
    axis: CommandAxisSpec | None = Field(
        default=None, description="the outputs' own axis instead of time (not set: time)"
    )


class CommandModelSpec(ModelSection):
    """``kind: command``: an external executable run once per node."""

    kind: Literal["command"]
    command: Command = Field(description="argv list, or a string split like a shell would")
    params: dict[Name, Real] = Field(
        default_factory=dict, description="nominal values rendered into the templates and command"
    )
    outputs: NameList = Field(description="names of the outputs the command writes")
    output: CommandOutputSpec
    templates: list[str] = Field(default_factory=list, description="files rendered per node")
    files: list[str] = Field(default_factory=list, description="files linked into each node dir")
    timeout: PositiveReal | None = Field(default=None, description="seconds per run")
    run_dir: str | None = Field(default=None, description="parent of node dirs (default: temp)")
    keep: KeepPolicy = Field(
        default="failed", description="which node work directories survive: failed, all or none"
    )

    def factory(self, base_dir: Path) -> CommandModelFactory:
        """A factory of the :class:`~pcmb.adapters.command.model.CommandModel`."""
        return CommandModelFactory(
            command=tuple(self.command),
            params=dict(self.params),
            outputs=tuple(self.outputs),
            output_file=self.output.file,
            output_format=self.output.format,
            templates=tuple(self.templates),
            files=tuple(self.files),
            base_dir=base_dir,
            timeout=self.timeout,
            run_dir=None if self.run_dir is None else Path(self.run_dir).resolve(),
            keep=self.keep,
            time_column=self.output.time_column,
            axis=None if self.output.axis is None else self.output.axis.axis(),
            axis_column="frequency" if self.output.axis is None else self.output.axis.column,
        )

    @property
    def output_names(self) -> tuple[str, ...]:
        """``outputs``: a command model has exactly these."""
        return tuple(self.outputs)
