"""How honest ``elements: auto``'s error estimate is: its estimate against the true error of
the mean and std, on responses with a jump, a kink or heavy tails whose moments are known.

For each case and ``diagnostics.tolerance`` the multi-element design runs in this process (no
workers, no held-out check) with ``max_elements`` 64; the true error is the largest over time
of max(|Δmean|, |Δstd|) over the largest std, against the closed form (double well:
:func:`pcmb.references.double_well_moments`; |x - 0.3| and the step at 0.3 on U[-1, 1];
exp(z t / 2): :func:`pcmb.references.lognormal_moments`; the cases no test tunes on,
|x1 - x2| + sin(x1 + x2), sign(x) x², exp(x) + 2 max(x - 1/√5, 0), a step along
x1 + x2 / 2 = 0.1, cos(2x) and exp(x1) sin(2 x2), in their docstrings) or, for the bouncing ball, a
4000-point Gauss–Legendre rule over its closed-form heights. Four cases are held out,
measured once after the rules were chosen (``docs/multi_element.md``, †): the relay with an
uncertain threshold, the ball with an uncertain restitution, the double well from
U[-0.2, 0.6] and a step in x1 times exp(x2), their references in their docstrings.
``estimate/true`` > 1 is a careful estimate, < 1 an over-confident one.

    python scripts/calibrate_elements.py [--order 3] [--tolerances 1e-1,1e-2,1e-3,1e-4]
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Callable

import numpy as np

import pcmb
from pcmb.chaos.nodes import TensorGrid, join_nodes
from pcmb.designs import MethodSettings, make_design
from pcmb.references import bouncing_ball, double_well, double_well_moments, lognormal_moments

Case = tuple[dict, np.ndarray, Callable[[np.ndarray, np.ndarray], np.ndarray], tuple]

KINK, STEP = 0.3, 0.3


def _double_well(low: float, high: float) -> Case:
    """The double well with x0 ~ U[low, high], t in [0, 4]
    (:func:`pcmb.references.double_well_moments`)."""
    times = np.linspace(0.0, 4.0, 41)
    return (
        {"x0": pcmb.Uniform(low, high)},
        times,
        lambda x, t: double_well(t, x[:, 0]),
        double_well_moments(times, low, high),
    )


def well() -> Case:
    return _double_well(-0.625, 0.375)


def kink() -> Case:
    mean = (1 + KINK**2) / 2
    return (
        {"x": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: np.abs(x[:, :1] - KINK),
        (np.array([mean]), np.sqrt(np.array([1 / 3 + KINK**2 - mean**2]))),
    )


def step() -> Case:
    p = (1 - STEP) / 2
    return (
        {"x": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: (x[:, :1] > STEP) + 0.0,
        (np.array([p]), np.sqrt(np.array([p * (1 - p)]))),
    )


def ball() -> Case:
    inputs, times = {"h0": pcmb.Uniform(0.5, 1.5)}, np.linspace(0.0, 3.0, 61)
    fine = TensorGrid(tuple(inputs.values()), (3999,))
    exact = bouncing_ball(fine.params[:, 0], times)
    mean = fine.weights @ exact
    return (
        inputs,
        times,
        lambda x, t: bouncing_ball(x[:, 0], t),
        (mean, np.sqrt(fine.weights @ (exact - mean) ** 2)),
    )


def lognormal() -> Case:
    times = np.linspace(0.0, 3.0, 31)
    return (
        {"z": pcmb.Normal(0.0, 1.0)},
        times,
        lambda x, t: np.exp(0.5 * np.outer(x[:, 0], t)),
        lognormal_moments(0.5 * times),
    )


def diagonal() -> Case:
    """|x1 - x2| + sin(x1 + x2) on U[-1, 1]²: smooth but for a kink along the diagonal, which
    no split follows (mean 2/3; E y² = 2/3 + (1 - sin²(2) / 4) / 2, the cross term odd)."""
    square = 2 / 3 + (1 - np.sin(2.0) ** 2 / 4) / 2
    return (
        {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: np.abs(x[:, :1] - x[:, 1:2]) + np.sin(x[:, :1] + x[:, 1:2]),
        (np.array([2 / 3]), np.sqrt(np.array([square - 4 / 9]))),
    )


def signed_square() -> Case:
    """sign(x) x² on U[-1, 2]: its second derivative jumps at x = 0 (mean 7/9, E y² = 11/5)."""
    return (
        {"x": pcmb.Uniform(-1.0, 2.0)},
        np.zeros(1),
        lambda x, t: np.sign(x[:, :1]) * x[:, :1] ** 2,
        (np.array([7 / 9]), np.sqrt(np.array([11 / 5 - 49 / 81]))),
    )


def _piecewise_moments(
    response: Callable[[np.ndarray], np.ndarray], cuts: list[float] | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) of a response of x ~ U[-1, 1] smooth between ``cuts`` ((N,) or (N, T) at N
    points): a 40-point Gauss rule on every piece (round-off for an analytic piece)."""
    x, w = np.polynomial.legendre.leggauss(40)
    pieces = list(itertools.pairwise([-1.0, *cuts, 1.0]))
    points = np.concatenate([(a + b) / 2 + (b - a) / 2 * x for a, b in pieces])
    weights = np.concatenate([(b - a) / 4 * w for a, b in pieces])
    y = response(points)
    mean = weights @ y
    return np.atleast_1d(mean), np.sqrt(np.atleast_1d(weights @ (y - mean) ** 2))


