"""The adapter kinds (``model.kind``): where each one's config section lives, in one table.

The config schema builds its ``model:`` union from :data:`ADAPTERS`, and messages, ``pcmb
validate`` and the docs list the kinds from it. A new adapter is one module or subpackage
in ``pcmb/adapters/``, one entry here, and its tests (``tests/test_adapter_contract.py``).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pcmb.config.types import ModelSection

__all__ = ["ADAPTERS", "AdapterEntry", "adapter_kinds", "spec_class"]


@dataclass(frozen=True)
class AdapterEntry:
    """One adapter kind.

    Attributes
    ----------
    spec:
        ``"module:Class"`` of its config section, a
        :class:`~pcmb.config.types.ModelSection` with ``kind: Literal["<kind>"]`` whose
        ``factory(base_dir)`` builds a :class:`~pcmb.adapters.protocol.ModelFactory`.
        Imported on first use, so that the registry costs nothing to import.
    summary:
        One line for listings.
    """

    spec: str
    summary: str

    def spec_class(self) -> type[ModelSection]:
        """The config section class (imports its module)."""
        module, _, name = self.spec.partition(":")
        return getattr(importlib.import_module(module), name)


#: ``model.kind`` -> adapter, in the order listings show them.
ADAPTERS: dict[str, AdapterEntry] = {
    "python": AdapterEntry(
        "pcmb.adapters.python.spec:PythonModelSpec",
        "a Python class, model object, model factory or marked function (entry: file.py:Name)",
    ),
    "mujoco": AdapterEntry(
        "pcmb.adapters.mujoco.spec:MujocoModelSpec",
        "an MJCF scene run by MuJoCo; inputs are placeholders, bound fields or initial states",
    ),
    "command": AdapterEntry(
        "pcmb.adapters.command.spec:CommandModelSpec",
        "an external program run once per node in its own work directory",
    ),
    "fmu": AdapterEntry(
        "pcmb.adapters.fmu.spec:FmuModelSpec",
        "a Functional Mock-up Unit (FMI 2.0/3.0) run through FMPy, instantiated once per worker",
    ),
}


def adapter_kinds() -> tuple[str, ...]:
    """Every ``model.kind``, in registry order."""
    return tuple(ADAPTERS)


def spec_class(kind: str) -> type[ModelSection]:
    """The config section class of ``kind``.

    Raises
    ------
    KeyError
        An unknown kind.
    """
    return ADAPTERS[kind].spec_class()
