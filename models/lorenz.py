"""Lorenz system (Part II Eq. 26–27).

    x' = σ (y − x),  y' = x (ρ − z) − y,  z' = x y − β z.

For ρ > 1 the equilibria (±√(β(ρ−1)), ±√(β(ρ−1)), ρ − 1) exist; they attract for σ = 1,
ρ = 10, β = 1 (the paper's stable case), and Lorenz's σ = 10, ρ = 28, β = 8/3 is chaotic.
Loaded by pcmb as ``entry: ../models/lorenz.py:Lorenz``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.integrate.stacked_ode import StackedODEModel

Params = Mapping[str, NDArray[np.float64]]

# Lorenz's chaotic parameters; the initial state is the middle of the paper's cube
# [0, 1] × [0, 1] × [14.5, 15.5].
_DEFAULTS = {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0, "x0": 0.5, "y0": 0.5, "z0": 15.0}


class Lorenz(StackedODEModel):
    """The Lorenz system from (x0, y0, z0); batched.

    Parameters
    ----------
    rtol, atol:
        Per-node DOP853 tolerances.
    **params:
        Nominal values: sigma (10), rho (28), beta (8/3), x0 (0.5), y0 (0.5), z0 (15).

    Notes
    -----
    Outputs: ``x``, ``y``, ``z``.

    Accuracy: rtol = 1e-10, atol = 1e-10 by default, per node whatever the batch size. In
    the stable case every node agrees with a tight separate run (DOP853, rtol 1e-11) to
    within 100·rtol of the solution's scale over 0–15. In the chaotic case an error grows on
    average like e^{0.906 t} (the largest Lyapunov exponent): up to t = 5 a node is within
    100·rtol·e^{0.906 t} of the scale; later the finite-time stretching of single
    trajectories outruns that average and by t = 15 single trajectories are off by up to a
    few 1e-2 at any practical tolerance -- only the statistics stay meaningful
    (tests/test_models_lorenz.py).

    Raises
    ------
    ValueError
        An unknown parameter or a non-finite value.
    """

    outputs: ClassVar[tuple[str, ...]] = ("x", "y", "z")

    def __init__(self, *, rtol: float = 1e-10, atol: float = 1e-10, **params: float) -> None:
        super().__init__(_DEFAULTS, params, rtol=rtol, atol=atol)

    def _initial_state(self, p: Params) -> NDArray[np.float64]:
        return np.stack([p["x0"], p["y0"], p["z0"]])

    def _rhs(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        x, yy, z = y
        return np.stack([p["sigma"] * (yy - x), x * (p["rho"] - z) - yy, x * yy - p["beta"] * z])

    def _observe(
        self, times: NDArray[np.float64], states: NDArray[np.float64], p: Params
    ) -> dict[str, NDArray[np.float64]]:
        x, y, z = states
        return {"x": x, "y": y, "z": z}
