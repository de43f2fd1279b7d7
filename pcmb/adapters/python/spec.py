"""The ``model:`` section of ``kind: python``."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import Field

from pcmb.adapters.python.model import PythonModelFactory
from pcmb.config.types import ModelSection, Name, NameList

__all__ = ["PythonModelSpec"]


class PythonModelSpec(ModelSection):
    """``kind: python``: a class, model object, factory or marked function from an entry point."""

    kind: Literal["python"]
    entry: str = Field(description="path/to/file.py:Name (relative to the config) or pkg.mod:Name")
    params: dict[Name, Any] = Field(
        default_factory=dict,
        description="nominal parameters (constructor keywords, or every parameter of a function)",
    )
    outputs: NameList | None = Field(default=None, description="outputs to keep (default: all)")
    files: list[str] = Field(
        default_factory=list,
        description="further files the model reads (data, scripts), relative to the config: "
        "a resumed run refuses to continue when one changed",
    )

    def factory(self, base_dir: Path) -> PythonModelFactory:
        """A factory that loads the entry and builds the model (see :func:`as_model`)."""
        outputs = None if self.outputs is None else tuple(self.outputs)
        return PythonModelFactory(
            self.entry, base_dir, dict(self.params), outputs, tuple(self.files)
        )

    @property
    def output_names(self) -> tuple[str, ...] | None:
        """``outputs``, or ``None`` for every output of the model."""
        return None if self.outputs is None else tuple(self.outputs)
