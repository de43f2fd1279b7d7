"""Simple pendulum as an ODE and as a DAE with projection (Part II Eq. 28–31).

The bob hangs from the origin on a massless rod of length L; θ is measured from the
downward vertical, and y points down: x = L sin θ, y = L cos θ. Loaded by pcmb as
``entry: ../models/pendulum.py:PendulumODE`` or ``...:PendulumDAE``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.integrate.stacked_ode import StackedODEModel, solve_projected

Params = Mapping[str, NDArray[np.float64]]

# Part II Eq. 28–31: g = 9.81 m/s², nominal L = 1 m, released from rest at θ0 = π/4.
_DEFAULTS = {"g": 9.81, "L": 1.0, "theta0": np.pi / 4, "omega0": 0.0}
_POSITIVE = frozenset({"g", "L"})


class PendulumODE(StackedODEModel):
    """Pendulum in its angle: θ'' = -(g/L) sin θ; batched.

    Parameters
    ----------
    rtol, atol:
        Per-node DOP853 tolerances (atol in rad and rad/s).
    **params:
        Nominal values: g (9.81 m/s²), L (1 m), theta0 (π/4 rad), omega0 (0 rad/s), the
        initial angle and angular velocity at t = 0.

    Notes
    -----
    Outputs: ``theta`` (rad), ``omega`` (rad/s), ``x`` = L sin θ and ``y`` = L cos θ (m).

    Accuracy: rtol = 1e-10, atol = 1e-12 by default, per node whatever the batch size. With
    them each node agrees with a tight separate run (DOP853, rtol 1e-11) to within 100·rtol
    (1e-8 rad) over 0–15 s; at rtol = 1e-12 the angle matches the exact elliptic-function
    solution to within 1e-8 rad over 0–15 s (tests/test_models_pendulum.py).

    Raises
    ------
    ValueError
        An unknown parameter or an invalid value (g and L must be positive).
    """

    outputs: ClassVar[tuple[str, ...]] = ("theta", "omega", "x", "y")
    _positive = _POSITIVE

    def __init__(self, *, rtol: float = 1e-10, atol: float = 1e-12, **params: float) -> None:
        super().__init__(_DEFAULTS, params, rtol=rtol, atol=atol)

    def _initial_state(self, p: Params) -> NDArray[np.float64]:
        return np.stack([p["theta0"], p["omega0"]])

    def _rhs(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        theta, omega = y
        return np.stack([omega, -(p["g"] / p["L"]) * np.sin(theta)])

    def _observe(
        self, times: NDArray[np.float64], states: NDArray[np.float64], p: Params
    ) -> dict[str, NDArray[np.float64]]:
        theta, omega = states
        length = p["L"][:, None]
        return {
            "theta": theta,
            "omega": omega,
            "x": length * np.sin(theta),
            "y": length * np.cos(theta),
        }


class PendulumDAE(StackedODEModel):
    """Pendulum in Cartesian coordinates, index-1 DAE with projection (Part I Eq. 4–6).

    States x, y, u = x', v = y' with

        x'' = -λ x,  y'' = g - λ y,  λ = (u² + v² + g y) / L²,

    the multiplier that keeps the twice-differentiated constraint x x'' + y y'' + u² + v² = 0.
    The integrator (:func:`pcmb.integrate.stacked_ode.solve_projected`, Dormand–Prince 5(4), error
    controlled per node) takes one step at a time, and after every accepted step projects the
    state onto the position manifold x² + y² = L² (the nearest point: a radial scaling) and
    then the velocity manifold x u + y v = 0 (removing the radial velocity), which solve Part I
    Eq. 5 and 6 exactly for a point mass.

    Parameters
    ----------
    rtol, atol:
        Per-node tolerances (atol in m and m/s).
    **params:
        As :class:`PendulumODE`: g, L, theta0, omega0.

    Notes
    -----
    Outputs: ``x``, ``y`` (m), ``theta`` = atan2(x, y) (rad, unwrapped along the output grid,
    so a rotating pendulum needs a grid finer than half a turn), ``constraint`` = x² + y² −
    L² (m², round-off after projection).

    Accuracy: rtol = 1e-9, atol = 1e-11 by default, error controlled per node. With them x
    and y agree with L sin θ, L cos θ of the exact solution to within 100·rtol·L (1e-7 m)
    over 0–15 s, and the constraint holds to round-off (tests/test_models_pendulum.py).

    Raises
    ------
    ValueError
        An unknown parameter or an invalid value (g and L must be positive).
    """

    outputs: ClassVar[tuple[str, ...]] = ("x", "y", "theta", "constraint")
    _positive = _POSITIVE

    def __init__(self, *, rtol: float = 1e-9, atol: float = 1e-11, **params: float) -> None:
        super().__init__(_DEFAULTS, params, rtol=rtol, atol=atol)

    def _initial_state(self, p: Params) -> NDArray[np.float64]:
        theta, omega, length = p["theta0"], p["omega0"], p["L"]
        return np.stack(
            [
                length * np.sin(theta),
                length * np.cos(theta),
                length * omega * np.cos(theta),
                -length * omega * np.sin(theta),
            ]
        )

    def _rhs(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        x, yy, u, v = y
        lam = (u**2 + v**2 + p["g"] * yy) / p["L"] ** 2
        return np.stack([u, v, -lam * x, p["g"] - lam * yy])

    def _project(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        x, yy, u, v = y
        scale = p["L"] / np.hypot(x, yy)
        x, yy = x * scale, yy * scale
        radial = (x * u + yy * v) / p["L"] ** 2
        return np.stack([x, yy, u - radial * x, v - radial * yy])

    def _integrate(self, p: Params, times: NDArray[np.float64]) -> NDArray[np.float64]:
        return solve_projected(
            lambda t, y: self._rhs(t, y, p),
            lambda t, y: self._project(t, y, p),
            self._initial_state(p),
            times,
            t0=self.initial_time,
            rtol=self.rtol,
            atol=self.atol,
        )

    def _observe(
        self, times: NDArray[np.float64], states: NDArray[np.float64], p: Params
    ) -> dict[str, NDArray[np.float64]]:
        x, y = states[0], states[1]
        return {
            "x": x,
            "y": y,
            "theta": np.unwrap(np.arctan2(x, y), axis=1),
            "constraint": x**2 + y**2 - p["L"][:, None] ** 2,
        }
