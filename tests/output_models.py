"""Models whose outputs are not all time series, with closed-form statistics (the tests of
scalar outputs, outputs on their own axis and ``derived:`` figures).

In an importable module so that worker processes unpickle them by reference; configs name
them as ``tests/output_models.py:Name``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.axes import OutputAxis

#: The frequency sweep of :class:`Resonance`: 0.02 to 0.5 Hz, logarithmic.
FREQUENCIES = np.geomspace(0.02, 0.5, 40)


class Decay:
    """x(t) = exp(-k t) on the time grid, and its energy ∫_0^∞ x² dt = 1/(2k), a scalar per
    run (returned as (B,)). With k ~ U[1, 2]: E = ln 2 / 2, E[energy²] = 1/8."""

    outputs = ("x", "energy")
    parameters: ClassVar = {"k": 1.5}
    output_axes: ClassVar = {"energy": None}

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        k = np.asarray(params["k"], dtype=float)
        return {"x": np.exp(-np.outer(k, times)), "energy": 0.5 / k}


def gain(zeta: NDArray[np.float64], frequencies: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, K) |H(iω)| of x'' + 2ζω0 x' + ω0² x = u, ω0 = 1 rad/s, at ω = 2π f."""
    omega = 2 * np.pi * frequencies
    return 1.0 / np.abs(1.0 - omega**2 + 2j * np.outer(zeta, omega))


class Resonance:
    """The gain |H(iω)| of a damped oscillator with uncertain damping ratio ``zeta`` on a
    frequency axis of its own (:data:`FREQUENCIES`, Hz), and its peak gain over the sweep
    (a scalar)."""

    outputs = ("gain", "peak")
    parameters: ClassVar = {"zeta": 0.2}
    output_axes: ClassVar = {"gain": OutputAxis("frequency", FREQUENCIES, "Hz"), "peak": None}

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        values = gain(np.asarray(params["zeta"], dtype=float), FREQUENCIES)
        return {"gain": values, "peak": values.max(axis=1)}


class Signals:
    """Time outputs whose figures of merit have closed forms (t in [0, 1] or [0, 10]):

    - ``wave`` = a sin(2π t): max |y| = a on a grid holding t = 1/4; RMS over a whole period
      = a / √2 (the trapezoid rule is exact for it);
    - ``ramp`` = b t: its value at any time s is b s (linear interpolation is exact);
    - ``step`` = 1 - exp(-k t): settles into ±band·|y_T| of its final value y_T at
      -ln(e^{-kT} + band (1 - e^{-kT})) / k;
    - ``line`` = t - c on t in [0, 1]: max |y| = max(c, 1 - c), a kink at c = 1/2 (the
      known hard case of a maximum).
    """

    outputs = ("wave", "ramp", "step", "line")
    parameters: ClassVar = {"a": 2.0, "b": 0.5, "k": 1.5, "c": 0.5}

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        size = len(next(iter(params.values())))
        a, b, k, c = (
            np.broadcast_to(np.asarray(params.get(n, self.parameters[n]), dtype=float), size)
            for n in ("a", "b", "k", "c")
        )
        return {
            "wave": np.outer(a, np.sin(2 * np.pi * times)),
            "ramp": np.outer(b, times),
            "step": 1.0 - np.exp(-np.outer(k, times)),
            "line": times - c[:, None],
        }
