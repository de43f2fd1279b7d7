"""The command adapter (``model.kind: command``): an external program run once per node.

Its config section is :mod:`pcmb.adapters.command.spec`; this package imports no pydantic.
"""

from pcmb.adapters.command.model import CommandModel, CommandModelFactory, split_command

__all__ = ["CommandModel", "CommandModelFactory", "split_command"]
