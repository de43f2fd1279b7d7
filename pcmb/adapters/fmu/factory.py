"""The picklable factory of an FMU model; importing it does not import fmpy."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from pcmb.adapters.protocol import ModelFactory
from pcmb.errors import MissingDependencyError

if TYPE_CHECKING:
    from pcmb.adapters.fmu.model import FmuModel

__all__ = ["INTERFACES", "FmuModelFactory", "Interface"]

Interface = Literal["co-simulation", "model-exchange"]
#: ``model.interface`` values.
INTERFACES: tuple[str, ...] = ("co-simulation", "model-exchange")


@dataclass(frozen=True)
class FmuModelFactory(ModelFactory):
    """Builds an :class:`~pcmb.adapters.fmu.model.FmuModel`; the fields are its arguments.

    Each worker calls it once: the FMU is extracted and instantiated once per worker.
    """

    fmu: Path
    params: Mapping[str, float | int | bool] = field(default_factory=dict)
    bind: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    outputs: tuple[str, ...] | None = None
    units: Mapping[str, str] = field(default_factory=dict)
    interface: Interface | None = None
    rtol: float | None = None

    def model_files(self) -> list[Path]:
        """The ``.fmu`` archive, or every file of an extracted FMU's folder."""
        path = Path(self.fmu)
        if path.is_dir():
            return sorted(p.resolve() for p in path.rglob("*") if p.is_file())
        return [path.resolve()] if path.is_file() else []

    def __call__(self) -> FmuModel:
        """Read, check, extract and instantiate the FMU.

        Raises
        ------
        MissingDependencyError
            fmpy is not installed (``pip install "pcmb[fmu]"``).
        ConfigError
            As :class:`~pcmb.adapters.fmu.model.FmuModel`.
        """
        try:
            from pcmb.adapters.fmu.model import FmuModel
        except ImportError as error:
            if error.name is not None and error.name.split(".")[0] == "fmpy":
                raise MissingDependencyError("fmpy", "fmu", "FMU models") from None
            raise
        return FmuModel(
            fmu=self.fmu,
            params=self.params,
            bind=self.bind,
            outputs=self.outputs,
            units=self.units,
            interface=self.interface,
            rtol=self.rtol,
        )
