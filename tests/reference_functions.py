"""Reference problems with closed-form statistics (test-only)."""

import numpy as np

ISHIGAMI_A, ISHIGAMI_B = 7.0, 0.1


def ishigami(x):
    """Ishigami function on θ ∈ [-π, π]³, x of shape (N, 3) -> (N,)."""
    a, b = ISHIGAMI_A, ISHIGAMI_B
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def ishigami_statistics():
    """Analytic mean, variance, first and total Sobol' indices (Ishigami & Homma 1990)."""
    a, b, pi = ISHIGAMI_A, ISHIGAMI_B, np.pi
    v1 = 0.5 * (1 + b * pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * pi**8 * (1 / 18 - 1 / 50)
    variance = v1 + v2 + v13
    first = np.array([v1, v2, 0.0]) / variance
    total = np.array([v1 + v13, v2, v13]) / variance
    return a / 2, variance, first, total
