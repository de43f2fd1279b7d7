"""The two-mode periodic terrain process of the uncertain-terrain case (Part II Eq. 11).

Not a model: the profile shared by ``quarter_car.py`` (the car drives over it) and
``oscillator.py`` (its zero-mean part, seen in time, drives the oscillator). Model files import
it as a sibling module; pcmb puts a model file's folder on ``sys.path`` while loading it.

The random part of the profile at distance s is

    A1 (ξ11 cos(s/L1) + ξ12 sin(s/L1)) + A2 (ξ21 cos(s/L2) + ξ22 sin(s/L2)),

with ξ independent standard normal germs: its covariance A1² cos(Δs/L1) + A2² cos(Δs/L2)
(Part II Eq. 12) has exactly these two eigenpairs, so the four germs are the whole
Karhunen–Loève expansion, not a truncation of it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

# Part II Eq. 16: a period D = 100 m; correlation lengths L_n = D / (2π n) for n = 3 and 7.
PERIOD = 100.0
L1_DEFAULT = PERIOD / (6 * np.pi)  # ≈ 5.3 m
L2_DEFAULT = PERIOD / (14 * np.pi)  # ≈ 2.3 m

GERMS = ("xi11", "xi12", "xi21", "xi22")


def random_profile(
    s: float | NDArray[np.float64], p: Mapping[str, NDArray[np.float64]]
) -> NDArray[np.float64]:
    """Zero-mean random part of the profile at distance ``s``.

    Parameters
    ----------
    s:
        Distance travelled, a scalar or (B,) (one value per node).
    p:
        (B,) arrays ``A1``, ``A2``, ``L1``, ``L2`` and the germs ``xi11``, ``xi12``,
        ``xi21``, ``xi22``.

    Returns
    -------
    NDArray
        Profile height, (B,).
    """
    phase1 = s / p["L1"]
    phase2 = s / p["L2"]
    return p["A1"] * (p["xi11"] * np.cos(phase1) + p["xi12"] * np.sin(phase1)) + p["A2"] * (
        p["xi21"] * np.cos(phase2) + p["xi22"] * np.sin(phase2)
    )


#: Forcing names of the random profile's polynomial form: its four time functions.
MODES = ("cos1", "sin1", "cos2", "sin2")


def mode_functions(p: Mapping[str, float]) -> Callable[[float], NDArray[np.float64]]:
    """``t -> (4,)`` cos(s/L1), sin(s/L1), cos(s/L2), sin(s/L2) at s = speed·t (floats ``p``)."""
    rates = np.array([p["speed"] / p["L1"], p["speed"] / p["L2"]])

    def modes(t: float) -> NDArray[np.float64]:
        phases = rates * t
        return np.array(
            [np.cos(phases[0]), np.sin(phases[0]), np.cos(phases[1]), np.sin(phases[1])]
        )

    return modes


def random_profile_form(p: Mapping[str, Any], modes: Sequence[Any]) -> Any:
    """The random profile as a polynomial (pcmb.designs.polynomial_form) in the amplitudes and germs
    ``p`` (numbers or polynomial variables) and the four ``modes`` variables (:data:`MODES`)."""
    return p["A1"] * (p["xi11"] * modes[0] + p["xi12"] * modes[1]) + p["A2"] * (
        p["xi21"] * modes[2] + p["xi22"] * modes[3]
    )


class SampledProfile:
    """A profile given by samples on a uniform grid: one C² cubic spline per node.

    The field-input form of the terrain: pcmb hands a random process input to the model as
    (B, m) values at ``numpy.linspace(start, stop, m)`` (SPEC §3), and the integrator needs
    the height between the samples. The not-a-knot cubic spline's error for a component of
    angular frequency ω and a spacing h is about 5(ω h)⁴/384 inside and up to (ω h)⁴/24 in
    the end intervals: 1.6e-6 of the shortest mode of the terrain (L2 ≈ 2.3 m) sampled every
    0.2 m (tests/test_process_configs.py).

    Parameters
    ----------
    values:
        (B, m) heights at the grid points, or (B,) for a profile constant along the grid.
    start, stop:
        (B,) or scalar ends of the grid (the same for every node).

    Raises
    ------
    ValueError
        A grid with start >= stop, or an evaluation outside [start, stop].
    """

    def __init__(self, values: NDArray[np.float64], start: float, stop: float) -> None:
        from scipy.interpolate import CubicSpline

        values = np.asarray(values, dtype=float)
        if values.ndim == 1:  # the nominal: one height along the whole grid
            values = np.repeat(values[:, None], 2, axis=1)
        self.start, self.stop = float(np.min(start)), float(np.max(stop))
        if not self.start < self.stop:
            raise ValueError(f"the profile's grid needs start < stop, got {start}, {stop}")
        points = values.shape[1]
        self.step = (self.stop - self.start) / (points - 1)
        grid = np.linspace(self.start, self.stop, points)
        # (4, m-1, B): the cubic of every interval and node.
        self._coefficients = CubicSpline(grid, values, axis=1).c

    def __call__(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Heights at distances ``s``, (B,) or (B, T) (one row per node) -> same shape."""
        s = np.asarray(s, dtype=float)
        slack = 1e-9 * (self.stop - self.start)
        if s.min() < self.start - slack or s.max() > self.stop + slack:
            raise ValueError(
                f"the profile is sampled on [{self.start:g}, {self.stop:g}], asked at "
                f"[{s.min():g}, {s.max():g}]"
            )
        intervals = self._coefficients.shape[1]
        index = np.clip(((s - self.start) / self.step).astype(int), 0, intervals - 1)
        dx = s - (self.start + index * self.step)
        nodes = np.arange(s.shape[0]).reshape(-1, *([1] * (s.ndim - 1)))
        c = self._coefficients[:, index, nodes]
        return ((c[0] * dx + c[1]) * dx + c[2]) * dx + c[3]
