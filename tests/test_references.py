"""pcmb.references against independent computations: ODE solvers, quadrature, definitions.

ODE references are compared with one tight DOP853 run per case (``model_loading``: rtol
1e-11); its global error on these stable, non-chaotic problems is a modest multiple of rtol,
so they must agree within GLOBAL_FACTOR·rtol of the solution's scale. Quadrature references
use rules that are exact, or exponentially accurate, for the integrands, so they agree to
round-off.
"""

from __future__ import annotations

import ast
import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from model_loading import GLOBAL_FACTOR, REFERENCE_RTOL, reference_run
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.special import beta as beta_function
from scipy.special import gamma as gamma_function

from pcmb import references
from pcmb.references import (
    cosine_covariance,
    cosine_covariance_kl,
    damped_oscillator,
    double_well,
    gamma_moment,
    ishigami,
    ishigami_moments,
    jacobi_moment,
    lorenz_equilibria,
    normal_moment,
    pendulum_angle,
    quarter_car_linear,
    statistical_linearization,
    uniform_moment,
)

BOUND = GLOBAL_FACTOR * REFERENCE_RTOL  # relative to the solution's scale


# --------------------------------------------------------------------------- ODE solutions


@pytest.mark.parametrize("theta0", [np.pi / 4, -1.0, 2.5])
def test_pendulum_angle_solves_the_pendulum(theta0):
    times = np.linspace(0.0, 15.0, 301)
    lengths = np.array([0.8, 1.0, 1.2])
    exact = pendulum_angle(times, lengths, theta0)
    assert exact.shape == (3, 301)
    for length, row in zip(lengths, exact, strict=True):
        run = reference_run(
            lambda t, y, length=length: [y[1], -(9.81 / length) * np.sin(y[0])],
            [theta0, 0.0],
            times,
            atol=1e-14,
        )
        assert np.abs(row - run[0]).max() <= BOUND * abs(theta0)


def test_pendulum_angle_shapes_and_arguments():
    times = np.linspace(0.0, 2.0, 5)
    assert pendulum_angle(times, 1.0).shape == (5,)
    assert pendulum_angle(times, 1.0)[0] == pytest.approx(np.pi / 4, abs=1e-15)
    # theta0 broadcasts with the lengths; g enters as g / L only.
    both = pendulum_angle(times, [1.0, 2.0], [0.3, 0.5], g=4.0)
    np.testing.assert_allclose(both[1], pendulum_angle(times, 1.0, 0.5, g=2.0), rtol=1e-14)
    with pytest.raises(ValueError, match="L > 0"):
        pendulum_angle(times, 0.0)
    with pytest.raises(ValueError, match="theta0"):
        pendulum_angle(times, 1.0, np.pi)


def test_double_well_solves_its_ode():
    times = np.linspace(0.0, 10.0, 201)
    x0 = np.array([-2.0, -0.625, -1e-3, 0.2, 0.375, 1.5])
    exact = double_well(times, x0)
    assert exact.shape == (6, 201)
    for start, row in zip(x0, exact, strict=True):
        run = reference_run(lambda t, y: y - y**3, [start], times, atol=1e-14)
        assert np.abs(row - run[0]).max() <= BOUND * max(1.0, abs(start))


def test_double_well_is_the_papers_formula_and_does_not_overflow():
    times = np.linspace(0.0, 4.0, 41)
    x0 = np.linspace(-0.625, 0.375, 9)[:, None]
    growth = np.exp(times)
    papers = x0 * growth / np.sqrt(1 + x0**2 * (growth**2 - 1))
    np.testing.assert_allclose(double_well(times, x0[:, 0]), papers, rtol=1e-14, atol=1e-16)
    # Equilibria stay put, and far in time every other state sits in its well.
    late = double_well([0.0, 1000.0], [-1.0, 0.0, 1.0, -1e-3, 2.0])
    np.testing.assert_array_equal(late, [[-1, -1], [0, 0], [1, 1], [-1e-3, -1], [2, 1]])


def test_damped_oscillator_solves_its_ode():
    times = np.linspace(0.0, 20.0, 401)
    k, c, x0 = np.array([1.0, 4.0, 2.5]), np.array([0.2, 0.5, 0.0]), np.array([1.0, -0.5, 2.0])
    exact = damped_oscillator(times, k, c, x0)
    assert exact.shape == (3, 401)
    for row, (kk, cc, start) in zip(exact, zip(k, c, x0, strict=True), strict=True):
        run = reference_run(
            lambda t, y, kk=kk, cc=cc: [y[1], -cc * y[1] - kk * y[0]],
            [start, 0.0],
            times,
            atol=1e-14,
        )
        assert np.abs(row - run[0]).max() <= BOUND * abs(start)
    with pytest.raises(ValueError, match="underdamped"):
        damped_oscillator(times, 1.0, 2.0)


