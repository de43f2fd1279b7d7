"""Karhunen–Loève expansion of a random process (Part I Eq. 13–19, Part II Eq. 11–14).

A second-order process z(x) on [a, b] with covariance R(x1, x2) is written as

    z(x) = z̄(x) + Σ_k √λ_k g_k(x) ξ_k,

with (λ_k, g_k) the eigenpairs of the covariance operator ∫ R(x, y) g(y) dy = λ g(x)
and ξ_k uncorrelated standard germs (independent standard normals for a Gaussian
process). Each retained ξ_k becomes one more uncertain input of a study.

The eigenproblem is solved by the Nyström method on a Gauss–Legendre rule, which
converges exponentially for smooth kernels; eigenfunctions are evaluated anywhere by
Nyström interpolation. A stationary covariance can also come from a one-sided power
spectrum by Wiener–Khinchin, R(τ) = ∫_0^∞ S(ω) cos(ωτ) dω (:func:`spectral_covariance`),
or from a line spectrum R(τ) = Σ σ_i² cos(ω_i τ) (:func:`line_covariance`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["KarhunenLoeve", "Spectrum", "line_covariance", "spectral_covariance"]

Kernel = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]

#: Eigenvalues below this fraction of the largest are treated as zero (discretisation noise).
ZERO_RATIO = 1e-12


def line_covariance(omega: ArrayLike, variance: ArrayLike) -> Kernel:
    """Stationary covariance of a line spectrum: R(x1, x2) = Σ_i σ_i² cos(ω_i (x1 - x2)).

    Parameters
    ----------
    omega:
        (m,) angular frequencies (rad per unit of x).
    variance:
        (m,) variance σ_i² carried by each line.
    """
    omega = np.asarray(omega, dtype=float)
    variance = np.asarray(variance, dtype=float)
    if omega.shape != variance.shape or omega.ndim != 1:
        raise ValueError("omega and variance must be 1-D arrays of the same length")
    if np.any(variance < 0):
        raise ValueError("line variances must be >= 0")

    def kernel(x1: NDArray[np.float64], x2: NDArray[np.float64]) -> NDArray[np.float64]:
        lag = np.subtract.outer(x1, x2)
        return np.tensordot(np.cos(np.multiply.outer(lag, omega)), variance, axes=(-1, 0))

    return kernel


def spectral_covariance(omega: ArrayLike, density: ArrayLike) -> Kernel:
    """Stationary covariance from a sampled one-sided power spectral density (Wiener–Khinchin).

    R(τ) = ∫_0^∞ S(ω) cos(ωτ) dω, evaluated by the trapezoidal rule on the given samples;
    the spectrum must have decayed at the last frequency (the truncated tail is lost variance).

    Parameters
    ----------
    omega:
        (m,) increasing angular frequencies >= 0.
    density:
        (m,) one-sided PSD S(ω) >= 0, so that Var z = ∫_0^∞ S(ω) dω.
    """
    omega = np.asarray(omega, dtype=float)
    density = np.asarray(density, dtype=float)
    if omega.shape != density.shape or omega.ndim != 1 or omega.size < 2:
        raise ValueError("omega and density must be 1-D arrays of the same length >= 2")
    if np.any(np.diff(omega) <= 0) or omega[0] < 0:
        raise ValueError("omega must be increasing and >= 0")
    if np.any(density < 0):
        raise ValueError("a power spectral density must be >= 0")

    def kernel(x1: NDArray[np.float64], x2: NDArray[np.float64]) -> NDArray[np.float64]:
        lag = np.subtract.outer(x1, x2)
        return np.trapezoid(density * np.cos(np.multiply.outer(lag, omega)), omega, axis=-1)

    return kernel


class Spectrum:
    """What a truncated Karhunen–Loève expansion says of itself, from its kept
    ``eigenvalues`` and the ``total_variance`` of the process (both set by the subclass)."""

    eigenvalues: NDArray[np.float64]
    total_variance: float

    @property
    def terms(self) -> int:
        """K, the number of kept terms: the germ inputs the process adds to a study."""
        return self.eigenvalues.size

    @property
    def captured_energy(self) -> float:
        """Share of the total variance the kept terms carry, Σ_{k<=K} λ_k / ∫ R(x, x) dx."""
        return float(self.eigenvalues.sum() / self.total_variance)


@dataclass(frozen=True)
class KarhunenLoeve(Spectrum):
    """A truncated Karhunen–Loève expansion on an interval.

    Attributes
    ----------
    eigenvalues:
        (K,) retained eigenvalues λ_1 >= λ_2 >= ... > 0.
    domain:
        (a, b).
    nodes, weights:
        (J,) the Gauss–Legendre rule of the Nyström discretisation.
    vectors:
        (J, K) eigenfunctions at the nodes, normalised so ∫ g_k² dx = 1.
    kernel:
        The covariance R(x1, x2) (vectorised: outer over its arguments).
    total_variance:
        ∫ R(x, x) dx, the trace of the covariance operator.
    """

    eigenvalues: NDArray[np.float64]
    domain: tuple[float, float]
    nodes: NDArray[np.float64]
    weights: NDArray[np.float64]
    vectors: NDArray[np.float64]
    kernel: Kernel
    total_variance: float

    @classmethod
    def from_covariance(
        cls,
        kernel: Kernel,
        domain: tuple[float, float],
        *,
        points: int = 200,
        terms: int | None = None,
        energy: float = 0.99,
        ratio: float | None = None,
    ) -> KarhunenLoeve:
        """Solve the KL eigenproblem of ``kernel`` on ``domain`` by Nyström.

        Parameters
        ----------
        kernel:
            R(x1, x2) for 1-D arrays x1 (J1,), x2 (J2,), returning (J1, J2).
        domain:
            (a, b) with a < b.
        points:
            Gauss–Legendre points J of the discretisation.
        terms:
            Keep exactly this many terms (overrides ``energy``).
        energy:
            Keep the fewest terms whose eigenvalues capture this fraction of the total
            variance ∫ R(x, x) dx.
        ratio:
            Instead of ``energy``: keep every term with λ_k >= ratio · λ_1, i.e. stop where
            λ_{n+1} / λ_1 < ratio (overridden by ``terms``).

        Raises
        ------
        ValueError
            On an empty domain, bad truncation settings, or a kernel that is not a covariance
            (asymmetric or with clearly negative eigenvalues).
        """
        a, b = map(float, domain)
        if not a < b:
            raise ValueError(f"domain must be (a, b) with a < b, got {domain}")
        if points < 2:
            raise ValueError(f"points must be >= 2, got {points}")
        if not 0.0 < energy <= 1.0:
            raise ValueError(f"energy must be in (0, 1], got {energy}")
        if ratio is not None and not 0.0 < ratio <= 1.0:
            raise ValueError(f"ratio must be in (0, 1], got {ratio}")
        import scipy.special  # here: reading a config never needs it

        x, w = scipy.special.roots_legendre(points)
        nodes = 0.5 * (b - a) * x + 0.5 * (a + b)
        weights = 0.5 * (b - a) * w
        matrix = np.asarray(kernel(nodes, nodes), dtype=float)
        if not np.allclose(matrix, matrix.T, rtol=1e-10, atol=1e-14 * np.abs(matrix).max()):
            raise ValueError("the covariance kernel is not symmetric")
        root = np.sqrt(weights)
        values, vectors = np.linalg.eigh(root[:, None] * matrix * root[None, :])
        values, vectors = values[::-1], vectors[:, ::-1]
        if values[-1] < -1e-8 * values[0]:
            raise ValueError(
                f"the kernel is not positive semi-definite (eigenvalue {values[-1]:.3g})"
            )
        total = float(weights @ np.diag(matrix))
        positive = int(np.sum(values > ZERO_RATIO * values[0]))
        if terms is None and ratio is not None:
            terms = int(np.sum(values[:positive] >= ratio * values[0] * (1.0 - 1e-12)))
        elif terms is None:
            captured = np.cumsum(values[:positive]) / total
            terms = int(np.searchsorted(captured, energy * (1.0 - 1e-12)) + 1)
        if not 1 <= terms <= positive:
            raise ValueError(
                f"terms must be between 1 and the {positive} non-zero eigenvalues, got {terms}"
            )
        return cls(
            eigenvalues=values[:terms].copy(),
            domain=(a, b),
            nodes=nodes,
            weights=weights,
            vectors=vectors[:, :terms] / root[:, None],
            kernel=kernel,
            total_variance=total,
        )

    def eigenfunctions(self, x: ArrayLike) -> NDArray[np.float64]:
        """g_k(x) by Nyström interpolation, (M,) -> (M, K)."""
        x = np.asarray(x, dtype=float)
        return (self.kernel(x, self.nodes) * self.weights) @ self.vectors / self.eigenvalues

    def realize(self, x: ArrayLike, xi: ArrayLike) -> NDArray[np.float64]:
        """Fluctuation z(x) - z̄(x) = Σ_k √λ_k g_k(x) ξ_k for germs ξ.

        Parameters
        ----------
        x:
            (M,) positions.
        xi:
            (B, K) germ values, one row per realisation.

        Returns
        -------
        ndarray
            (B, M).
        """
        xi = np.atleast_2d(np.asarray(xi, dtype=float))
        if xi.shape[1] != self.terms:
            raise ValueError(f"xi must be (B, {self.terms}), got shape {xi.shape}")
        return (xi * np.sqrt(self.eigenvalues)) @ self.eigenfunctions(x).T
