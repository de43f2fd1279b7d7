"""Exact references: closed-form solutions and statistics with known answers.

The problems the tests, benchmarks and scripts measure pcmb and the native models against
(like SALib's test problems): pure math on numpy arrays, with no knowledge of pcmb's classes
or of the simulators in ``models/``. Each is checked against an independent computation in
``tests/test_references.py``. scipy is imported inside the functions that need it, so
importing this module stays cheap; it is not exported from ``pcmb``::

    from pcmb.references import double_well, ishigami, ishigami_moments

"Part II" is Sandu, Sandu & Ahmadian, Modeling multibody systems with uncertainties, Part II:
Numerical applications, Multibody Syst. Dyn. 15 (2006), whose cases ``configs/`` reproduce.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "IshigamiMoments",
    "borehole",
    "borehole_bounds",
    "bouncing_ball",
    "cosine_covariance",
    "cosine_covariance_kl",
    "damped_oscillator",
    "double_well",
    "exponential_kl_eigenvalues",
    "gamma_moment",
    "ishigami",
    "ishigami_moments",
    "jacobi_moment",
    "lognormal_moments",
    "lorenz_equilibria",
    "normal_moment",
    "pendulum_angle",
    "piston",
    "piston_bounds",
    "piston_moments",
    "quarter_car_linear",
    "statistical_linearization",
    "uniform_moment",
    "wing_weight",
    "wing_weight_bounds",
    "wing_weight_moments",
]

Array = NDArray[np.float64]


def _outer(values: Array, t: Array) -> Array:
    """``values`` with one trailing axis of length 1 per axis of ``t`` (for an outer product)."""
    return values.reshape(values.shape + (1,) * t.ndim)


# --------------------------------------------------------------------------- ODE solutions


def pendulum_angle(
    t: ArrayLike, length: ArrayLike, theta0: ArrayLike = np.pi / 4, g: float = 9.81
) -> Array:
    """Angle of a simple pendulum released from rest, θ'' = −(g/L) sin θ, θ(0) = θ0.

    θ(t) = 2 asin(k sn(K(k) − √(g/L) t, k)), k = sin(θ0/2) (scipy's ``ellipj`` and
    ``ellipk`` take the parameter m = k²).

    Parameters
    ----------
    t : array_like, shape (T,)
        Times (s).
    length : array_like, shape S, e.g. (N,)
        Rod lengths L > 0 (m).
    theta0 : array_like, broadcastable with ``length``
        Release angles (rad), |θ0| < π; the pendulum starts at rest.
    g : float
        Gravitational acceleration (m/s²).

    Returns
    -------
    ndarray, shape S + (T,)
        θ (rad); (N, T) for N lengths.

    Notes
    -----
    Source: Lawden, Elliptic Functions and Applications (Springer 1989); Part II Eq. 28.
    """
    from scipy.special import ellipj, ellipk

    t = np.asarray(t, dtype=float)
    length, theta0 = np.broadcast_arrays(
        np.asarray(length, dtype=float), np.asarray(theta0, dtype=float)
    )
    if np.any(length <= 0) or np.any(np.abs(theta0) >= np.pi):
        raise ValueError("pendulum_angle needs L > 0 and |theta0| < pi")
    k = _outer(np.sin(theta0 / 2), t)
    phase = ellipk(k**2) - _outer(np.sqrt(g / length), t) * t
    return 2 * np.arcsin(k * ellipj(phase, k**2)[0])


def bouncing_ball(
    h0: ArrayLike, t: ArrayLike, gravity: float = 9.81, restitution: float = 0.8
) -> Array:
    """(N, T) height of balls dropped at rest from heights ``h0`` (N,) onto a floor that
    returns ``restitution`` of the speed at each bounce; at rest on it once the bounces,
    ever shorter, have all happened."""
    h0 = np.asarray(h0, dtype=float)[:, None]
    t = np.asarray(t, dtype=float)[None, :]
    height = h0 - gravity * t**2 / 2
    start, speed = np.sqrt(2 * h0 / gravity), restitution * np.sqrt(2 * gravity * h0)
    for _ in range(80):  # at 0.8 per bounce the speed is 1e-8 of the first after 80
        since = t - start
        height = np.where(since >= 0, speed * since - gravity * since**2 / 2, height)
        start, speed = start + 2 * speed / gravity, speed * restitution
    return np.where(t >= start, 0.0, height)


def lognormal_moments(a: ArrayLike) -> tuple[Array, Array]:
    """Mean and std of exp(a z), z ~ N(0, 1): e^{a²/2} and √(e^{a²} (e^{a²} - 1))."""
    a2 = np.asarray(a, dtype=float) ** 2
    return np.exp(a2 / 2), np.sqrt(np.exp(a2) * np.expm1(a2))


def double_well(t: ArrayLike, x0: ArrayLike) -> Array:
    """Solution of the double-well problem x' = x − x³, x(0) = x0.

    x(t) = x0 eᵗ / √(1 + x0² (e^{2t} − 1)), evaluated as x0 / √(x0² + (1 − x0²) e^{−2t}),
    which does not overflow for large t.

    Parameters
    ----------
    t : array_like, shape (T,)
        Times, t >= 0.
    x0 : array_like, shape S, e.g. (N,)
        Initial states.

    Returns
    -------
    ndarray, shape S + (T,)
        x; (N, T) for N initial states.

    Notes
    -----
    Source: separation of variables (a Bernoulli equation); Part II Eq. 25.
    """
    t = np.asarray(t, dtype=float)
    x0 = _outer(np.asarray(x0, dtype=float), t)
    with np.errstate(invalid="ignore"):  # 0/0 where x0 = 0 and e^{-2t} underflows
        x = x0 / np.sqrt(x0**2 + (1 - x0**2) * np.exp(-2 * t))
    return np.where(x0 == 0, 0.0, x)


def double_well_moments(t: ArrayLike, low: float, high: float) -> tuple[Array, Array]:
    """Mean and standard deviation of the double well's x(t) for x0 ~ U[low, high].

    With a = e^{−2t}, b = 1 − a and r(x0) = √(b x0² + a), x = x0 / r(x0), so
    E[x] = (r(high) − r(low)) / (b (high − low)) = (low + high) / (r(low) + r(high)) (no
    cancellation at small t) and, from x² = (1 − a / r²) / b,
    E[x²] = [G(high) − G(low)] / (high − low), G(x0) = (x0 − √(a/b) arctan(x0 √(b/a))) / b,
    whose cancellation for b < 1e-4 is avoided by its series x0³/(3a) − b x0⁵/(5a²) + b² x0⁷/(7a³).

    Parameters
    ----------
    t : array_like, shape (T,)
        Times, t >= 0.
    low, high : float
        The uniform's support.

    Returns
    -------
    mean, std : ndarray, shape (T,)
    """
    a = np.exp(-2.0 * np.asarray(t, dtype=float))
    b = -np.expm1(-2.0 * np.asarray(t, dtype=float))
    roots = [np.sqrt(b * x0**2 + a) for x0 in (low, high)]
    mean = (high + low) / (roots[0] + roots[1])
    small = b < 1e-4
    safe = np.where(small, 1.0, b)

    def antiderivative(x0: float) -> Array:
        with np.errstate(divide="ignore", invalid="ignore"):
            exact = (x0 - np.sqrt(a / safe) * np.arctan(x0 * np.sqrt(safe / a))) / safe
        series = x0**3 / (3 * a) - b * x0**5 / (5 * a**2) + b**2 * x0**7 / (7 * a**3)
        return np.where(small, series, exact)

    square = (antiderivative(high) - antiderivative(low)) / (high - low)
    return mean, np.sqrt(np.maximum(square - mean**2, 0.0))


def damped_oscillator(t: ArrayLike, k: ArrayLike, c: ArrayLike, x0: ArrayLike = 1.0) -> Array:
    """Free underdamped oscillator x'' + c x' + k x = 0 from rest at x(0) = x0.

    x(t) = x0 e^{−ct/2} (cos ω t + c/(2ω) sin ω t), ω = √(k − c²/4).

    Parameters
    ----------
    t : array_like, shape (T,)
        Times.
    k, c, x0 : array_like, broadcastable to a shape S, e.g. (N,)
        Stiffness and damping per unit mass (c² < 4k) and the initial displacement.

    Returns
    -------
    ndarray, shape S + (T,)
        x; (N, T) for N oscillators.

    Notes
    -----
    Source: Thomson & Dahleh, Theory of Vibration with Applications, 5th ed. (1998), ch. 2.
    """
    t = np.asarray(t, dtype=float)
    k, c, x0 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k, c, x0)))
    if np.any(c**2 >= 4 * k):
        raise ValueError("damped_oscillator needs an underdamped oscillator, c² < 4k")
    decay, omega = _outer(c / 2, t), _outer(np.sqrt(k - c**2 / 4), t)
    return (
        _outer(x0, t) * np.exp(-decay * t) * (np.cos(omega * t) + decay / omega * np.sin(omega * t))
    )


def quarter_car_linear(
    t: ArrayLike,
    *,
    ms: float,
    mu: float,
    k: float,
    c: float,
    kt: float,
    amplitude: float,
    frequency: float,
) -> Array:
    """Linear quarter car from rest on the road z = A sin(2π f t): x1, x2, v1, v2.

    Body (ms) on a spring k and damper c over the wheel (mu), the wheel on a tire spring kt
    over the road. With x' = S x + b sin(ωt), x(0) = 0: x = Im(X e^{iωt}) − exp(S t) Im X,
    X = (iω − S)⁻¹ b, the steady response plus the free response that cancels it at t = 0;
    exp(S t) by the eigendecomposition of S.

    Parameters
    ----------
    t : array_like, shape (T,)
        Times (s).
    ms, mu, k, c, kt : float
        Body and wheel masses (kg), suspension stiffness (N/m) and damping (N·s/m), tire
        stiffness (N/m).
    amplitude, frequency : float
        Road amplitude A (m) and frequency f (Hz).

    Returns
    -------
    ndarray, shape (4, T)
        Body and wheel displacements x1, x2 (m) and velocities v1, v2 (m/s).

    Notes
    -----
    Source: Gillespie, Fundamentals of Vehicle Dynamics (SAE 1992), ch. 5; Part II Eq. 1–5
    with a linear spring.
    """
    t = np.asarray(t, dtype=float)
    system = np.array(
        [
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [-k / ms, k / ms, -c / ms, c / ms],
            [k / mu, -(k + kt) / mu, c / mu, -c / mu],
        ]
    )
    forcing = np.array([0.0, 0.0, 0.0, kt * amplitude / mu])
    omega = 2 * np.pi * frequency
    steady = np.linalg.solve(1j * omega * np.eye(4) - system, forcing)
    eigenvalues, vectors = np.linalg.eig(system)
    start = np.linalg.solve(vectors, -steady.imag)
    free = vectors @ (start[:, None] * np.exp(np.multiply.outer(eigenvalues, t)))
    return np.imag(steady[:, None] * np.exp(1j * omega * t)) + free.real


def lorenz_equilibria(rho: float, beta: float) -> Array:
    """Equilibria of the Lorenz system x' = σ(y − x), y' = x(ρ − z) − y, z' = xy − βz.

    (±√(β(ρ−1)), ±√(β(ρ−1)), ρ − 1) for ρ > 1, and the origin; σ plays no part.

    Parameters
    ----------
    rho, beta : float
        ρ and β (> 0).

    Returns
    -------
    ndarray, shape (3, 3) for ρ > 1, else (1, 3)
        One equilibrium (x, y, z) per row: C+, C−, then the origin.

    Notes
    -----
    Source: Lorenz, Deterministic nonperiodic flow, J. Atmos. Sci. 20 (1963); Part II Eq. 26.
    """
    origin = np.zeros((1, 3))
    if rho <= 1:
        return origin
    r = math.sqrt(beta * (rho - 1))
    return np.vstack([[[r, r, rho - 1], [-r, -r, rho - 1]], origin])


def statistical_linearization(
    m: float, c: float, h: float, amplitudes: Sequence[float], frequencies: Sequence[float]
) -> float:
    """Mean square E[x²] of m x'' + c x' + h x³ = Σ_i A_i (ξ_i1 cos ω_i t + ξ_i2 sin ω_i t).

    The Gaussian closure replaces h x³ by k_eq x, k_eq = 3 h E[x²]; the stationary response to
    the modes (independent standard normal ξ) then has
    E[x²] = Σ_i A_i² / ((k_eq − m ω_i²)² + c² ω_i²), a polynomial equation in E[x²] of degree
    2M + 1 (M modes) solved here by its roots. An approximation of the nonlinear response,
    exact only for h = 0.

    Parameters
    ----------
    m, c, h : float
        Mass, damping and cubic stiffness (h >= 0).
    amplitudes, frequencies : sequence of float, length M
        A_i and ω_i of the forcing modes.

    Returns
    -------
    float
        The positive root E[x²].

    Raises
    ------
    ValueError
        If the equation has several positive roots (the linearized system's jump region).

    Notes
    -----
    Source: Roberts & Spanos, Random Vibration and Statistical Linearization (Wiley 1990);
    Part II Eq. 21–23.
    """
    poly = np.polynomial.Polynomial
    denominators = [
        poly([-m * w**2, 3 * h]) ** 2 + poly([(c * w) ** 2]) for w in np.asarray(frequencies, float)
    ]
    equation = poly([0.0, 1.0]) * math.prod(denominators, start=poly([1.0]))
    for i, a in enumerate(np.asarray(amplitudes, float)):
        equation -= a**2 * math.prod(denominators[:i] + denominators[i + 1 :], start=poly([1.0]))
    equation = equation.trim()
    roots = equation.roots()
    real = roots[np.abs(roots.imag) <= 1e-8 * np.maximum(1.0, np.abs(roots))].real
    positive = np.unique(real[real > 0])
    slope = equation.deriv()
    for _ in range(3):  # Newton's method polishes the companion-matrix roots
        positive = positive - equation(positive) / slope(positive)
    if positive.size != 1:
        raise ValueError(f"statistical linearization has {positive.size} roots: {positive}")
    return float(positive[0])


# --------------------------------------------------------------------------- random fields


def cosine_covariance(
    x1: ArrayLike, x2: ArrayLike, variances: Sequence[float], lengths: Sequence[float]
) -> Array:
    """Covariance R(x1, x2) = Σ_n σ_n² cos((x1 − x2)/L_n) of a sum of random-phase cosines.

    Parameters
    ----------
    x1 : array_like, shape (P,)
    x2 : array_like, shape (Q,)
        Positions.
    variances, lengths : sequence of float, length M
        σ_n² and L_n of each mode.

    Returns
    -------
    ndarray, shape (P, Q)

    Notes
    -----
    Source: Part II Eq. 12 (the uncertain terrain, M = 2).
    """
    lag = np.subtract.outer(np.asarray(x1, dtype=float), np.asarray(x2, dtype=float))
    return sum(
        (s2 * np.cos(lag / ell) for s2, ell in zip(variances, lengths, strict=True)),
        start=np.zeros_like(lag),
    )


def cosine_covariance_kl(
    x: ArrayLike, variances: Sequence[float], lengths: Sequence[float], period: float
) -> tuple[Array, Array]:
    """Karhunen–Loève eigenpairs of :func:`cosine_covariance` on [0, D], D a common period.

    When D/L_n = 2π j_n with distinct integers j_n, cos(x/L_n) and sin(x/L_n) are orthogonal
    on [0, D] and ∫ R(x, y) φ(y) dy = (D σ_n²/2) φ(x) for both: each mode gives a double
    eigenvalue D σ_n²/2 with eigenfunctions √(2/D) cos(x/L_n), √(2/D) sin(x/L_n).

    Parameters
    ----------
    x : array_like, shape (P,)
        Where to evaluate the eigenfunctions.
    variances, lengths : sequence of float, length M
        σ_n² and L_n, as for :func:`cosine_covariance`.
    period : float
        D.

    Returns
    -------
    eigenvalues : ndarray, shape (2M,)
        D σ_n²/2, each twice, in the order of the modes.
    eigenfunctions : ndarray, shape (P, 2M)
        cos then sin of each mode, orthonormal in L²(0, D).

    Notes
    -----
    Source: Ghanem & Spanos, Stochastic Finite Elements: A Spectral Approach (1991), ch. 2.
    """
    turns = period / (2 * np.pi * np.asarray(lengths, dtype=float))
    if np.any(np.abs(turns - np.round(turns)) > 1e-9 * turns) or np.any(np.round(turns) < 1):
        raise ValueError("cosine_covariance_kl needs period / (2π L_n) to be whole numbers")
    if np.unique(np.round(turns)).size != turns.size:
        raise ValueError("cosine_covariance_kl needs distinct lengths")
    x = np.asarray(x, dtype=float)
    phases = np.divide.outer(x, np.asarray(lengths, dtype=float))
    functions = np.stack([np.cos(phases), np.sin(phases)], axis=-1).reshape(x.size, -1)
    eigenvalues = np.repeat(period * np.asarray(variances, dtype=float) / 2, 2)
    return eigenvalues, functions * np.sqrt(2 / period)


def exponential_kl_eigenvalues(variance: float, length: float, width: float, count: int) -> Array:
    """The largest ``count`` Karhunen–Loève eigenvalues of σ² exp(-|x1 − x2|/ℓ) on an
    interval of length ``width``.

    With c = 1/ℓ and a = width/2, the eigenfunctions are cos(ω x) for the roots of
    c − ω tan(ω a) = 0 and sin(ω x) for those of ω + c tan(ω a) = 0 (x from the centre), and
    λ = 2cσ²/(ω² + c²). Both equations together are c ω cos(2ωa) + (c² − ω²) sin(2ωa)/2 = 0,
    which has exactly one root in each interval ((n − 1)π/(2a), nπ/(2a)), n = 1, 2, ...:
    found by bracketing, to machine precision.

    Parameters
    ----------
    variance : float
        σ².
    length : float
        ℓ.
    width : float
        b − a.
    count : int
        How many eigenvalues.

    Returns
    -------
    ndarray, shape (count,)
        Decreasing.

    Notes
    -----
    Source: Ghanem & Spanos, Stochastic Finite Elements: A Spectral Approach (1991), §2.3.3;
    Van Trees, Detection, Estimation and Modulation Theory I (1968), §3.3.
    """
    from scipy.optimize import brentq

    c, a = 1.0 / length, width / 2.0

    def equation(w: float) -> float:
        return c * w * math.cos(2 * w * a) + (c * c - w * w) * math.sin(2 * w * a) / 2

    step = math.pi / (2 * a)
    roots = [
        brentq(equation, max((n - 1) * step, 1e-12 * step), n * step, xtol=1e-15, rtol=1e-15)
        for n in range(1, count + 1)
    ]
    return 2 * c * variance / (np.square(roots) + c * c)


# --------------------------------------------------------------------------- germ moments


def normal_moment(m: int) -> float:
    """E[ξ^m] of a standard normal ξ: (m − 1)!! for even m, 0 for odd m.

    Notes
    -----
    Source: Johnson, Kotz & Balakrishnan, Continuous Univariate Distributions 1 (1994).
    """
    return 0.0 if m % 2 else float(math.prod(range(m - 1, 0, -2)))


def uniform_moment(m: int) -> float:
    """E[ξ^m] of ξ ~ U[−1, 1]: 1/(m + 1) for even m, 0 for odd m.

    Notes
    -----
    Source: direct integration.
    """
    return 0.0 if m % 2 else 1.0 / (m + 1)


def gamma_moment(m: int, alpha: float) -> float:
    """E[ξ^m] of ξ with density ∝ ξ^α e^{−ξ} on (0, ∞) (Laguerre weight): (α + 1)_m.

    Notes
    -----
    Source: Johnson, Kotz & Balakrishnan, Continuous Univariate Distributions 1 (1994).
    """
    return float(math.prod(alpha + 1 + r for r in range(m)))


def jacobi_moment(m: int, alpha: float, beta: float) -> float:
    """E[ξ^m] of ξ with density ∝ (1 − ξ)^α (1 + ξ)^β on [−1, 1] (Jacobi weight).

    ξ = 2u − 1 with u ~ Beta(β + 1, α + 1), E[u^j] = Π_{r<j} (β + 1 + r)/(α + β + 2 + r); the
    alternating binomial sum is done in exact rational arithmetic (it cancels badly in
    floats), so the result is correctly rounded.

    Notes
    -----
    Source: Johnson, Kotz & Balakrishnan, Continuous Univariate Distributions 2 (1995).
    """
    a, b = Fraction(beta) + 1, Fraction(alpha) + 1
    raw = [Fraction(1)]
    for r in range(m):
        raw.append(raw[-1] * (a + r) / (a + b + r))
    return float(sum(math.comb(m, j) * (-1) ** (m - j) * 2**j * raw[j] for j in range(m + 1)))


# --------------------------------------------------------------------------- Borehole


def borehole_bounds() -> tuple[tuple[float, float], ...]:
    """The ranges of the Borehole function's uniform inputs rw, r, Tu, Hu, Tl, Hl, L, Kw."""
    return (
        (0.05, 0.15),
        (100.0, 50_000.0),
        (63_070.0, 115_600.0),
        (990.0, 1110.0),
        (63.1, 116.0),
        (700.0, 820.0),
        (1120.0, 1680.0),
        (9855.0, 12_045.0),
    )


def borehole(x: ArrayLike) -> Array:
    """Water flow through a borehole, m³/year (Harper & Gupta, 1983).

    Parameters
    ----------
    x : array_like, shape (N, 8)
        rw, r, Tu, Hu, Tl, Hl, L, Kw (the ranges of :func:`borehole_bounds`).

    Returns
    -------
    ndarray, shape (N,)
    """
    rw, r, tu, hu, tl, hl, length, kw = np.asarray(x, dtype=float).T
    log = np.log(r / rw)
    return 2 * np.pi * tu * (hu - hl) / (log * (1 + 2 * length * tu / (log * rw**2 * kw) + tu / tl))


# --------------------------------------------------------------------------- Piston, Wing weight


def piston_bounds() -> dict[str, tuple[float, float]]:
    """The Piston function's uniform inputs and their ranges, in order (Kenett & Zacks, 1998)."""
    return {
        "m": (30.0, 60.0),
        "s": (0.005, 0.020),
        "v0": (0.002, 0.010),
        "k": (1000.0, 5000.0),
        "p0": (90_000.0, 110_000.0),
        "ta": (290.0, 296.0),
        "t0": (340.0, 360.0),
    }


def piston_moments() -> tuple[float, float]:
    """The Piston function's mean and std: a tensor Gauss–Legendre rule of 12^7 points (orders
    10 and 12 agree to 3e-10 of the std)."""
    return 0.462496236201101, 0.139500546566524


def piston(x: ArrayLike) -> Array:
    """A piston's cycle time, s: x (N, 7) in the order of :func:`piston_bounds`; (N,)."""
    m, s, v0, k, p0, ta, t0 = np.asarray(x, dtype=float).T
    a = p0 * s + 19.62 * m - k * v0 / s
    v = s / (2 * k) * (np.sqrt(a**2 + 4 * k * p0 * v0 * ta / t0) - a)
    return 2 * np.pi * np.sqrt(m / (k + s**2 * p0 * v0 * ta / (t0 * v**2)))


def wing_weight_bounds() -> dict[str, tuple[float, float]]:
    """The Wing weight function's inputs and their ranges, in order (Forrester et al., 2008)."""
    return {
        "sw": (150.0, 200.0),
        "wfw": (220.0, 300.0),
        "a": (6.0, 10.0),
        "sweep": (-10.0, 10.0),
        "q": (16.0, 45.0),
        "taper": (0.5, 1.0),
        "tc": (0.08, 0.18),
        "nz": (2.5, 6.0),
        "wdg": (1700.0, 2500.0),
        "wp": (0.025, 0.08),
    }


def wing_weight_moments() -> tuple[float, float]:
    """The Wing weight function's mean and std, from its 1-D integrals (a product of 1-D
    factors plus sw wp)."""
    return 268.075236831743, 48.082494458102


def wing_weight(x: ArrayLike) -> Array:
    """A light aircraft's wing weight, lb: x (N, 10) in the order of
    :func:`wing_weight_bounds`; (N,)."""
    sw, wfw, a, sweep, q, taper, tc, nz, wdg, wp = np.asarray(x, dtype=float).T
    cos = np.cos(np.deg2rad(sweep))
    structure = (a / cos**2) ** 0.6 * q**0.006 * taper**0.04 * (100 * tc / cos) ** -0.3
    return 0.036 * sw**0.758 * wfw**0.0035 * structure * (nz * wdg) ** 0.49 + sw * wp


# --------------------------------------------------------------------------- Ishigami


def ishigami(x: ArrayLike, a: float = 7.0, b: float = 0.1) -> Array:
    """Ishigami function f = sin x1 + a sin² x2 + b x3⁴ sin x1, inputs U[−π, π]³.

    Parameters
    ----------
    x : array_like, shape (N, 3)
        Points.
    a, b : float
        The function's constants (7 and 0.1 are the usual ones).

    Returns
    -------
    ndarray, shape (N,)

    Notes
    -----
    Source: Ishigami & Homma, ISUMA '90 (1990).
    """
    x = np.asarray(x, dtype=float)
    return np.sin(x[..., 0]) + a * np.sin(x[..., 1]) ** 2 + b * x[..., 2] ** 4 * np.sin(x[..., 0])


class IshigamiMoments(NamedTuple):
    """Mean, variance, first-order and total Sobol' indices (each (3,)) of :func:`ishigami`."""

    mean: float
    variance: float
    first: Array
    total: Array


def ishigami_moments(a: float = 7.0, b: float = 0.1) -> IshigamiMoments:
    """Exact statistics of :func:`ishigami` over U[−π, π]³.

    V1 = (1 + b π⁴/5)²/2, V2 = a²/8, V13 = b² π⁸ (1/18 − 1/50) (the only interaction);
    mean a/2, variance V1 + V2 + V13.

    Returns
    -------
    IshigamiMoments
        ``mean``, ``variance``, ``first`` (3,) and ``total`` (3,) Sobol' indices.

    Notes
    -----
    Source: Homma & Saltelli, Reliab. Eng. Syst. Saf. 52 (1996).
    """
    v1 = 0.5 * (1 + b * np.pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * np.pi**8 * (1 / 18 - 1 / 50)
    variance = v1 + v2 + v13
    first = np.array([v1, v2, 0.0]) / variance
    total = np.array([v1 + v13, v2, v13]) / variance
    return IshigamiMoments(a / 2, variance, first, total)
