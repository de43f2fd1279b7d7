"""Orthonormal polynomials and Gauss rules of an input conditioned on an interval.

Multi-element chaos (Wan & Karniadakis, J. Comput. Phys. 209 (2005)) gives every element its
own basis, orthonormal under the *conditional* law of each input on the element's interval
[a, b] of physical values (a, b may be infinite). Inputs are monotone increasing maps
θ = T(ξ) of a standard germ, so the condition θ ∈ [a, b] is ξ ∈ [T⁻¹(a), T⁻¹(b)]: the
element measure is the germ measure truncated to that interval, in a local coordinate

    ζ = (ξ - shift) / scale,

shift and scale the midpoint and half-width of a bounded interval (ζ in [-1, 1], where a
uniform germ gives Legendre again) or the conditional mean and standard deviation of a
half-line.

Construction: the discretised Stieltjes procedure (Gautschi, *Orthogonal Polynomials:
Computation and Approximation*, 2004, §2.2.3): the truncated measure is replaced by an M-point
quadrature that integrates polynomials times its density to round-off, and the monic
recurrence coefficients are the inner products of that discrete measure. The discretisation
is Gauss–Jacobi on a bounded interval, whose endpoint exponents absorb the germ density's
singular factors (1 ∓ ξ)^e where the interval reaches a finite end of the germ's support
(beta with shape < 1), leaving an analytic factor; a half-line is mapped to (-1, 1) by
ξ = end ± c (1 + t) / (1 - t), where the normal and gamma tails make the integrand flat at
t = 1. The CDF variable u = F(ξ) would be simpler but the quantile function is singular at
the ends of a normal or beta interval (e.g. √(-2 log u)), which costs algebraic instead of
exponential convergence. Gauss rules of the element measure come from the recurrence by
Golub–Welsch. The tests check: Legendre and Jacobi recovered to round-off, truncated-normal
moments against scipy.stats.truncnorm, and q-point rules exact to degree 2q - 1.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.polynomials import Hermite, Jacobi, Laguerre, Legendre, OrthonormalFamily

__all__ = ["Conditional", "TruncatedFamily", "interval_probability"]

#: Points of the discretised measure; ample for the recurrence up to :data:`MAX_TERMS`.
POINTS = 400
#: Recurrence terms available (polynomial degree + 1, Gauss points).
MAX_TERMS = 64


@dataclass(frozen=True)
class _Density:
    """A germ density (x - L)^lower (R - x)^upper exp(log_smooth(x)), unnormalised, with L, R
    the ends of the germ's support (the exponent of an infinite end is 0)."""

    lower: float
    upper: float
    log_smooth: Callable[[NDArray[np.float64]], NDArray[np.float64]]


def _density(family: OrthonormalFamily) -> _Density:
    if isinstance(family, Legendre):
        return _Density(0.0, 0.0, np.zeros_like)
    if isinstance(family, Jacobi):
        return _Density(family.beta, family.alpha, np.zeros_like)
    if isinstance(family, Hermite):
        return _Density(0.0, 0.0, lambda x: -0.5 * x**2)
    if isinstance(family, Laguerre):
        return _Density(family.alpha, 0.0, np.negative)
    raise TypeError(f"no truncated family for {type(family).__name__}")


