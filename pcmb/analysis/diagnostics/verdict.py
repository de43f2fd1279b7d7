"""The verdict: the first time an estimated error exceeds the tolerance by more than its noise."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import STANDARD_NORMAL, HeldOutCheck

#: Default accepted error, relative to the output's largest standard deviation.
TOLERANCE = 0.05


def verdict(
    times: ArrayLike, estimate: ArrayLike, tolerance: float = TOLERANCE, noise: ArrayLike = 0.0
) -> float:
    """The first time at which the estimated error exceeds the tolerance by more than its
    ``noise`` (NaN if never)."""
    lower = np.asarray(estimate, dtype=float) - np.asarray(noise, dtype=float)
    above = np.flatnonzero(lower > tolerance)
    return float(np.asarray(times, dtype=float)[above[0]]) if above.size else float("nan")


def flag_margin(checked: HeldOutCheck, tolerance: float) -> NDArray[np.float64]:
    """(T,) how far the held-out estimate must pass the tolerance to be flagged: m times its
    standard error s, where an error at the tolerance itself, estimated as ê ~ N(tolerance,
    s²), has a sign-free |ê| beyond tolerance + m s with probability Φ(-m) + Φ(-m - 2
    tolerance / s) = 1 - confidence. m is the one-sided quantile (1.28 at 90 %) where s is
    small against the tolerance, the two-sided one (1.64) where it is large: there |ê| passes
    the tolerance by 1.28 s on either side of a truth near zero, twice as often as the
    confidence allows. Found by bisection; infinite where s is unknown (NaN)."""
    tail = np.frompyfunc(lambda x: 0.5 * math.erfc(x / math.sqrt(2.0)), 1, 1)
    miss = 1.0 - checked.confidence
    spread = np.where(np.isnan(checked.spread), np.inf, checked.spread)
    edge = np.divide(2.0 * tolerance, spread, out=np.full(spread.shape, np.inf), where=spread > 0)
    low = np.full(spread.shape, STANDARD_NORMAL.inv_cdf(1.0 - miss))
    high = np.full(spread.shape, STANDARD_NORMAL.inv_cdf(1.0 - miss / 2.0))
    for _ in range(40):
        middle = 0.5 * (low + high)
        beyond = (tail(middle) + tail(middle + edge)).astype(float) > miss
        low, high = np.where(beyond, middle, low), np.where(beyond, high, middle)
    return high * spread
