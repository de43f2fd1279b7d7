"""Whether a run fits in memory: an upper estimate of what pcmb's own process holds at its
peak, checked against the memory available before anything runs (as the disk space is, see
:mod:`pcmb.run.output`).

The estimate's model, measured on the pipeline (tracemalloc, N = 64 and 512 nodes, 2 outputs,
20 000 to 160 000 times): at its peak pcmb's process holds 5.6 to 6.1 copies of the values
array of the nodes *and* the held-out runs (the runs, the chaos coefficients, the statistics'
squares, and, while the result file is written, its HDF5 image in memory and that image's
bytes), counted here as :data:`COPIES`; besides, the range check of the diagnostics
(:func:`pcmb.analysis.diagnostics.out_of_range`) evaluates each output's surrogate at a few
thousand draws at every time at once, 1.3 to 1.5 times that array, counted as
:data:`DRAW_COPIES`. Workers hold at most about three copies of their chunks, all of them
together fewer nodes than the run, while pcmb's process holds one copy: below its peak.
"""

from __future__ import annotations

from dataclasses import dataclass

from pcmb.errors import ConfigProblem, UsageError
from pcmb.run.output import format_bytes

__all__ = ["COPIES", "DRAW_COPIES", "MemoryEstimate", "available_memory", "check_memory"]

#: Copies of the values array (nodes and held-out runs) pcmb's process holds at its peak.
COPIES = 7
#: Copies of the range check's (draws, W) surrogate values, one output at a time.
DRAW_COPIES = 2
_FLOAT = 8


@dataclass(frozen=True)
class MemoryEstimate:
    """An upper estimate of the bytes pcmb's process needs at its peak (module docstring).

    Attributes
    ----------
    nodes, held_out:
        The runs whose values are kept: the nodes (of all rounds) and the held-out runs.
    width:
        Values per run of the widest output (T on time).
    outputs:
        The outputs kept (derived ones included).
    draws:
        The surrogate draws of the range check (0 for a method without an expansion).
    """

    nodes: int
    held_out: int
    width: int
    outputs: int
    draws: int

    @property
    def values(self) -> int:
        """Bytes of one copy of every run's values."""
        return (self.nodes + self.held_out) * self.width * self.outputs * _FLOAT

    @property
    def total(self) -> int:
        return COPIES * self.values + DRAW_COPIES * self.draws * self.width * _FLOAT

    def describe(self) -> str:
        """How :attr:`total` is made, for a message."""
        text = (
            f"{COPIES} copies of the values of {self.nodes + self.held_out} runs ({self.nodes} "
            f"nodes + {self.held_out} held-out) × {self.width} times × {self.outputs} outputs "
            f"× 8 bytes = {format_bytes(self.values)} each"
        )
        if self.draws:
            text += (
                f", and {DRAW_COPIES} copies of the range check's {self.draws} surrogate draws "
                f"× {self.width} times × 8 bytes"
            )
        return text


def available_memory() -> int:
    """Bytes the system can give a process without swapping (``MemAvailable`` on Linux)."""
    import psutil

    return int(psutil.virtual_memory().available)


def check_memory(estimate: MemoryEstimate) -> int:
    """Check, before anything runs, that ``estimate`` fits in the memory available.

    Returns
    -------
    int
        The bytes available.

    Raises
    ------
    UsageError
        At ``times``, with the bytes needed and available and how they are made.
    """
    available = available_memory()
    if estimate.total > available:
        raise UsageError(
            [
                ConfigProblem(
                    "times",
                    f"the run needs about {format_bytes(estimate.total)} of memory, more than "
                    f"the {format_bytes(available)} available: {estimate.describe()}; give "
                    "fewer time points (time.points), nodes or outputs, or use a machine with "
                    "more memory",
                )
            ],
            source="Study",
        )
    return available
