"""How the diagnostics' records word times and shares."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def time_count(where: NDArray[np.bool_]) -> str:
    """``"3 of 50 times"``: how many of the (T,) times ``where`` holds."""
    return f"{int(where.sum())} of {where.size} times"


def time_span(times: NDArray[np.float64], where: NDArray[np.bool_]) -> tuple[float, float]:
    """The first and last of the ``times`` where ``where`` holds."""
    found = np.flatnonzero(where)
    return float(times[found[0]]), float(times[found[-1]])


def as_percent(share: float) -> str:
    """A share in percent, two significant digits ("5.6 %", "12 %", "110 %")."""
    percent = 100 * share
    return f"{percent:.0f} %" if abs(percent) >= 100 else f"{percent:.2g} %"
