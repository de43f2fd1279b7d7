"""A uniform random sample of a fixed number of runs from a stream of runs too many to hold.

Reservoir sampling (Vitter's algorithm R): the first ``size`` rows fill the reservoir; the
i-th row after them (0-based position i in the stream) replaces a row chosen uniformly when
a uniform draw from {0, ..., i} falls below ``size``. Every subset of ``size`` rows of the
stream is then equally likely, so the reservoir is a simple random sample of the runs, and
whole rows are kept: every time point (and output) of a kept run, so quantiles, PDFs and
spectra of the sample describe the same runs. Its quantiles are those of a sample of
``size`` runs: the probability level of the p-quantile has a standard error of
sqrt(p (1 − p) / size) (0.0022 at p = 0.05 for 10 000 rows); with ``size`` at least the
stream's length the reservoir holds every run and its quantiles are exact. The draws come
from a seeded generator in stream order, so the same stream in the same blocks gives the
same reservoir.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Reservoir"]


class Reservoir:
    """A uniform sample of ``size`` rows (of ``width`` columns) of the rows given to
    :meth:`add`, with their ``index`` (any per-row label, e.g. the node index)."""

    def __init__(self, size: int, width: int, seed: int = 0):
        if size < 1:
            raise ValueError(f"a reservoir holds at least one row, got size {size}")
        self.seen = 0
        self._rows = np.empty((size, width))
        self._index = np.empty(size, dtype=np.int64)
        self._random = np.random.default_rng(seed)

    def add(self, block: ArrayLike, index: ArrayLike) -> None:
        """Offer the rows of a (b, W) ``block``, labelled by (b,) ``index``."""
        block, index = np.asarray(block, dtype=float), np.asarray(index, dtype=np.int64)
        size = self._rows.shape[0]
        fill = max(0, min(block.shape[0], size - self.seen))
        self._rows[self.seen : self.seen + fill] = block[:fill]
        self._index[self.seen : self.seen + fill] = index[:fill]
        positions = self.seen + np.arange(fill, block.shape[0])
        slots = self._random.integers(0, positions + 1) if positions.size else positions
        for row in np.flatnonzero(slots < size):  # in stream order: a later row wins a slot
            self._rows[slots[row]] = block[fill + row]
            self._index[slots[row]] = index[fill + row]
        self.seen += block.shape[0]

    @property
    def rows(self) -> NDArray[np.float64]:
        """(min(seen, size), W) the sampled rows."""
        return self._rows[: min(self.seen, self._rows.shape[0])]

    @property
    def index(self) -> NDArray[np.int64]:
        """The labels of :attr:`rows`."""
        return self._index[: min(self.seen, self._index.shape[0])]
