"""The ``model:`` section of ``kind: mujoco``, in the binding language of :mod:`.binding`.
This module does not import mujoco."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Literal

from pydantic import Field

from pcmb.adapters.mujoco.binding import Bindings, InitSpec, Outputs
from pcmb.config.types import ModelSection, Name, Real

if TYPE_CHECKING:
    from pcmb.adapters.mujoco.model import MujocoModelFactory

__all__ = ["MujocoModelSpec"]


class MujocoModelSpec(ModelSection):
    """``kind: mujoco``: an MJCF scene."""

    kind: Literal["mujoco"]
    xml: str = Field(description="MJCF file, relative to the config; may hold {{ name }}")
    params: dict[Name, Real] = Field(
        default_factory=dict,
        description="nominal values of the {{ name }} placeholders and of bound inputs",
    )
    bind: Bindings = Field(
        default_factory=dict, description="input -> the MjModel fields or initial states it sets"
    )
    init: InitSpec = Field(default_factory=InitSpec)
    outputs: Outputs = Field(description="output name -> what it reads from the simulation")

    def factory(self, base_dir: Path) -> MujocoModelFactory:
        """A factory of the :class:`~pcmb.adapters.mujoco.model.MujocoModel` (imports mujoco)."""
        from pcmb.adapters.mujoco.model import MujocoModelFactory

        return MujocoModelFactory(
            xml=(base_dir / self.xml).resolve(),
            params=dict(self.params),
            bind={
                name: [entry.model_dump(exclude_none=True) for entry in entries]
                for name, entries in self.bind.items()
            },
            init=self.init.model_dump(),
            outputs={name: out.model_dump(exclude_none=True) for name, out in self.outputs.items()},
        )

    @property
    def output_names(self) -> tuple[str, ...]:
        """The names under ``outputs``: a scene has exactly these."""
        return tuple(self.outputs)

    @property
    def nominal_names(self) -> frozenset[str]:
        """Placeholders' nominal values and bound inputs (whose nominal the scene holds)."""
        return frozenset(self.params) | frozenset(self.bind)
