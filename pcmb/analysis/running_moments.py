"""Mean and standard deviation of runs met block by block, never all held at once.

Each block's mean and sum of squared deviations (two-pass within the block) are merged into
the running ones by the pairwise update of Chan, Golub and LeVeque (1979), which extends
Welford's one-at-a-time update to blocks:
``n = n_a + n_b``, ``δ = m_b − m_a``, ``m = m_a + δ n_b / n``,
``M2 = M2_a + M2_b + δ² n_a n_b / n``. Its round-off stays at the level of the two-pass
formula over all runs (no ``E[y²] − E[y]²`` cancellation); a column whose runs are all equal
has std exactly 0, as :func:`pcmb.chaos.expansion.sample_std` gives it. Values are kept in
units of a power of two near each column's largest magnitude so far (rescaled, exactly, when
a larger one comes), so squares of values near the float limits neither overflow nor
underflow, as in ``sample_std``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["RunningMoments"]


class RunningMoments:
    """Running mean and variance over the rows of the blocks given to :meth:`add`.

    Parameters
    ----------
    width:
        Columns of every block (W).
    """

    def __init__(self, width: int):
        self.count = 0
        self._mean = np.zeros(width)
        self._squares = np.zeros(width)  # the sum of squared deviations from the mean, M2
        self._first: NDArray[np.float64] | None = None
        self._constant = np.ones(width, dtype=bool)
        self._scale = np.zeros(width)  # per column a power of two, the units of mean and M2

    def add(self, block: ArrayLike) -> None:
        """Take the rows of a (b, W) ``block``."""
        block = np.asarray(block, dtype=float)
        size = block.shape[0]
        if size == 0:
            return
        if self._first is None:
            self._first = block[0].copy()
        self._constant &= np.all(block == self._first, axis=0)
        magnitude = np.abs(block).max(axis=0, where=np.isfinite(block), initial=0.0)
        scale = np.fmax(self._scale, np.ldexp(1.0, np.frexp(magnitude)[1]))
        ratio = self._scale / scale  # a power of two: the rescaling is exact
        self._mean *= ratio
        self._squares *= ratio**2
        self._scale = scale
        block = block / scale
        mean = block.mean(axis=0)
        squares = ((block - mean) ** 2).sum(axis=0)
        total = self.count + size
        delta = mean - self._mean
        self._mean += delta * (size / total)
        self._squares += squares + delta**2 * (self.count * size / total)
        self.count = total

    @property
    def mean(self) -> NDArray[np.float64]:
        """(W,) the mean of the rows so far (NaN before any)."""
        return self._mean * self._scale if self.count else np.full(self._mean.shape, np.nan)

    def std(self, ddof: int = 1) -> NDArray[np.float64]:
        """(W,) the standard deviation of the rows so far, exactly 0 where they are all
        equal (NaN with ``ddof`` rows or fewer)."""
        if self.count <= ddof:
            return np.full(self._mean.shape, np.nan)
        spread = np.sqrt(self._squares / (self.count - ddof)) * self._scale
        return np.where(self._constant, 0.0, spread)
