"""One-dimensional orthonormal polynomial families and their Gauss rules.

Each family is orthonormal under the *probability* measure of its germ variable ξ, so
that ``E[p_i(ξ) p_j(ξ)] = δ_ij`` and ``p_0 = 1``. The polynomials are evaluated by the
three-term recurrence of the monic family,

    p̃_{k+1}(x) = (x - a_k) p̃_k(x) - b_k p̃_{k-1}(x),

rescaled to unit norm, which gives the stable orthonormal recurrence

    √b_{k+1} p_{k+1}(x) = (x - a_k) p_k(x) - √b_k p_{k-1}(x).

| family              | germ density on support            | Askey partner |
|---------------------|------------------------------------|---------------|
| ``Legendre()``      | 1/2 on [-1, 1]                      | uniform       |
| ``Jacobi(a, b)``    | ∝ (1-x)^a (1+x)^b on [-1, 1]        | beta          |
| ``Hermite()``       | standard normal on R                | normal        |
| ``Laguerre(a)``     | x^a e^{-x} / Γ(a+1) on [0, ∞)       | gamma         |

Gauss rules of Legendre and Hermite up to :data:`NUMPY_RULE_POINTS` points come from
:mod:`numpy.polynomial` (``leggauss``, ``hermegauss``: equal to scipy's to ~1e-13, and the
nodes of uniform and normal inputs import no scipy.special); the others from
:mod:`scipy.special` (``roots_*``; Newton-polished, accurate for hundreds of points, where
numpy's eigen-solve costs O(q³) and its Hermite weights overflow past 370 points). The
weights are rescaled to sum to one.

Double-precision limits (checked by the tests): the discrete orthonormality of the
basis under a (d+1)-point rule holds to ~1e-12 up to degree 20 for every family here;
Hermite and Laguerre values grow like (q/e)^{q/2} at the outermost nodes, so beyond
degree ~40 their products lose relative accuracy even though the rule stays exact in
exact arithmetic.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.polynomial import hermite_e, legendre
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import scipy.stats as st

__all__ = [
    "NUMPY_RULE_POINTS",
    "GaussRule",
    "Hermite",
    "Jacobi",
    "Laguerre",
    "Legendre",
    "OrthonormalFamily",
]

#: Most points of a Legendre or Hermite rule taken from numpy (more: scipy's).
NUMPY_RULE_POINTS = 100


def _special():
    """:mod:`scipy.special`, imported on first use: reading a config or starting a worker never
    needs it."""
    import scipy.special

    return scipy.special


@dataclass(frozen=True)
class GaussRule:
    """A Gauss quadrature rule for a germ's probability measure.

    Attributes
    ----------
    nodes:
        (q,) increasing abscissae.
    weights:
        (q,) positive probability weights, summing to one.
    """

    nodes: NDArray[np.float64]
    weights: NDArray[np.float64]

    def integrate(self, values: ArrayLike) -> NDArray[np.float64]:
        """E[f(ξ)] ≈ Σ w_i f(ξ_i) for values f(ξ_i) of shape (q, ...)."""
        return np.tensordot(self.weights, np.asarray(values, dtype=float), axes=(0, 0))


class OrthonormalFamily(ABC):
    """A family of polynomials orthonormal under a germ's probability measure.

    Implementers provide the monic recurrence coefficients, the raw Gauss rule and the
    germ distribution; evaluation and normalisation are shared.
    """

    @abstractmethod
    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Monic recurrence coefficients ``a_k, b_k`` for k = 0..n-1 (``b_0`` = 1, the mass)."""

    @abstractmethod
    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Nodes and unnormalised weights of the q-point rule."""

    @property
    @abstractmethod
    def germ(self) -> st.rv_continuous:
        """The germ's distribution (frozen scipy.stats object): sampling, cdf, ppf."""

    @abstractmethod
    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """(size,) independent germ draws with numpy's generator (the same draws as the
        scipy.stats germ's ``rvs``, without importing scipy.stats)."""

    @abstractmethod
    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        """The germ's inverse CDF at probabilities ``u`` (its ``ppf``, without importing
        scipy.stats)."""

    @property
    def support(self) -> tuple[float, float]:
        """Closed support of the germ."""
        low, high = self.germ.support()
        return float(low), float(high)

    def evaluate(self, x: ArrayLike, degree: int) -> NDArray[np.float64]:
        """Orthonormal polynomials p_0..p_degree at x.

        Parameters
        ----------
        x:
            Points, any shape (...).
        degree:
            Highest degree, >= 0.

        Returns
        -------
        ndarray
            Shape (..., degree + 1); ``[..., k]`` is p_k(x).

        Raises
        ------
        ValueError
            If degree is negative.
        """
        if degree < 0:
            raise ValueError(f"degree must be >= 0, got {degree}")
        x = np.asarray(x, dtype=float)
        a, b = self.recurrence(degree + 1)
        sqrt_b = np.sqrt(b)
        out = np.empty((*x.shape, degree + 1))
        out[..., 0] = 1.0
        if degree >= 1:
            out[..., 1] = (x - a[0]) / sqrt_b[1]
        for k in range(1, degree):
            out[..., k + 1] = ((x - a[k]) * out[..., k] - sqrt_b[k] * out[..., k - 1]) / sqrt_b[
                k + 1
            ]
        return out

    def gauss_rule(self, q: int) -> GaussRule:
        """The q-point Gauss rule, exact for polynomials of degree <= 2q - 1.

        Raises
        ------
        ValueError
            If q < 1.
        """
        if q < 1:
            raise ValueError(f"a Gauss rule needs at least one point, got {q}")
        nodes, weights = self._raw_gauss(q)
        return GaussRule(nodes=np.asarray(nodes, float), weights=weights / weights.sum())


