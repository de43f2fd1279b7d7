"""The placed held-out check of a one-input design whose response jumps or has kinks (issue 23).

The references are closed forms: sign(x − 0.2) (1 − e^{−t}) + 0.1 x, x ~ U[−1, 1], integrated
by Gauss–Legendre on each side of the jump; a ball bouncing off a floor, by the midpoint rule
on 10,000 drops; the double well's moments (:func:`pcmb.references.double_well_moments`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

import pcmb
from pcmb.analysis.diagnostics import TOLERANCE, held_out_placed, placed_check, verdict
from pcmb.analysis.diagnostics.check import HeldOutCheck
from pcmb.analysis.diagnostics.verdict import flag_margin
from pcmb.chaos.nodes import TensorGrid
from pcmb.references import double_well, double_well_moments

TIMES = np.array([0.3, 0.4, 1.0, 3.0])


def _jump(x: np.ndarray) -> np.ndarray:
    return np.where(x > 0.2, 1.0, -1.0)[:, None] * (1 - np.exp(-TIMES)) + 0.1 * x[:, None]


def _checked(
    low: float, high: float, order: int, response: Callable[[np.ndarray], np.ndarray]
) -> tuple[pcmb.ChaosExpansion, HeldOutCheck]:
    """The tensor design of ``order`` on x ~ U[low, high] (its Gauss projection) and its
    default placed check of 8 runs; ``response`` maps (N,) inputs to (N, T) outputs."""
    grid = TensorGrid((pcmb.Uniform(low, high),), (order,))
    family = grid.distributions[0].family
    values = response(grid.params[:, 0])
    basis = family.evaluate(grid.nodes[:, 0], order)
    expansion = pcmb.ChaosExpansion(
        basis.T @ (grid.weights[:, None] * values),
        [[p] for p in range(order + 1)],
        grid.distributions,
    )
    scale = float(expansion.std().max())
    draws, _ = held_out_placed(grid.distributions[0], grid.nodes, 8)
    observed = response(draws.params[:, 0])
    return expansion, placed_check(expansion, grid.nodes, values, draws.nodes, observed, scale)


def _flagged(times: np.ndarray, found: HeldOutCheck) -> float:
    """The verdict's first flag of the placed check ``found`` at the default tolerance."""
    return verdict(times, found.statistics, TOLERANCE, flag_margin(found, TOLERANCE))


def test_the_mean_error_of_a_jump_counts_the_interpolant_s_own_error():
    # Order 5 (6 Gauss nodes, exact to degree 11) and 8 placed runs: the interpolant of degree
    # 13 holds degrees the design's rule does not integrate, so its mean differs from the
    # design's, but through a jump it is itself wrong by nearly as much (its Legendre tail
    # decays algebraically). Its difference alone read 0.55 of the design's true mean error.
    # The interpolant's own error, about 0.43 of that truth here, is an extrapolated tail,
    # known to within a factor 2 either way: halved, the sum still reads 3/4 of the truth.
    points, weights = np.polynomial.legendre.leggauss(400)
    x = np.concatenate([-1 + (points + 1) * 0.6, 0.2 + (points + 1) * 0.4])
    w = np.concatenate([weights * 0.6, weights * 0.4]) / 2
    true_mean = w @ _jump(x)
    expansion, found = _checked(-1.0, 1.0, 5, _jump)
    true = abs(expansion.mean() - true_mean) / float(expansion.std().max())
    assert np.all(0.75 * true <= found.mean_error) and np.all(found.mean_error <= 2 * true)


def _bounce(h: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(H, T) height of a ball dropped from ``h`` (g = 9.81) onto a floor, restitution 0.6."""
    h = h[:, None]
    y, speed, start = h - 4.905 * times**2, 0.6 * np.sqrt(19.62 * h), np.sqrt(h / 4.905)
    for _ in range(40):
        flight = times - start
        y = np.where((flight >= 0) & (flight < speed / 4.905), flight * (speed - 4.905 * flight), y)
        start, speed = start + speed / 4.905, 0.6 * speed
    return np.where(times >= start, 0.0, y)


def test_a_contact_s_interpolant_error_is_no_false_alarm():
    # A ball dropped from h ~ U[0.3, 1.2], restitution 0.6, to t = 3; order 3 (4 Gauss nodes)
    # and 8 placed runs. Each contact puts a kink in h, so the interpolant of degree 11 through
    # nodes and runs errs itself (algebraically), here by 1 % of the scale at t = 0.46, where
    # its std happens to settle (moves of 0.2 %, shrunk to 0.01 % by their rate) and so
    # doubled the design's own error: flagged at 0.46 where the truth first passes 5 % at
    # 0.76, 10 % of the horizon early.
    times = np.linspace(0.0, 3.0, 151)
    expansion, found = _checked(0.3, 1.2, 3, lambda h: _bounce(h, times))
    truth = _bounce(0.3 + 0.9 * (np.arange(10000) + 0.5) / 10000, times)
    mean, std = truth.mean(axis=0), truth.std(axis=0)
    scale = float(expansion.std().max())
    true = np.fmax(abs(expansion.mean() - mean), abs(expansion.std() - std)) / scale
    crossing = verdict(times, true, TOLERANCE)
    assert 0.7 <= crossing <= 0.8  # the closed form's
    assert abs(_flagged(times, found) - crossing) <= 0.05 * times[-1], _flagged(times, found)


def test_a_noisy_std_estimate_leaves_a_steady_mean_s_flag_standing():
    # The double well x' = x − x³, x0 ~ U[−0.625, 0.375], to t = 4, order 7 (8 Gauss nodes,
    # exact to degree 15) and 8 placed runs: x(t) tends to sign(x0), a jump. The interpolant's
    # std errs by as much as the design's (+5 % of the scale where the design's is −2.4 %,
    # t = 3.14), and its standard error now says so (7.8 %); the mean's error, the unseen
    # degrees' alone (6.3 % against a true 5.1 %), is steady. Judged by the larger estimate's
    # noise, the std's, no time was flagged where the truth crosses 5 % at t = 3.14.
    times = np.linspace(0.0, 4.0, 201)
    expansion, found = _checked(-0.625, 0.375, 7, lambda x0: double_well(times, x0))
    mean, std = double_well_moments(times, -0.625, 0.375)
    scale = float(expansion.std().max())
    true = np.fmax(abs(expansion.mean() - mean), abs(expansion.std() - std)) / scale
    crossing = verdict(times, true, TOLERANCE)
    assert 3.1 <= crossing <= 3.2  # the closed form's
    assert abs(_flagged(times, found) - crossing) <= 0.05 * times[-1], _flagged(times, found)
