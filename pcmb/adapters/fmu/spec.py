"""The ``model:`` section of ``kind: fmu``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, Field
from pydantic_core import PydanticCustomError

from pcmb.adapters.fmu.factory import FmuModelFactory, Interface
from pcmb.config.types import ModelSection, Name, PositiveReal, unique

__all__ = ["FmuModelSpec"]


def _number_or_bool(value: Any) -> Any:
    """Start values are numbers or true/false, never text (``"1.5"``)."""
    if isinstance(value, str):
        raise PydanticCustomError("wrong_type", "expected a number, true or false")
    return value


Variable = Annotated[str, Field(min_length=1)]
StartValue = Annotated[bool | int | float, BeforeValidator(_number_or_bool)]
Variables = Annotated[list[Variable], Field(min_length=1), AfterValidator(unique)]


class FmuModelSpec(ModelSection):
    """``kind: fmu``: a Functional Mock-up Unit (FMI 2.0 or 3.0) run through FMPy."""

    kind: Literal["fmu"]
    fmu: str = Field(description="the .fmu file, relative to the config")
    params: dict[Variable, StartValue] = Field(
        default_factory=dict,
        description="FMU variable -> start value (parameters, inputs, initial states); "
        "an input under bind -> its nominal value",
    )
    bind: dict[Name, Variables] = Field(
        default_factory=dict,
        description="input -> the FMU variables it sets (default: the variable of its name)",
    )
    outputs: Variables | None = Field(
        default=None, description="FMU variables recorded (default: every output variable)"
    )
    units: dict[Variable, str] = Field(
        default_factory=dict, description="FMU variable -> unit, checked against the FMU's"
    )
    interface: Interface | None = Field(
        default=None,
        description="co-simulation or model-exchange (default: co-simulation if offered)",
    )
    rtol: PositiveReal | None = Field(
        default=None,
        description="relative tolerance (model exchange: CVode's; co-simulation: the FMU's)",
    )

    def factory(self, base_dir: Path) -> FmuModelFactory:
        """A factory of the :class:`~pcmb.adapters.fmu.model.FmuModel`."""
        return FmuModelFactory(
            fmu=(base_dir / self.fmu).resolve(),
            params=dict(self.params),
            bind={name: tuple(targets) for name, targets in self.bind.items()},
            outputs=None if self.outputs is None else tuple(self.outputs),
            units=dict(self.units),
            interface=self.interface,
            rtol=self.rtol,
        )

    @property
    def output_names(self) -> tuple[str, ...] | None:
        """``outputs``, or ``None`` for every output variable of the FMU."""
        return None if self.outputs is None else tuple(self.outputs)