@dataclass(frozen=True)
class Legendre(OrthonormalFamily):
    """Legendre polynomials, orthonormal for the uniform germ on [-1, 1]."""

    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        k = np.arange(n, dtype=float)
        b = k**2 / (4.0 * k**2 - 1.0)
        b[0] = 1.0
        return np.zeros(n), b

    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return legendre.leggauss(q) if q <= NUMPY_RULE_POINTS else _special().roots_legendre(q)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        return -1.0 + 2.0 * rng.uniform(0.0, 1.0, size)

    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        return -1.0 + 2.0 * np.asarray(u, dtype=float)

    @cached_property
    def germ(self) -> st.rv_continuous:
        import scipy.stats as st  # deferred: 1.3 s of import that collocation never needs

        return st.uniform(loc=-1.0, scale=2.0)


@dataclass(frozen=True)
class Jacobi(OrthonormalFamily):
    """Jacobi polynomials for the germ density ∝ (1-x)^alpha (1+x)^beta on [-1, 1].

    The germ is ``2u - 1`` with ``u ~ Beta(beta + 1, alpha + 1)`` in scipy's convention.
    """

    alpha: float
    beta: float

    def __post_init__(self) -> None:
        if not (self.alpha > -1.0 and self.beta > -1.0):
            raise ValueError(f"Jacobi exponents must be > -1, got ({self.alpha}, {self.beta})")

    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        al, be = float(self.alpha), float(self.beta)
        k = np.arange(n, dtype=float)
        s = 2.0 * k + al + be
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (be**2 - al**2) / (s * (s + 2.0))
            b = 4.0 * k * (k + al) * (k + be) * (k + al + be) / (s**2 * (s + 1.0) * (s - 1.0))
        # k = 0 and k = 1 hit 0/0 for some (alpha, beta); use their closed forms.
        a[0] = (be - al) / (al + be + 2.0)
        b[0] = 1.0
        if n > 1:
            b[1] = 4.0 * (1.0 + al) * (1.0 + be) / ((2.0 + al + be) ** 2 * (3.0 + al + be))
        return a, b

    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _special().roots_jacobi(q, self.alpha, self.beta)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        return -1.0 + 2.0 * rng.beta(self.beta + 1.0, self.alpha + 1.0, size)

    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        return -1.0 + 2.0 * _special().betaincinv(self.beta + 1.0, self.alpha + 1.0, u)

    @cached_property
    def germ(self) -> st.rv_continuous:
        import scipy.stats as st

        return st.beta(self.beta + 1.0, self.alpha + 1.0, loc=-1.0, scale=2.0)


@dataclass(frozen=True)
class Hermite(OrthonormalFamily):
    """Probabilists' Hermite polynomials, orthonormal for the standard normal germ."""

    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        b = np.arange(n, dtype=float)
        b[0] = 1.0
        return np.zeros(n), b

    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if q <= NUMPY_RULE_POINTS:
            return hermite_e.hermegauss(q)
        return _special().roots_hermitenorm(q)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        return rng.standard_normal(size)

    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        return _special().ndtri(u)

    @cached_property
    def germ(self) -> st.rv_continuous:
        import scipy.stats as st

        return st.norm()


@dataclass(frozen=True)
class Laguerre(OrthonormalFamily):
    """Generalised Laguerre polynomials, germ density x^alpha e^{-x} / Γ(alpha+1) on [0, ∞)."""

    alpha: float = 0.0

    def __post_init__(self) -> None:
        if not self.alpha > -1.0:
            raise ValueError(f"Laguerre exponent must be > -1, got {self.alpha}")

    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        k = np.arange(n, dtype=float)
        b = k * (k + self.alpha)
        b[0] = 1.0
        return 2.0 * k + self.alpha + 1.0, b

    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _special().roots_genlaguerre(q, self.alpha)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        return rng.standard_gamma(self.alpha + 1.0, size)

    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        return _special().gammaincinv(self.alpha + 1.0, u)

    @cached_property
    def germ(self) -> st.rv_continuous:
        import scipy.stats as st

        return st.gamma(self.alpha + 1.0)