def test_quarter_car_linear_solves_its_ode():
    p = {"ms": 250.0, "mu": 35.0, "k": 2.0e4, "c": 1000.0, "kt": 1.5e5}
    amplitude, frequency = 0.05, 1.3
    times = np.linspace(0.0, 6.0, 601)
    exact = quarter_car_linear(times, **p, amplitude=amplitude, frequency=frequency)
    assert exact.shape == (4, 601)

    def rhs(t, y):
        # The suspension's force on the wheel (minus that on the body), and the road.
        x1, x2, v1, v2 = y
        force = p["k"] * (x1 - x2) + p["c"] * (v1 - v2)
        road = amplitude * np.sin(2 * np.pi * frequency * t)
        return [v1, v2, -force / p["ms"], (force + p["kt"] * (road - x2)) / p["mu"]]

    run = reference_run(rhs, np.zeros(4), times, atol=1e-14)
    for state, row in zip(run, exact, strict=True):
        assert np.abs(row - state).max() <= BOUND * np.abs(state).max()


@pytest.mark.parametrize(
    ("sigma", "rho", "beta"), [(1.0, 10.0, 1.0), (10.0, 28.0, 8.0 / 3.0), (10.0, 0.5, 8.0 / 3.0)]
)
def test_lorenz_equilibria_are_the_zeros_of_the_field(sigma, rho, beta):
    points = lorenz_equilibria(rho, beta)
    assert points.shape == ((3, 3) if rho > 1 else (1, 3))
    assert len({tuple(p) for p in points}) == len(points)
    for x, y, z in points:
        field = [sigma * (y - x), x * (rho - z) - y, x * y - beta * z]
        assert np.abs(field).max() <= 1e-13 * rho**2


def test_statistical_linearization_is_the_root_of_its_equation():
    """Part II's oscillator (m, c, h, A, ω): the one root on a fine log grid, by brentq."""
    m, c, h = 10.0, 7.2, 1.0
    amplitudes, omegas = [4.0, 2.0], [3.2 * 6 * np.pi / 100, 3.2 * 14 * np.pi / 100]

    def gap(e):
        k = 3 * h * e
        return (
            sum(
                a**2 / ((k - m * w**2) ** 2 + (c * w) ** 2)
                for a, w in zip(amplitudes, omegas, strict=True)
            )
            - e
        )

    grid = np.geomspace(1e-6, 1e3, 2001)
    values = np.array([gap(e) for e in grid])
    (i,) = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
    root = brentq(gap, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-14)
    found = statistical_linearization(m, c, h, amplitudes, omegas)
    assert found == pytest.approx(root, rel=1e-12)


def test_statistical_linearization_is_exact_without_the_cubic_term_and_finds_jumps():
    # h = 0: the linear oscillator's stationary mean square, Σ A² |H(ω)|².
    linear = statistical_linearization(2.0, 0.5, 0.0, [1.0, 3.0], [0.7, 2.0])
    expected = 1 / ((2 * 0.7**2) ** 2 + 0.35**2) + 9 / ((2 * 4.0) ** 2 + 1.0**2)
    assert linear == pytest.approx(expected, rel=1e-13)
    # One lightly damped mode near resonance: e ((3e - 1)² + c²) = A² has three roots.
    with pytest.raises(ValueError, match="3 roots"):
        statistical_linearization(1.0, 0.05, 1.0, [0.1], [1.0])


# --------------------------------------------------------------------------- random fields

PERIOD, VARIANCES = 100.0, [0.2**2, 0.1**2]
LENGTHS = [PERIOD / (6 * np.pi), PERIOD / (14 * np.pi)]


def test_cosine_covariance_kl_solves_the_eigenproblem():
    """The trapezoidal rule on a full period integrates trigonometric polynomials of degree
    below the number of points exactly: the integral equation holds to round-off."""
    y = np.linspace(0.0, PERIOD, 64, endpoint=False)
    weight = PERIOD / y.size
    x = np.array([0.0, 7.0, 31.0, 77.0, 99.5])
    values, functions = cosine_covariance_kl(x, VARIANCES, LENGTHS, PERIOD)
    np.testing.assert_allclose(values, [2.0, 2.0, 0.5, 0.5], rtol=1e-14)
    _, at_nodes = cosine_covariance_kl(y, VARIANCES, LENGTHS, PERIOD)
    integral = weight * cosine_covariance(x, y, VARIANCES, LENGTHS) @ at_nodes
    np.testing.assert_allclose(integral, functions * values, atol=1e-13)
    np.testing.assert_allclose(weight * at_nodes.T @ at_nodes, np.eye(4), atol=1e-14)
    # Mercer: the four pairs are the whole kernel (it has rank 4).
    rebuilt = (functions * values) @ functions.T
    np.testing.assert_allclose(rebuilt, cosine_covariance(x, x, VARIANCES, LENGTHS), atol=1e-15)


