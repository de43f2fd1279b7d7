"""Quarter-car vehicle suspension (Part II Eq. 1–5, 10, 11).

Two masses: the sprung mass Ms (body, displacement x1, velocity v1) on the unsprung mass Mu
(wheel, x2, v2), joined by a suspension spring and damper; the tire is a linear spring kT
between the wheel and the terrain height z(t) under it:

    Ms v1' = -Fs(x1 - x2) - Fd(v1 - v2)
    Mu v2' =  Fs(x1 - x2) + Fd(v1 - v2) + kT (z(t) - x2)

Displacements are measured from the static equilibrium (gravity does not appear, as in the
paper). Loaded by pcmb as ``entry: ../models/quarter_car.py:QuarterCar``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import NDArray
from terrain_process import (
    GERMS,
    L1_DEFAULT,
    L2_DEFAULT,
    MODES,
    PERIOD,
    SampledProfile,
    mode_functions,
    random_profile,
    random_profile_form,
)

from pcmb.integrate.stacked_ode import StackedODEModel

if TYPE_CHECKING:
    from pcmb.designs.polynomial_form import PolynomialForm

Params = Mapping[str, NDArray[np.float64]]
Law = Callable[[NDArray[np.float64], Params], NDArray[np.float64]]
Height = Callable[[float | NDArray[np.float64], Params], NDArray[np.float64]]

_BODY = {"Ms": 250.0, "Mu": 35.0, "kT": 1.5e5}
_INITIAL = {"x1_0": 0.0, "x2_0": 0.0, "v1_0": 0.0, "v2_0": 0.0}

# Suspension spring force Fs(δ), δ = x1 - x2; k is in N/m³ (cubic) or N/m (linear).
_SPRINGS: dict[str, tuple[dict[str, float], Law]] = {
    # d * d * d, not d**3: libm's pow takes a slow path for a negative base (8 times the
    # cost at 128 nodes), and this law runs about 12 times per integration step.
    "cubic": ({"k": 6.0e6}, lambda d, p: p["k"] * (d * d * d)),
    # A typical passenger-car corner rate; the linear law serves checks against closed forms.
    "linear": ({"k": 2.0e4}, lambda d, p: p["k"] * d),
}


def _mr_force(dv: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
    # Part II Eq. 10 as reconstructed in docs/paper_cases.md §3: a viscous part and a tanh
    # (smoothed Coulomb) part in the relative velocity, both growing linearly with the current.
    viscous = (p["c0"] + p["c1"] * p["I"]) * dv
    return viscous + (p["F0"] + p["F1"] * p["I"]) * np.tanh(p["mr_slope"] * dv)


# Damper force Fd(δ'), δ' = v1 - v2.
_DAMPERS: dict[str, tuple[dict[str, float], Law]] = {
    "linear": ({"c": 1000.0}, lambda dv, p: p["c"] * dv),
    # Part II Eq. 10 (docs/paper_cases.md §3): 800, 2868 and 4936 N at 1.5 m/s for I = 0, 1, 2 A.
    "mr": (
        {"I": 1.0, "c0": 531.0, "c1": 701.95, "F0": 4.0, "F1": 1015.0, "mr_slope": 14.3},
        _mr_force,
    ),
}


def _sine(t: float | NDArray[np.float64], p: Params) -> NDArray[np.float64]:
    return p["A"] * np.sin(2 * np.pi * p["f"] * t)


def _bump(t: float | NDArray[np.float64], p: Params) -> NDArray[np.float64]:
    start = p["bump_start"]
    on = (t >= start) & (t < start + p["bump_duration"])
    return np.where(on, p["bump_height"], 0.0)


def _kl(t: float | NDArray[np.float64], p: Params) -> NDArray[np.float64]:
    s = p["speed"] * t
    return p["A0"] * np.sin(2 * np.pi * s / p["D"]) + random_profile(s, p)


def _field(t: float | NDArray[np.float64], p: Params) -> NDArray[np.float64]:
    s = p["speed"] * t
    return p["A0"] * np.sin(2 * np.pi * s / p["D"]) + p["road"](s)


_TERRAINS: dict[str, tuple[dict[str, float], Height]] = {
    "sine": ({"A": 0.05, "f": 1.0}, _sine),
    "bump": ({"bump_height": 0.25, "bump_start": 0.5, "bump_duration": 0.5}, _bump),
    # Part II Eq. 16 and the 10 m/s of the uncertain-terrain case.
    "kl": (
        {
            "speed": 10.0,
            "D": PERIOD,
            "A0": 0.5,
            "A1": 0.2,
            "A2": 0.1,
            "L1": L1_DEFAULT,
            "L2": L2_DEFAULT,
            **dict.fromkeys(GERMS, 0.0),
        },
        _kl,
    ),
    # The same mean profile; the random part is a field input `road` sampled on a grid.
    "field": (
        {"speed": 10.0, "D": PERIOD, "A0": 0.5, "road": 0.0, "road_start": 0.0, "road_stop": 100.0},
        _field,
    ),
}


def _choice(kind: str, value: str, table: Mapping[str, object]) -> None:
    if value not in table:
        raise ValueError(f"QuarterCar {kind} must be one of {', '.join(table)}, got {value!r}")


class QuarterCar(StackedODEModel):
    """Quarter car with a choice of suspension spring, damper and terrain; batched.

    Parameters
    ----------
    terrain:
        ``"sine"``: z = A sin(2π f t) (A in m, f in Hz).
        ``"bump"``: a square bump z = bump_height (m) for bump_start <= t < bump_start +
        bump_duration (s), else 0; the integration restarts at both edges.
        ``"kl"``: the periodic profile of Part II Eq. 11 driven over at ``speed`` (m/s):
        z(t) = A0 sin(2π s/D) + A1 (xi11 cos(s/L1) + xi12 sin(s/L1))
        + A2 (xi21 cos(s/L2) + xi22 sin(s/L2)), s = speed·t; the germs xi.. are parameters.
        ``"field"``: the same mean profile plus a random part given as a field input: z(t) =
        A0 sin(2π s/D) + road(s), with ``road`` (B, m) heights at
        ``numpy.linspace(road_start, road_stop, m)`` (m), as pcmb hands a random process
        input (``inputs.road: {process: kl, ...}`` with the same grid), interpolated by a
        cubic spline (:class:`terrain_process.SampledProfile`); nominal ``road`` 0 is flat.
    damper:
        ``"linear"``: Fd = c·δ' (c in N·s/m). ``"mr"``: magneto-rheological damper
        (Part II Eq. 10) Fd = (c0 + c1·I)·δ' + (F0 + F1·I) tanh(mr_slope·δ') with the coil
        current I (A), c0 (N·s/m), c1 (N·s/(m·A)), F0 (N), F1 (N/A), mr_slope (s/m).
    spring:
        ``"cubic"``: Fs = k·δ³ (k in N/m³, the paper's). ``"linear"``: Fs = k·δ (N/m).
    rtol, atol:
        Per-node tolerances of the DOP853 integration (atol in m and m/s).
    **params:
        Nominal values by name (SI units), defaults in parentheses. Always: Ms (250 kg), Mu
        (35 kg), kT (1.5e5 N/m), k (6e6 N/m³ cubic, 2e4 N/m linear), and the initial state
        x1_0, x2_0 (m), v1_0, v2_0 (m/s) (all 0). The terrain's and the damper's own
        parameters, listed above, with defaults: sine A = 0.05, f = 1; bump bump_height =
        0.25, bump_start = 0.5, bump_duration = 0.5; kl speed = 10, D = 100, A0 = 0.5, A1 =
        0.2, A2 = 0.1, L1 = D/(6π), L2 = D/(14π) for the default D (set them with D), germs 0;
        field speed = 10, D = 100, A0 = 0.5, road = 0, road_start = 0, road_stop = 100;
        linear damper c = 1000; MR damper I = 1, c0 = 531, c1 = 701.95, F0 = 4, F1 = 1015,
        mr_slope = 14.3.
        A parameter that does not belong to the chosen options is rejected.

    Notes
    -----
    The car starts at t = 0 on the terrain: x1(0) = z(0) + x1_0, x2(0) = z(0) + x2_0 (both
    springs unstretched when x1_0 = x2_0 = 0), v1(0) = v1_0, v2(0) = v2_0.

    Outputs: ``x1``, ``x2`` (m), ``v1``, ``v2`` (m/s), ``a1`` (sprung-mass acceleration,
    m/s², from the equations of motion at the output times), ``z`` (terrain under the tire, m).

    Accuracy: rtol = 1e-10, atol = 1e-13 by default, per node whatever the batch size (see
    :func:`pcmb.integrate.stacked_ode.solve_stacked`). With them every node, in a batch or alone,
    agrees with a tight separate run (DOP853, rtol = 1e-11) to within 1e-6 of each state's
    largest magnitude over the run (tests/test_models_quarter_car.py). The tolerances are
    tighter than that 1e-6 suggests because outputs come from DOP853's dense output, whose
    error between steps is not controlled: with the wheel-hop mode (≈ 10 Hz) spanning a good
    part of each step, rtol = 1e-8 gives single runs up to 2e-6 at the output times although
    the steps themselves are 100 times more accurate; atol must stay small because the car
    starts at rest and a large atol lets the first steps grow long. ``a1`` is computed from the
    states and inherits their error amplified by the damper's slope: with the MR damper,
    (c0 + c1·I + mr_slope·(F0 + F1·I))/Ms ≈ 120 s⁻¹ (I = 2 A) times the velocity error.

    Raises
    ------
    ValueError
        An unknown option or parameter, or an invalid value.
    """

    outputs: ClassVar[tuple[str, ...]] = ("x1", "x2", "v1", "v2", "a1", "z")
    _positive = frozenset(
        {"Ms", "Mu", "kT", "k", "f", "bump_duration", "D", "L1", "L2", "mr_slope"}
    )
    _nonnegative = frozenset({"c", "c0", "c1", "I", "F0", "F1", "bump_start"})
    _fields = frozenset({"road"})

    def __init__(
        self,
        *,
        terrain: str = "sine",
        damper: str = "linear",
        spring: str = "cubic",
        rtol: float = 1e-10,
        atol: float = 1e-13,
        **params: float,
    ) -> None:
        _choice("terrain", terrain, _TERRAINS)
        _choice("damper", damper, _DAMPERS)
        _choice("spring", spring, _SPRINGS)
        spring_defaults, self._spring = _SPRINGS[spring]
        damper_defaults, self._damper = _DAMPERS[damper]
        terrain_defaults, self._terrain = _TERRAINS[terrain]
        defaults = {
            **_BODY,
            **spring_defaults,
            **damper_defaults,
            **terrain_defaults,
            **_INITIAL,
        }
        super().__init__(defaults, params, rtol=rtol, atol=atol)
        self.terrain, self.damper, self.spring = terrain, damper, spring

    def polynomial_form(self, inputs: Sequence[str]) -> PolynomialForm:
        """The dynamics as polynomials in (x1, x2, v1, v2, inputs, forcing), for pcmb's
        intrusive methods: the linear damper on the sine or KL terrain, either spring.

        The sine terrain's forcing is sin(2π f t); the KL terrain's are sin(2π s/D) and the
        four modes of its random part (s = speed·t). The model divides by the masses and
        the forcing holds f, speed, D, L1 and L2: those must stay certain.

        Raises
        ------
        ValueError
            The MR damper (tanh), the bump terrain (a jump in time), or an uncertain input
            the dynamics are not polynomial in.
        """
        # Imported here: pcmb.designs loads scipy, which the workers running nodes do without.
        from pcmb.designs.polynomial_form import PolynomialForm, PolynomialSpace

        if self.damper != "linear":
            raise ValueError(f"the {self.damper} damper's force law is not polynomial")
        fixed = ["Ms", "Mu"]
        if self.terrain == "sine":
            forcing: tuple[str, ...] = ("sine",)
            fixed.append("f")
            rate = 2 * np.pi * self.parameters["f"]

            def functions(t: float) -> NDArray[np.float64]:
                return np.array([np.sin(rate * t)])

        elif self.terrain == "kl":
            forcing = ("ground", *MODES)
            fixed += ["speed", "D", "L1", "L2"]
            modes = mode_functions(self.parameters)
            ground = 2 * np.pi * self.parameters["speed"] / self.parameters["D"]

            def functions(t: float) -> NDArray[np.float64]:
                return np.concatenate([[np.sin(ground * t)], modes(t)])

        else:
            raise ValueError(
                "the bump terrain jumps in time, which the polynomial form cannot carry"
            )
        space = PolynomialSpace(("x1", "x2", "v1", "v2"), inputs, forcing)
        p = space.parameters(self.parameters, fixed)
        x1, x2, v1, v2 = space.states
        if self.terrain == "sine":
            z = p["A"] * space.forcing[0]
        else:
            z = p["A0"] * space.forcing[0] + random_profile_form(p, space.forcing[1:])
        force = self._suspension(x1, x2, v1, v2, p)
        return PolynomialForm(
            space,
            rhs=(v1, v2, force / p["Ms"], (p["kT"] * (z - x2) - force) / p["Mu"]),
            initial=(z + p["x1_0"], z + p["x2_0"], p["v1_0"], p["v2_0"]),
            outputs={"x1": x1, "x2": x2, "v1": v1, "v2": v2, "a1": force / p["Ms"], "z": z},
            forcing=functions,
            t0=self.initial_time,
            rtol=self.rtol,
            atol=self.atol,
            method=self.method,
        )

    def _prepare(self, p: dict[str, NDArray[np.float64]]) -> Mapping[str, object]:
        if self.terrain != "field":
            return p
        return {**p, "road": SampledProfile(p["road"], p["road_start"], p["road_stop"])}

    def _initial_state(self, p: Params) -> NDArray[np.float64]:
        z0 = self._terrain(self.initial_time, p)
        return np.stack([z0 + p["x1_0"], z0 + p["x2_0"], p["v1_0"], p["v2_0"]])

    def _suspension(
        self,
        x1: NDArray[np.float64],
        x2: NDArray[np.float64],
        v1: NDArray[np.float64],
        v2: NDArray[np.float64],
        p: Params,
    ) -> NDArray[np.float64]:
        """Force of the suspension on the sprung mass (its reaction acts on the wheel)."""
        return -self._spring(x1 - x2, p) - self._damper(v1 - v2, p)

    def _rhs(self, t: float, y: NDArray[np.float64], p: Params) -> NDArray[np.float64]:
        x1, x2, v1, v2 = y
        force = self._suspension(x1, x2, v1, v2, p)
        tire = p["kT"] * (self._terrain(t, p) - x2)
        out = np.empty_like(y)
        out[0] = v1
        out[1] = v2
        np.divide(force, p["Ms"], out=out[2])
        np.divide(tire - force, p["Mu"], out=out[3])
        return out

    def _breakpoints(self, p: Params) -> Sequence[float]:
        if self.terrain != "bump":
            return ()
        return np.unique(np.concatenate([p["bump_start"], p["bump_start"] + p["bump_duration"]]))

    def _observe(
        self, times: NDArray[np.float64], states: NDArray[np.float64], p: Params
    ) -> dict[str, NDArray[np.float64]]:
        x1, x2, v1, v2 = states
        # (B, 1) against (B, T); a sampled profile takes (B, T) distances as they are.
        column = {
            name: value[:, None] if isinstance(value, np.ndarray) else value
            for name, value in p.items()
        }
        return {
            "x1": x1,
            "x2": x2,
            "v1": v1,
            "v2": v2,
            "a1": self._suspension(x1, x2, v1, v2, column) / column["Ms"],
            "z": self._terrain(times[None, :], column),
        }