def _gauss(family: OrthonormalFamily, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nodes and probability weights of a family's q-point Gauss rule: Golub–Welsch nodes and
    Christoffel weights 1 / Σ_k p_k(x)², which keep their relative accuracy where they are tiny
    (eigenvector weights only have absolute accuracy; scipy's roots_jacobi loses digits for
    hundreds of points). Weights that underflow are 0."""
    from scipy.linalg import eigvalsh_tridiagonal  # here: reading a config never needs it

    a, b = family.recurrence(q)
    nodes = eigvalsh_tridiagonal(a, np.sqrt(b[1:]))
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.sum(family.evaluate(nodes, q - 1) ** 2, axis=1)
    weights = np.where(np.isfinite(norm), 1.0 / norm, 0.0)
    return nodes, weights


@functools.cache
def _gauss_jacobi(upper: float, lower: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The POINTS-point Gauss rule of (1 - t)^upper (1 + t)^lower on [-1, 1]."""
    return _gauss(Jacobi(upper, lower), POINTS)


def _discretise(
    family: OrthonormalFamily, lower: float, upper: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
    """Nodes ζ and probability weights of the truncated measure, and (shift, scale)."""
    density = _density(family)
    low_end, high_end = family.support
    if np.isfinite(lower) and np.isfinite(upper):
        # Exponents of the ends the interval shares with the support go into the rule.
        at_low = density.lower if lower == low_end else 0.0
        at_high = density.upper if upper == high_end else 0.0
        t, w = _gauss_jacobi(at_high, at_low)
        shift, scale = 0.5 * (lower + upper), 0.5 * (upper - lower)
        x = shift + scale * t
        log_w = np.log(w) + density.log_smooth(x)
        if at_low == 0.0 and density.lower:
            log_w += density.lower * np.log(x - low_end)
        if at_high == 0.0 and density.upper:
            log_w += density.upper * np.log(high_end - x)
    elif (lower, upper) == (low_end, high_end):
        x, w = _gauss(family, POINTS)  # the measure itself: exact to degree 2 POINTS - 1
        with np.errstate(divide="ignore"):
            log_w = np.log(w)
    else:
        end, sign = (lower, 1.0) if np.isfinite(lower) else (upper, -1.0)
        mean = family.recurrence(1)[0][0]
        c = 1.0 + max(0.0, sign * (mean - end))  # 1 + how far the germ's mean lies inside
        t, w = _gauss_jacobi(0.0, 0.0)
        x = end + sign * c * (1.0 + t) / (1.0 - t)
        log_w = np.log(w * 2.0 * c / (1.0 - t) ** 2) + density.log_smooth(x)
        if density.lower:
            log_w += density.lower * np.log(x - low_end)
    weights = np.exp(log_w - log_w.max())
    kept = weights > 0  # nodes whose weight underflows carry nothing but overflow risk
    x, weights = x[kept], weights[kept] / weights[kept].sum()
    if not (np.isfinite(lower) and np.isfinite(upper)):
        shift = float(weights @ x)
        scale = float(np.sqrt(weights @ (x - shift) ** 2))
    return (x - shift) / scale, weights, shift, scale


def _stieltjes(
    nodes: NDArray[np.float64], weights: NDArray[np.float64], n: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Monic recurrence coefficients a_k, b_k (k < n, b_0 = 1) of a discrete probability
    measure, by the Stieltjes procedure on orthonormal vectors."""
    a, b = np.empty(n), np.ones(n)
    previous, current = np.zeros_like(nodes), np.ones_like(nodes)
    for k in range(n):
        a[k] = weights @ (nodes * current**2)
        if k + 1 == n:
            break
        following = (nodes - a[k]) * current - np.sqrt(b[k]) * previous
        b[k + 1] = weights @ following**2
        previous, current = current, following / np.sqrt(b[k + 1])
    return a, b


@functools.cache
def _truncated(
    family: OrthonormalFamily, lower: float, upper: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
    """Recurrence (MAX_TERMS terms) and (shift, scale) of a truncated germ measure."""
    nodes, weights, shift, scale = _discretise(family, lower, upper)
    return (*_stieltjes(nodes, weights, MAX_TERMS), shift, scale)


def interval_probability(germ: Any, lower: ArrayLike, upper: ArrayLike) -> NDArray[np.float64]:
    """P(lower <= X <= upper) under a frozen scipy distribution, through survival functions
    above the median so that far-tail intervals keep their digits."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    tail = lower >= germ.median()
    return np.where(tail, germ.sf(lower) - germ.sf(upper), germ.cdf(upper) - germ.cdf(lower))


def _conditional_law(parent: Any, lower: float, upper: float, shift: float, scale: float) -> Any:
    """The law of (X - shift) / scale given X in [lower, upper], X ~ parent (frozen scipy)."""
    import scipy.stats as st  # deferred, as everywhere in the core

    mass = float(interval_probability(parent, lower, upper))
    tail = lower >= parent.median()

    class _Law(st.rv_continuous):
        def _pdf(self, x: NDArray) -> NDArray:
            return parent.pdf(x) / mass

        def _cdf(self, x: NDArray) -> NDArray:
            return interval_probability(parent, lower, x) / mass

        def _sf(self, x: NDArray) -> NDArray:
            return interval_probability(parent, x, upper) / mass

        def _ppf(self, q: NDArray) -> NDArray:
            if tail:
                return parent.isf(parent.sf(lower) - q * mass)
            return parent.ppf(parent.cdf(lower) + q * mass)

    return _Law(a=lower, b=upper, name="conditional")(loc=-shift / scale, scale=1.0 / scale)


@dataclass(frozen=True)
class TruncatedFamily(OrthonormalFamily):
    """Polynomials orthonormal under a germ measure truncated to [lower, upper], in ζ.

    Parameters
    ----------
    parent:
        The germ's family (Legendre, Jacobi, Hermite or Laguerre).
    lower, upper:
        The interval in the parent's germ coordinate ξ, inside its support, lower < upper;
        either may be infinite where the support is.

    Attributes
    ----------
    shift, scale:
        ξ = shift + scale · ζ.

    Raises
    ------
    ValueError
        If the interval is empty or leaves the support.
    """

    parent: OrthonormalFamily
    lower: float
    upper: float

    def __post_init__(self) -> None:
        low, high = self.parent.support
        if not (low <= self.lower < self.upper <= high):
            raise ValueError(
                f"need {low} <= lower < upper <= {high}, got [{self.lower}, {self.upper}]"
            )

    @property
    def _table(self) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
        return _truncated(self.parent, float(self.lower), float(self.upper))

    @property
    def shift(self) -> float:
        return self._table[2]

    @property
    def scale(self) -> float:
        return self._table[3]

    def recurrence(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if n > MAX_TERMS:
            raise ValueError(f"a truncated family has {MAX_TERMS} recurrence terms, asked {n}")
        a, b, _, _ = self._table
        return a[:n].copy(), b[:n].copy()

    def _raw_gauss(self, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _gauss(self, q)

    @cached_property
    def germ(self) -> Any:
        return _conditional_law(self.parent.germ, self.lower, self.upper, self.shift, self.scale)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        return self.quantile(rng.uniform(0.0, 1.0, size))

    def quantile(self, u: ArrayLike) -> NDArray[np.float64]:
        return self.germ.ppf(u)


@dataclass(frozen=True)
class Conditional(Distribution):
    """An input conditioned on physical values in [low, high]: an element's input.

    Its germ is the element coordinate ζ of :class:`TruncatedFamily`; over the input's whole
    support it is the input itself (same family, same germ).

    Parameters
    ----------
    parent:
        The input.
    low, high:
        The interval, low < high, either possibly infinite; clipped to the support.
    """

    parent: Distribution
    low: float
    high: float

    @cached_property
    def _germ_interval(self) -> tuple[float, float]:
        """The interval in the parent's germ coordinate, the support's own ends kept exact."""
        low, high = self.parent.family.support
        physical_low, physical_high = self.parent.physical.support()
        lower = low if self.low <= physical_low else float(self.parent.to_germ(self.low))
        upper = high if self.high >= physical_high else float(self.parent.to_germ(self.high))
        if not lower < upper:
            raise ValueError(f"the interval [{self.low}, {self.high}] holds no probability")
        return lower, upper

    @property
    def whole(self) -> bool:
        """Whether the interval is the input's whole support."""
        return self._germ_interval == self.parent.family.support

    @cached_property
    def family(self) -> OrthonormalFamily:
        if self.whole:
            return self.parent.family
        return TruncatedFamily(self.parent.family, *self._germ_interval)

    @property
    def _shift_scale(self) -> tuple[float, float]:
        family = self.family
        if isinstance(family, TruncatedFamily):
            return family.shift, family.scale
        return 0.0, 1.0

    @cached_property
    def probability(self) -> float:
        """P(low <= θ <= high) under the parent."""
        return float(interval_probability(self.parent.family.germ, *self._germ_interval))

    @cached_property
    def physical(self) -> Any:
        low, high = self.parent.physical.support()
        law = self.parent.physical
        return _conditional_law(law, max(self.low, low), min(self.high, high), 0.0, 1.0)

    def to_physical(self, xi: ArrayLike) -> NDArray[np.float64]:
        shift, scale = self._shift_scale
        return self.parent.to_physical(shift + scale * np.asarray(xi, dtype=float))

    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        shift, scale = self._shift_scale
        return (self.parent.to_germ(theta) - shift) / scale

    def describe(self) -> dict[str, Any]:
        return {
            "dist": "conditional",
            "of": self.parent.describe(),
            "low": self.low,
            "high": self.high,
        }
