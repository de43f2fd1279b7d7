"""Uncertain inputs: distributions and their maps between germ ξ and physical value θ.

Every input θ_k is a map θ_k = T_k(ξ_k) of a standard germ ξ_k whose measure has an
orthonormal polynomial family (:mod:`pcmb.chaos.polynomials`):

=========================================  =============  ==========================
distribution                               germ           map θ = T(ξ)
=========================================  =============  ==========================
``Uniform(low, high)``                     U[-1, 1]       affine
``Beta(alpha, beta, low, high)``           Jacobi         affine
``Normal(mean, std)``                      N(0, 1)        affine
``Gamma(shape, scale, loc)``               Gamma(shape)   affine
``LogUniform(low, high)``                  U[-1, 1]       θ = exp(affine): uniform in ln θ
``Transformed(target, germ)``              U[-1,1]/N(0,1) θ = F⁻¹(G(ξ))  (isoprobabilistic)
=========================================  =============  ==========================

The affine maps are exact, so a chaos expansion in ξ of a polynomial response in θ is
exact at finite order. ``Transformed`` reaches any continuous scipy.stats distribution
(lognormal, truncated normal, triangular, ...) but the nonlinear map F⁻¹∘G makes even a
linear response non-polynomial in ξ: expect slower convergence in the order.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.polynomials import Hermite, Jacobi, Laguerre, Legendre, OrthonormalFamily

__all__ = [
    "Beta",
    "Distribution",
    "Gamma",
    "LogUniform",
    "Normal",
    "Transformed",
    "Uniform",
    "from_description",
]

# Parameter-free families are shared so their cached germ distributions are built once.
_LEGENDRE = Legendre()
_HERMITE = Hermite()


def _stats() -> Any:
    """scipy.stats, imported on first use: 1.3 s that a collocation run never needs."""
    import scipy.stats

    return scipy.stats


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _finite(**values: float) -> None:
    for name, value in values.items():
        _require(bool(np.isfinite(value)), f"{name} must be a finite number, got {value!r}")


def _interval(low: float, high: float) -> None:
    """``low < high``, and ``high - low`` a float: the germ's map needs the width."""
    _require(low < high, f"low must be < high, got low={low}, high={high}")
    _require(
        bool(np.isfinite(high - low)),
        f"the range from low={low!r} to high={high!r} is wider than the largest float "
        f"({np.finfo(float).max:.3g}); give this parameter in other units",
    )