def derivative_jump() -> Case:
    """exp(x) + 2 max(x - 1/√5, 0) on U[-1, 1]: analytic but for a jump of its derivative at an
    irrational point, which no halving reaches."""
    cut = 1 / np.sqrt(5)
    return (
        {"x": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: np.exp(x[:, :1]) + 2 * np.maximum(x[:, :1] - cut, 0.0),
        _piecewise_moments(lambda x: np.exp(x) + 2 * np.maximum(x - cut, 0.0), [cut]),
    )


def oblique_step() -> Case:
    """A step along x1 + x2 / 2 = 0.1 on U[-1, 1]²: no split follows it (mean P(x1 > 0.1 - x2 / 2)
    = 0.45, the threshold within [-1, 1] for every x2)."""
    p = 0.45
    return (
        {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: (x[:, :1] + x[:, 1:2] / 2 > 0.1) + 0.0,
        (np.array([p]), np.sqrt(np.array([p * (1 - p)]))),
    )


def cosine() -> Case:
    """cos(2x) on U[-1, 1]: analytic, even (mean sin(2) / 2, E y² = (1 + sin(4) / 4) / 2)."""
    mean = np.sin(2.0) / 2
    return (
        {"x": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: np.cos(2 * x[:, :1]),
        (np.array([mean]), np.sqrt(np.array([(1 + np.sin(4.0) / 4) / 2 - mean**2]))),
    )


def exp_sine() -> Case:
    """exp(x1) sin(2 x2) on U[-1, 1]²: analytic in both inputs (mean 0, E y² = sinh(2) / 2
    times (1 - sin(4) / 4) / 2)."""
    square = np.sinh(2.0) / 2 * (1 - np.sin(4.0) / 4) / 2
    return (
        {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: np.exp(x[:, :1]) * np.sin(2 * x[:, 1:2]),
        (np.zeros(1), np.sqrt(np.array([square]))),
    )


def relay_value(theta: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(N, T) x' = u - x, x(0) = 0, u = 1 until x reaches ``theta`` (at t* = -ln(1 - theta)),
    then 0: 1 - e^-t before t*, theta e^-(t - t*) after, a kink at theta = 1 - e^-t."""
    theta, rising = theta[:, None], 1 - np.exp(-times[None, :])
    return np.where(theta > rising, rising, theta * np.exp(-times[None, :]) / (1 - theta))


def relay() -> Case:
    """The relay with its threshold theta ~ U[0.2, 0.8], t in [0, 3] (:func:`relay_value`):
    per time, a Gauss rule on either side of the kink."""
    times = np.linspace(0.0, 3.0, 61)
    exact = []
    for t in times:
        kink = (0.5 - np.exp(-t)) / 0.3  # theta = 1 - e^-t, with theta = 0.5 + 0.3 u
        exact.append(
            _piecewise_moments(
                lambda u, t=t: relay_value(0.5 + 0.3 * u, np.array([t]))[:, 0],
                [kink] if abs(kink) < 1 else [],
            )
        )
    return (
        {"theta": pcmb.Uniform(0.2, 0.8)},
        times,
        lambda x, t: relay_value(x[:, 0], t),
        tuple(np.concatenate(moments) for moments in zip(*exact, strict=True)),
    )


def restitution_ball() -> Case:
    """A ball dropped from 1 m with restitution e ~ U[0.6, 0.9], t in [0, 3]
    (:func:`pcmb.references.bouncing_ball`): a kink at every contact, which moves with e.
    Reference: 500 pieces of a 40-point Gauss rule (agrees with 20 000 pieces of 8 points to
    2e-8 of the largest std)."""
    times = np.linspace(0.0, 3.0, 61)

    def heights(e: np.ndarray) -> np.ndarray:
        return bouncing_ball(np.ones(e.size), times, restitution=e[:, None])

    return (
        {"e": pcmb.Uniform(0.6, 0.9)},
        times,
        lambda x, t: bouncing_ball(np.ones(len(x)), t, restitution=x[:, :1]),
        _piecewise_moments(lambda u: heights(0.75 + 0.15 * u), np.linspace(-1, 1, 501)[1:-1]),
    )


def shifted_well() -> Case:
    """The double well with x0 ~ U[-0.2, 0.6], t in [0, 4]: its jump at x0 = 0 a quarter of the
    way in."""
    return _double_well(-0.2, 0.6)


def step_times_exp() -> Case:
    """1[x1 > 0.15] exp(x2) on U[-1, 1]²: a jump in one input times an analytic function of
    the other (mean 0.425 sinh(1), E y² = 0.425 sinh(2) / 2)."""
    p = 0.425
    mean = p * np.sinh(1.0)
    return (
        {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)},
        np.zeros(1),
        lambda x, t: (x[:, :1] > 0.15) * np.exp(x[:, 1:2]),
        (np.array([mean]), np.sqrt(np.array([p * np.sinh(2.0) / 2 - mean**2]))),
    )


CASES = {
    f.__name__: f
    for f in (
        well,
        kink,
        step,
        ball,
        lognormal,
        diagonal,
        signed_square,
        derivative_jump,
        oblique_step,
        cosine,
        exp_sine,
        relay,
        restitution_ball,
        shifted_well,
        step_times_exp,
    )
}


def run(
    case: str, order: int, tolerance: float, max_elements: int
) -> tuple[int, int, float, float]:
    """(runs, elements, the design's final estimate (NaN before it had one), true error)."""
    inputs, times, function, (mean, std) = CASES[case]()
    settings = MethodSettings(
        "collocation",
        orders=(order,) * len(inputs),
        elements="auto",
        max_elements=max_elements,
        diagnostics_tolerance=tolerance,
    )
    design = make_design(inputs, settings)
    nodes = design.nodes()
    values = {"y": function(nodes.params, times)}
    while (batch := design.more(nodes, values, np.ones(nodes.size, bool))) is not None:
        nodes = join_nodes(nodes, batch)
        values = {"y": np.concatenate([values["y"], function(batch.params, times)])}
    recovery = design.recover(nodes, values, np.ones(nodes.size, bool), times)
    expansion = recovery.expansions["y"]
    error = np.fmax(abs(expansion.mean() - mean), abs(expansion.std() - std)).max() / std.max()
    estimate = float(getattr(design, "estimate", np.nan))
    return nodes.size, design.partition.size, estimate, float(error)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="?", default=",".join(CASES))
    parser.add_argument("--order", type=int, default=3)
    parser.add_argument("--tolerances", default="1e-1,1e-2,1e-3,1e-4")
    parser.add_argument("--max-elements", type=int, default=64)
    args = parser.parse_args()
    print("| case | tolerance | runs | elements | estimate | true error | estimate/true |")
    print("|---|---|---|---|---|---|---|")
    for case in args.cases.split(","):
        for tolerance in map(float, args.tolerances.split(",")):
            runs, size, estimate, error = run(case, args.order, tolerance, args.max_elements)
            print(
                f"| {case} | {tolerance:g} | {runs} | {size} | {estimate:.2g} | {error:.2g} | "
                f"{estimate / error:.2g} |"
            )


if __name__ == "__main__":
    main()
