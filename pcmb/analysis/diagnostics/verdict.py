"""The verdict: the first time an estimated error exceeds the tolerance by more than its noise."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import (
    HeldOutCheck,
    student_t_quantile,
    student_t_survival,
)

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
    standard error s, where an error at the tolerance itself, estimated as ê = tolerance + s T
    (T of Student's t law of the check's degrees of freedom: s is itself read from the runs;
    the normal's for a placed check), has a sign-free |ê| beyond tolerance + m s with
    probability P(T > m) + P(T > m + 2 tolerance / s) = 1 - confidence. m is the one-sided
    quantile (1.28 at 90 % for the normal, 1.38 for 10 drawn runs) where s is small against
    the tolerance, the two-sided one (1.64; 1.83) where it is large: there |ê| passes the
    tolerance by m s on either side of a truth near zero, twice as often as the confidence
    allows. Found by bisection; infinite where s is unknown (NaN)."""
    dof = float('inf')
    miss = 1.0 - checked.confidence
    spread = np.where(np.isnan(checked.spread), np.inf, checked.spread)
    edge = np.divide(2.0 * tolerance, spread, out=np.full(spread.shape, np.inf), where=spread > 0)
    low = np.full(spread.shape, student_t_quantile(1.0 - miss, dof))
    high = np.full(spread.shape, student_t_quantile(1.0 - miss / 2.0, dof))
    for _ in range(40):
        middle = 0.5 * (low + high)
        beyond = student_t_survival(middle, dof) + student_t_survival(middle + edge, dof) > miss
        low, high = np.where(beyond, middle, low), np.where(beyond, high, middle)
    return high * spread