def test_cosine_covariance_kl_needs_a_common_period():
    with pytest.raises(ValueError, match="whole numbers"):
        cosine_covariance_kl([0.0], [1.0], [1.0], PERIOD)
    with pytest.raises(ValueError, match="distinct"):
        cosine_covariance_kl([0.0], [1.0, 1.0], [LENGTHS[0]] * 2, PERIOD)


# --------------------------------------------------------------------------- germ moments


def _quad(f, low, high, **options):
    value, _ = quad(f, low, high, epsabs=1e-13, epsrel=1e-13, limit=200, **options)
    return value


@pytest.mark.parametrize("m", range(13))
def test_germ_moments_against_adaptive_quadrature(m):
    """quad is asked for 1e-13 (relative, or absolute for the vanishing odd moments); 1e-10
    and 1e-12 leave room for its error estimate."""
    normal = _quad(lambda x: x**m * np.exp(-(x**2) / 2), -np.inf, np.inf) / np.sqrt(2 * np.pi)
    assert normal_moment(m) == pytest.approx(normal, rel=1e-10, abs=1e-12)
    assert uniform_moment(m) == pytest.approx(_quad(lambda x: x**m / 2, -1, 1), abs=1e-12)
    for alpha in (0.0, 1.5):
        integral = _quad(lambda x, a=alpha: x ** (m + a) * np.exp(-x), 0, np.inf)
        assert gamma_moment(m, alpha) == pytest.approx(
            integral / gamma_function(alpha + 1), rel=1e-10
        )
    for alpha, beta in [(0.0, 0.0), (1.0, 1.0), (0.5, 2.5), (-0.5, -0.5)]:
        # quad's 'alg' weight (x + 1)^beta (1 - x)^alpha takes the endpoint singularities.
        integral = _quad(lambda x: x**m, -1, 1, weight="alg", wvar=(beta, alpha))
        mass = 2 ** (alpha + beta + 1) * beta_function(alpha + 1, beta + 1)
        assert jacobi_moment(m, alpha, beta) == pytest.approx(integral / mass, rel=1e-10, abs=1e-12)


# --------------------------------------------------------------------------- Ishigami


def test_ishigami_is_the_function_of_the_literature():
    x = np.array([[np.pi / 2, np.pi / 2, 1.0], [0.0, 0.0, 2.0], [-np.pi / 2, 0.0, 2.0]])
    np.testing.assert_allclose(ishigami(x), [1 + 7 + 0.1, 0.0, -1 - 1.6], rtol=1e-15)
    np.testing.assert_allclose(ishigami(x, a=2.0, b=1.0)[0], 4.0, rtol=1e-15)


@pytest.mark.parametrize(("a", "b"), [(7.0, 0.1), (2.0, 0.5)])
def test_ishigami_moments_against_tensor_quadrature(a, b):
    """A 40³ Gauss–Legendre rule: exact for the x3 polynomial, and for sin x1, sin² x2 its
    error is below (π/2)^80 / 80! ~ 1e-103, so round-off is all that separates them."""
    nodes, weights = np.polynomial.legendre.leggauss(40)
    nodes, weights = np.pi * nodes, weights / 2
    grid = np.array(list(itertools.product(nodes, repeat=3)))
    values = ishigami(grid, a, b).reshape(40, 40, 40)

    def average(f, axes):
        for axis in sorted(axes, reverse=True):
            f = np.tensordot(f, weights, axes=([axis], [0]))
        return f

    mean = average(values, (0, 1, 2))
    variance = average((values - mean) ** 2, (0, 1, 2))
    others = [tuple(j for j in range(3) if j != i) for i in range(3)]
    first = [average((average(values, o) - mean) ** 2, (0,)) / variance for o in others]
    # Total index: the expected variance over x_i with the others fixed.
    total = [
        average(average((values - np.expand_dims(average(values, (i,)), i)) ** 2, (i,)), (0, 1))
        / variance
        for i in range(3)
    ]
    exact = ishigami_moments(a, b)
    assert exact.mean == pytest.approx(mean, rel=1e-12)
    assert exact.variance == pytest.approx(variance, rel=1e-12)
    np.testing.assert_allclose(exact.first, first, atol=1e-12)
    np.testing.assert_allclose(exact.total, total, atol=1e-12)


# --------------------------------------------------------------------------- the module


def test_the_module_is_pure_math_and_cheap_to_import():
    tree = ast.parse(Path(references.__file__).read_text())
    imported = {
        alias.name.split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in (node.names if isinstance(node, ast.Import) else [ast.alias(node.module)])
    }
    assert imported <= {
        "__future__",
        "collections",
        "fractions",
        "math",
        "numpy",
        "scipy",
        "typing",
    }
    code = "import sys, pcmb.references; print('scipy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    assert all(callable(getattr(references, name)) for name in references.__all__)
