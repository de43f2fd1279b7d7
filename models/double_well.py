"""Double-well problem x' = x − x³ (Part II Eq. 25).

Stable equilibria at x = ±1, an unstable one at 0: every x0 < 0 flows to −1 and every x0 > 0
to +1, so an initial distribution straddling 0 ends as two Dirac peaks. Loaded by pcmb as
``entry: ../models/double_well.py:DoubleWell``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.integrate.stacked_ode import StackedODEModel

Params = Mapping[str, NDArray[np.float64]]


class DoubleWell(StackedODEModel):
    """x' = x − x³ from x(0) = x0; batched.

    Parameters
    ----------
    rtol, atol:
        Per-node DOP853 tolerances.
    **params:
        Nominal value of ``x0``: −0.125, the middle of the paper's U[−0.625, 0.375].

    Notes
    -----
    Output: ``x``. Exact solution x0 eᵗ / √(1 + x0² (e^{2t} − 1)).

    Accuracy: rtol = 1e-10, atol = 1e-12 by default, per node whatever the batch size; each
    node then agrees with the exact solution to within 100·rtol (1e-8) over 0–4
    (tests/test_models_double_well.py).

    Raises
    ------
    ValueError
        An unknown parameter or a non-finite value.
    """

    outputs: ClassVar[tuple[str, ...]] = ("x",)

    def __init__(self, *, rtol: float = 1e-10, atol: float = 1e-12, **params: float) -> None:
        super().__init__({"x0": -0.125}, params, rtol=rtol, atol=atol)

    def _initial_state(self, p: Params) -> NDArray[np.float64]:
        return p["x0"][None, :]

    def _rhs(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        return y - y * y * y

    def _observe(
        self, times: NDArray[np.float64], states: NDArray[np.float64], p: Params
    ) -> dict[str, NDArray[np.float64]]:
        return {"x": states[0]}
