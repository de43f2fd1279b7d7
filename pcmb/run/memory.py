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

``execution.memory`` (:class:`MemoryBudget`) bounds that estimate. A sampling study over the
budget *streams* (:class:`StreamPlan`): its runs stay in the journal and go to the result file
block by block while their statistics accumulate (``docs/benchmarks.md``, "Streaming"); any
other study over the budget is refused before anything runs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from pcmb.errors import ConfigProblem, UsageError
from pcmb.run.output import format_bytes

__all__ = [
    "COPIES",
    "DEFAULT_MEMORY",
    "DRAW_COPIES",
    "MemoryBudget",
    "MemoryEstimate",
    "StreamPlan",
    "available_memory",
    "check_memory",
    "parse_memory",
]

#: Copies of the values array (nodes and held-out runs) pcmb's process holds at its peak.
COPIES = 7
#: Copies of the range check's (draws, W) surrogate values, one output at a time.
DRAW_COPIES = 2
_FLOAT = 8
#: ``execution.memory`` when not given: a share of the memory available, leaving the rest to
#: the workers (each holds about three copies of its chunk) and to the system.
DEFAULT_MEMORY = "80%"
_UNITS = {
    "": 1,
    "b": 1,
    "kb": 10**3,
    "mb": 10**6,
    "gb": 10**9,
    "tb": 10**12,
    "kib": 2**10,
    "mib": 2**20,
    "gib": 2**30,
    "tib": 2**40,
}
_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([a-z]*|%)\s*")
#: A streamed study's reservoir of runs (quantiles, PDFs, spectra), at most: the standard
#: error of a 5 % quantile's probability level is then sqrt(0.05 · 0.95 / 10 000) = 0.0022.
RESERVOIR_ROWS = 10_000
#: Fewest runs a reservoir may hold (below, a streamed study is refused).
MIN_RESERVOIR_ROWS = 100
#: Copies of the reservoir at the peak of the analysis (it, a sorted transpose, a draw).
_RESERVOIR_COPIES = 3
#: Bytes of one block of streamed runs, at most (and an eighth of the budget).
_BLOCK_BYTES = 64 * 10**6
#: Bytes pcmb's process keeps per node while streaming: germ, params and the model's copy of
#: the params per input; the status and the journal's record of each node.
_PER_INPUT = 3 * _FLOAT
_PER_NODE = 1 + _FLOAT


@dataclass(frozen=True)
class MemoryBudget:
    """``execution.memory``: a size in bytes (``size``) or a share of the memory available
    (``share``, in (0, 1]); exactly one is given. ``text`` is the setting as written."""

    text: str
    size: int | None = None
    share: float | None = None

    def limit(self, available: int) -> int:
        """The bytes pcmb's process may use, given the bytes ``available``."""
        return self.size if self.size is not None else int(self.share * available)

    def describe(self, available: int) -> str:
        """The budget for a message: ``"execution.memory: 80% of the 20.1 GB available"``."""
        if self.size is not None:
            return f"execution.memory: {self.text}"
        return f"execution.memory: {self.text} of the {format_bytes(available)} available"


def parse_memory(value: str | int) -> MemoryBudget:
    """``execution.memory`` from its setting: bytes (``2000000000``), a size with a unit
    (``"2GB"``, ``"512 MiB"``: kB, MB, GB, TB in powers of 1000, KiB... in powers of 1024),
    or a percentage of the memory available (``"80%"``).

    Raises
    ------
    ValueError
        For anything else, a size of 0 or a percentage outside (0, 100].
    """
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise ValueError(f"expected a size such as 2GB or a percentage such as 80%, got {value!r}")
    text = str(value)
    found = _SIZE.fullmatch(text.lower())
    if found is None or found[2] not in (*_UNITS, "%"):
        raise ValueError(
            f"expected a size such as 2GB, 512MiB or 2000000000 (bytes), or a percentage of "
            f"the memory available such as 80%, got {text!r}"
        )
    number = float(found[1])
    if found[2] == "%":
        if not 0 < number <= 100:
            raise ValueError(f"a percentage must be in (0, 100], got {text!r}")
        return MemoryBudget(text.strip(), share=number / 100)
    size = int(number * _UNITS[found[2]])
    if size < 1:
        raise ValueError(f"must be at least 1 byte, got {text!r}")
    return MemoryBudget(text.strip(), size=size)


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


@dataclass(frozen=True)
class StreamPlan:
    """How a study over its memory budget streams: ``block_rows`` runs per block of the
    pass over the journal, ``reservoir_rows`` runs kept for quantiles, PDFs and spectra."""

    block_rows: int
    reservoir_rows: int


def check_memory(
    estimate: MemoryEstimate,
    budget: MemoryBudget,
    *,
    inputs: int = 1,
    streams: str | None = None,
) -> tuple[int, StreamPlan | None]:
    """Check, before anything runs, that ``estimate`` fits in ``budget``, or how the study
    streams when it does not and can (``streams`` is ``None``; otherwise why it cannot).

    Parameters
    ----------
    inputs:
        The study's inputs (the columns of its node arrays, held while streaming).

    Returns
    -------
    available, plan
        The bytes available, and ``None`` (held in memory) or the :class:`StreamPlan`.

    Raises
    ------
    UsageError
        At ``times``, naming ``execution.memory``, with the bytes needed and allowed and how
        they are made: the study does not fit and cannot stream, or even streamed it would
        not keep :data:`MIN_RESERVOIR_ROWS` runs within the budget.
    """
    available = available_memory()
    limit = budget.limit(available)
    if estimate.total <= limit:
        return available, None
    needs = (
        f"the run needs about {format_bytes(estimate.total)} of memory, more than the "
        f"{format_bytes(limit)} it may use ({budget.describe(available)}): {estimate.describe()}"
    )
    row = estimate.width * estimate.outputs * _FLOAT
    block = min(_BLOCK_BYTES, limit // 8)
    fixed = estimate.nodes * (inputs * _PER_INPUT + _PER_NODE) + 2 * block
    rows = min(estimate.nodes, RESERVOIR_ROWS, max(0, limit - fixed) // (_RESERVOIR_COPIES * row))
    if streams is None and rows >= min(estimate.nodes, MIN_RESERVOIR_ROWS):
        return available, StreamPlan(max(1, block // row), int(rows))
    why = (
        f"; streamed, it would keep fewer than {MIN_RESERVOIR_ROWS} runs for its quantiles"
        if streams is None
        else f"; it cannot stream ({streams})"
    )
    raise UsageError(
        [
            ConfigProblem(
                "times",
                f"{needs}{why}: raise execution.memory, give fewer time points "
                "(time.points), nodes or outputs, or use a machine with more memory",
            )
        ],
        source="Study",
    )
