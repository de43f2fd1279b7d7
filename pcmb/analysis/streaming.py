"""Statistics of runs streamed from the journal: one pass in node order, fixed blocks.

The runs come record by record (:meth:`pcmb.run.journal.Journal.chunks`); the successful ones
are regrouped into blocks of a fixed number of runs in node order, so the running moments and
the reservoir see the same blocks however the runs were cut into records (an uninterrupted
run, a resumed one, retries): their numbers are the same to the last bit.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.reservoir import Reservoir
from pcmb.analysis.running_moments import RunningMoments
from pcmb.result import Status

__all__ = ["stream_statistics"]


def stream_statistics(
    chunks: Iterable[tuple[NDArray[np.int64], Mapping[str, NDArray[np.float64]], NDArray]],
    widths: Mapping[str, int],
    block_rows: int,
    reservoir_rows: int,
    seed: int = 0,
) -> tuple[dict[str, RunningMoments], Reservoir]:
    """Every output's running mean and std over the successful runs, and a reservoir of
    ``reservoir_rows`` of them (every output side by side, in the order of ``widths``,
    labelled by node index).

    Parameters
    ----------
    chunks:
        (B,) increasing node indices, output name -> (B, W) values, (B,) statuses; in node
        order.
    widths:
        Output name -> its columns W.
    block_rows:
        Runs per block.
    """
    moments = {name: RunningMoments(width) for name, width in widths.items()}
    reservoir = Reservoir(reservoir_rows, sum(widths.values()), seed)
    ends = np.cumsum([0, *widths.values()]).tolist()

    def take(rows: NDArray[np.float64], index: NDArray[np.int64]) -> None:
        for moment, a, b in zip(moments.values(), ends, ends[1:], strict=False):
            moment.add(rows[:, a:b])
        reservoir.add(rows, index)

    parts: list[tuple[NDArray[np.float64], NDArray[np.int64]]] = []
    held = 0
    for indices, values, status in chunks:
        ok = status == Status.OK
        parts.append((np.concatenate([values[name][ok] for name in widths], axis=1), indices[ok]))
        held += int(ok.sum())
        if held < block_rows:
            continue
        rows = np.concatenate([part[0] for part in parts])
        index = np.concatenate([part[1] for part in parts])
        whole = held - held % block_rows
        for start in range(0, whole, block_rows):
            take(rows[start : start + block_rows], index[start : start + block_rows])
        parts, held = [(rows[whole:], index[whole:])], held - whole
    if held:
        take(np.concatenate([part[0] for part in parts]), np.concatenate([p[1] for p in parts]))
    return moments, reservoir
