"""What became of each node: its status code and, for a failed run, why and where.

Kept apart from :mod:`pcmb.result` so that worker processes, which report nodes, need not
import the chaos machinery the result holds.
"""

from __future__ import annotations

import dataclasses
import enum
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pcmb.wording import plural

__all__ = ["ModelTraceback", "NodeFailure", "Status", "failure_report"]


class Status(enum.IntEnum):
    """The state of a node, with the codes stored in ``/nodes/status``."""

    PENDING = 0
    OK = 1
    FAILED = 2


@dataclass(frozen=True)
class ModelTraceback:
    """Where the model's code raised: its exception and the frames of the model's own code.

    Attributes
    ----------
    error:
        The exception's type name, ``"KeyError"``.
    file:
        The file of the innermost frame of the model's code (absolute, as Python names it).
    line:
        Its line number.
    function:
        The name of its function.
    text:
        The traceback as Python prints it (file, line and code of every frame), trimmed to
        the model's frames (see :func:`pcmb.run.tracebacks.model_traceback`).
    """

    error: str
    file: str
    line: int
    function: str
    text: str

    @property
    def where(self) -> str:
        """``helpers.py:12 in rate()``."""
        return f"{os.path.basename(self.file)}:{self.line} in {self.function}()"

    def describe(self) -> dict[str, Any]:
        """The record as JSON-ready values (read back by :meth:`from_description`)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_description(cls, description: Mapping[str, Any]) -> ModelTraceback:
        return cls(**{field.name: description[field.name] for field in dataclasses.fields(cls)})


@dataclass(frozen=True)
class NodeFailure:
    """A node whose model run failed.

    Attributes
    ----------
    index:
        The node's index in the full node set.
    params:
        The node's values of the uncertain inputs (a tuple for a field input).
    message:
        The model's message (exception type and text), ``"non-finite output 'x1' at t=..."``,
        or ``"worker process died (...)"``.
    traceback:
        Where the model's code raised, when it did (``None`` for the other failures, and in
        files written before pcmb kept tracebacks).
    run:
        What the run was, as messages name it: ``"node"`` (of the design), or ``"held-out
        run"`` (numbered among the held-out runs).
    """

    index: int
    params: dict[str, float | tuple[float, ...]]
    message: str
    traceback: ModelTraceback | None = None
    run: str = "node"

    @property
    def node(self) -> str:
        """``node 3 (a=0.5, b=2)``, or ``held-out run 3 (…)``."""
        values = ", ".join(f"{name}={_format_value(v)}" for name, v in self.params.items())
        return f"{self.run} {self.index} ({values})"

    @property
    def cause(self) -> tuple[str, ...]:
        """What the failures of one cause share: the exception's type and the innermost frame
        of the model's code (file, line), or, without a traceback, the message."""
        if self.traceback is None:
            return (self.message,)
        return (self.traceback.error, self.traceback.file, str(self.traceback.line))

    def __str__(self) -> str:
        where = "" if self.traceback is None else f" at {self.traceback.where}"
        return f"{self.node}: {' '.join(self.message.split())}{where}"


def failure_report(failures: Sequence[NodeFailure], label: str = "") -> list[str]:
    """Lines that report failed nodes once per cause (:attr:`NodeFailure.cause`): the first
    failure of each cause with its traceback, then the other nodes of that cause on one line.
    The lines of a failure start with ``label``, its traceback's are indented below it."""
    causes: dict[tuple[str, ...], list[NodeFailure]] = {}
    for failure in failures:
        causes.setdefault(failure.cause, []).append(failure)
    indent = " " * len(label) + "  "
    lines = []
    for first, *others in causes.values():
        lines.append(f"{label}{first}")
        if first.traceback is not None:
            text = first.traceback.text.rstrip("\n")
            lines += [indent + line if line else "" for line in text.splitlines()]
        if others:
            lines.append(
                f"{label}and {plural(len(others), f'more {first.run}', f'more {first.run}s')} "
                "with the same error: " + ", ".join(other.node for other in others)
            )
    return lines


def _format_value(value: float | tuple[float, ...]) -> str:
    if isinstance(value, tuple):
        shown = ", ".join(f"{v:.6g}" for v in value[:3])
        return f"[{shown}, ... ({len(value)} values)]" if len(value) > 3 else f"[{shown}]"
    return f"{value:.6g}"