class Distribution(ABC):
    """An uncertain input: a probability law and its map from the standard germ."""

    @property
    @abstractmethod
    def family(self) -> OrthonormalFamily:
        """The orthonormal polynomial family of the germ."""

    @property
    @abstractmethod
    def physical(self) -> Any:
        """The law of θ as a frozen scipy.stats distribution."""

    @abstractmethod
    def to_physical(self, xi: ArrayLike) -> NDArray[np.float64]:
        """θ = T(ξ), elementwise."""

    @abstractmethod
    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        """ξ = T⁻¹(θ), elementwise."""

    @abstractmethod
    def describe(self) -> dict[str, Any]:
        """A JSON-able description, e.g. ``{"dist": "uniform", "low": 0.0, "high": 1.0}``."""

    @property
    def law(self) -> str:
        """The law as text, e.g. ``uniform(low=0.025, high=0.075)``."""
        settings = self.describe()
        name = settings.pop("dist")
        shown = (
            f"{key}={value:.4g}" if isinstance(value, float) else f"{key}={value}"
            for key, value in settings.items()
        )
        return f"{name}({', '.join(shown)})"

    @property
    def finite_at_nodes(self) -> bool:
        """Whether θ = T(ξ) is a finite number at every node of any rule, known without the
        nodes; False when that is not known (then only the nodes tell)."""
        return False

    def expectation(self) -> float:
        """E[θ]."""
        return float(self.physical.mean())

    def pdf(self, theta: ArrayLike) -> NDArray[np.float64]:
        """Density of θ."""
        return self.physical.pdf(np.asarray(theta, dtype=float))

    def sample_germ(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """(size,) independent germ samples."""
        return self.family.sample(size, rng)

    def sample(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """(size,) independent samples of θ (drawn through the germ, as Monte Carlo does)."""
        return self.to_physical(self.sample_germ(size, rng))


class _Affine(Distribution):
    """θ = shift + scale · ξ."""

    #: The largest |ξ| of the germ's support, when it is bounded.
    _germ_reach: ClassVar[float | None] = None

    @property
    @abstractmethod
    def _shift_scale(self) -> tuple[float, float]: ...

    @property
    def finite_at_nodes(self) -> bool:
        """On a bounded germ, every node lies within twice its reach (within it, but for
        rounding): twice that again keeps |shift| + |scale ξ| and its rounding clear of
        overflow."""
        if self._germ_reach is None:
            return False
        shift, scale = self._shift_scale
        return bool(np.isfinite(abs(shift) + 4.0 * self._germ_reach * abs(scale)))

    def to_physical(self, xi: ArrayLike) -> NDArray[np.float64]:
        shift, scale = self._shift_scale
        return shift + scale * np.asarray(xi, dtype=float)

    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        shift, scale = self._shift_scale
        return (np.asarray(theta, dtype=float) - shift) / scale

    def expectation(self) -> float:
        # E[ξ] is the recurrence coefficient a_0 (p_1 ∝ ξ - a_0 is orthogonal to 1): no scipy.
        shift, scale = self._shift_scale
        return float(shift + scale * self.family.recurrence(1)[0][0])


@dataclass(frozen=True)
class Uniform(_Affine):
    """θ ~ U[low, high]; germ U[-1, 1], Legendre chaos."""

    _germ_reach: ClassVar[float | None] = 1.0
    low: float
    high: float

    def __post_init__(self) -> None:
        _finite(low=self.low, high=self.high)
        _interval(self.low, self.high)

    @property
    def family(self) -> OrthonormalFamily:
        return _LEGENDRE

    @cached_property
    def physical(self) -> Any:
        return _stats().uniform(loc=self.low, scale=self.high - self.low)

    @property
    def _shift_scale(self) -> tuple[float, float]:
        return 0.5 * (self.low + self.high), 0.5 * (self.high - self.low)

    def describe(self) -> dict[str, Any]:
        return {"dist": "uniform", "low": self.low, "high": self.high}


@dataclass(frozen=True)
class Beta(_Affine):
    """θ = low + (high - low) u with u ~ Beta(alpha, beta) in scipy's shape convention.

    The germ ξ = 2u - 1 on [-1, 1] has density ∝ (1-ξ)^(beta-1) (1+ξ)^(alpha-1): Jacobi
    chaos P^(beta-1, alpha-1). The papers' Beta(a, b), density ∝ (1-ξ)^a (1+ξ)^b, is
    ``Beta(alpha=b + 1, beta=a + 1)``; a = b = 0 is the uniform case.
    """

    _germ_reach: ClassVar[float | None] = 1.0
    alpha: float
    beta: float
    low: float
    high: float

    def __post_init__(self) -> None:
        _finite(alpha=self.alpha, beta=self.beta, low=self.low, high=self.high)
        _require(self.alpha > 0, f"alpha must be > 0, got {self.alpha}")
        _require(self.beta > 0, f"beta must be > 0, got {self.beta}")
        _interval(self.low, self.high)

    @cached_property
    def family(self) -> OrthonormalFamily:
        return Jacobi(alpha=self.beta - 1.0, beta=self.alpha - 1.0)

    @cached_property
    def physical(self) -> Any:
        return _stats().beta(self.alpha, self.beta, loc=self.low, scale=self.high - self.low)

    @property
    def _shift_scale(self) -> tuple[float, float]:
        return 0.5 * (self.low + self.high), 0.5 * (self.high - self.low)

    def describe(self) -> dict[str, Any]:
        return {
            "dist": "beta",
            "alpha": self.alpha,
            "beta": self.beta,
            "low": self.low,
            "high": self.high,
        }


@dataclass(frozen=True)
class Normal(_Affine):
    """θ ~ N(mean, std²); germ N(0, 1), probabilists' Hermite chaos."""

    mean: float
    std: float

    def __post_init__(self) -> None:
        _finite(mean=self.mean, std=self.std)
        _require(self.std > 0, f"std must be > 0, got {self.std}")

    @property
    def family(self) -> OrthonormalFamily:
        return _HERMITE

    @cached_property
    def physical(self) -> Any:
        return _stats().norm(loc=self.mean, scale=self.std)

    @property
    def _shift_scale(self) -> tuple[float, float]:
        return self.mean, self.std

    def describe(self) -> dict[str, Any]:
        return {"dist": "normal", "mean": self.mean, "std": self.std}


@dataclass(frozen=True)
class Gamma(_Affine):
    """θ = loc + scale · ξ with ξ ~ Gamma(shape); generalised Laguerre chaos L^(shape-1)."""

    shape: float
    scale: float
    loc: float = 0.0

    def __post_init__(self) -> None:
        _finite(shape=self.shape, scale=self.scale, loc=self.loc)
        _require(self.shape > 0, f"shape must be > 0, got {self.shape}")
        _require(self.scale > 0, f"scale must be > 0, got {self.scale}")

    @cached_property
    def family(self) -> OrthonormalFamily:
        return Laguerre(alpha=self.shape - 1.0)

    @cached_property
    def physical(self) -> Any:
        return _stats().gamma(self.shape, loc=self.loc, scale=self.scale)

    @property
    def _shift_scale(self) -> tuple[float, float]:
        return self.loc, self.scale

    def describe(self) -> dict[str, Any]:
        return {"dist": "gamma", "shape": self.shape, "scale": self.scale, "loc": self.loc}


@dataclass(frozen=True)
class LogUniform(Distribution):
    """θ with ln θ ~ U[ln low, ln high] (rates and material constants spanning decades).

    Germ U[-1, 1], Legendre chaos, θ = exp(m + h ξ): smooth in ξ but not polynomial, so even a
    linear response converges geometrically in the order rather than exactly.
    """

    low: float
    high: float

    def __post_init__(self) -> None:
        _finite(low=self.low, high=self.high)
        _require(self.low > 0, f"low must be > 0, got {self.low}")
        _require(self.low < self.high, f"low must be < high, got low={self.low}, high={self.high}")

    @property
    def family(self) -> OrthonormalFamily:
        return _LEGENDRE

    @cached_property
    def physical(self) -> Any:
        return _stats().loguniform(self.low, self.high)

    @property
    def _centre_half_width(self) -> tuple[float, float]:
        logs = np.log([self.low, self.high])
        return 0.5 * float(logs.sum()), 0.5 * float(logs[1] - logs[0])

    def to_physical(self, xi: ArrayLike) -> NDArray[np.float64]:
        centre, half = self._centre_half_width
        return np.exp(centre + half * np.asarray(xi, dtype=float))

    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        centre, half = self._centre_half_width
        return (np.log(np.asarray(theta, dtype=float)) - centre) / half

    def expectation(self) -> float:
        return (self.high - self.low) / float(np.log(self.high / self.low))

    def describe(self) -> dict[str, Any]:
        return {"dist": "loguniform", "low": self.low, "high": self.high}


_GERMS: dict[str, OrthonormalFamily] = {"uniform": _LEGENDRE, "normal": _HERMITE}


@dataclass(frozen=True)
class Transformed(Distribution):
    """Any continuous scipy.stats law reached through the isoprobabilistic map θ = F⁻¹(G(ξ)).

    Parameters
    ----------
    target:
        A frozen continuous scipy.stats distribution, e.g. ``scipy.stats.lognorm(0.25)``.
    germ:
        ``"normal"`` (Hermite; natural for laws with unbounded tails) or ``"uniform"``
        (Legendre; natural for bounded laws).

    Notes
    -----
    The map is nonlinear, so the chaos of even a linear response converges only
    as fast as F⁻¹∘G is approximated by polynomials — prefer an Askey-scheme input
    when the physics allows it. Tails are mapped through survival functions so that
    large |ξ| does not round to probability one.
    """

    target: Any
    germ: Literal["uniform", "normal"] = "normal"

    def __post_init__(self) -> None:
        _require(
            isinstance(getattr(self.target, "dist", None), _stats().rv_continuous),
            f"target must be a frozen continuous scipy.stats distribution, got {self.target!r}",
        )
        _require(self.germ in _GERMS, f"germ must be 'uniform' or 'normal', got {self.germ!r}")

    @property
    def family(self) -> OrthonormalFamily:
        return _GERMS[self.germ]

    @property
    def physical(self) -> Any:
        return self.target

    def to_physical(self, xi: ArrayLike) -> NDArray[np.float64]:
        xi = np.asarray(xi, dtype=float)
        germ = self.family.germ
        lower = xi <= germ.median()
        return np.where(lower, self.target.ppf(germ.cdf(xi)), self.target.isf(germ.sf(xi)))

    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        theta = np.asarray(theta, dtype=float)
        germ = self.family.germ
        lower = theta <= self.target.median()
        return np.where(lower, germ.ppf(self.target.cdf(theta)), germ.isf(self.target.sf(theta)))

    @property
    def law(self) -> str:
        shown = [f"{a:.4g}" for a in self.target.args]
        shown += [f"{k}={v:.4g}" for k, v in self.target.kwds.items()]
        return f"{self.target.dist.name}({', '.join(shown)}), germ {self.germ}"

    def describe(self) -> dict[str, Any]:
        return {
            "dist": "scipy",
            "name": self.target.dist.name,
            "args": [float(a) for a in self.target.args],
            "params": {k: float(v) for k, v in self.target.kwds.items()},
            "germ": self.germ,
        }


def from_description(description: dict[str, Any]) -> Distribution:
    """Rebuild a distribution from :meth:`Distribution.describe` output (e.g. read from a file).

    Raises
    ------
    ValueError
        If the description names an unknown distribution or has invalid parameters.
    """
    fields = dict(description)
    kind = fields.pop("dist", None)
    if kind == "scipy":
        target = getattr(_stats(), fields["name"])(
            *fields.get("args", []), **fields.get("params", {})
        )
        return Transformed(target, germ=fields.get("germ", "normal"))
    classes: dict[str, type[Distribution]] = {
        "uniform": Uniform,
        "beta": Beta,
        "normal": Normal,
        "gamma": Gamma,
        "loguniform": LogUniform,
    }
    if kind not in classes:
        raise ValueError(f"unknown distribution {kind!r}")
    return classes[kind](**fields)
