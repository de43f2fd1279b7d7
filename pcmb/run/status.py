"""What became of each node: its status code and, for a failed run, why.

Kept apart from :mod:`pcmb.result` so that worker processes, which report nodes, need not
import the chaos machinery the result holds.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["NodeFailure", "Status"]


class Status(enum.IntEnum):
    """The state of a node, with the codes stored in ``/nodes/status``."""

    PENDING = 0
    OK = 1
    FAILED = 2


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
    """

    index: int
    params: dict[str, float | tuple[float, ...]]
    message: str

    def __str__(self) -> str:
        values = ", ".join(f"{name}={_format_value(v)}" for name, v in self.params.items())
        return f"node {self.index} ({values}): {' '.join(self.message.split())}"


def _format_value(value: float | tuple[float, ...]) -> str:
    if isinstance(value, tuple):
        shown = ", ".join(f"{v:.6g}" for v in value[:3])
        return f"[{shown}, ... ({len(value)} values)]" if len(value) > 3 else f"[{shown}]"
    return f"{value:.6g}"
