"""The chaos expansion y(ξ) = Σ_α c_α φ_α(ξ) and its statistics.

Coefficients have shape (S, ...): one row per basis term, any trailing shape (an output
over time is (S, T)). Every statistic is vectorised over the trailing axes and computed
from the coefficients alone, because the basis is orthonormal:

- mean = c_0, variance = Σ_{α≠0} c_α² (never E[y²] - E[y]², which cancels catastrophically),
- covariance of two outputs on the same basis = Σ_{α≠0} c_α d_α,
- Sobol' first index of input k = Σ c_α² over α involving only input k, divided by the variance;
  total index = Σ c_α² over α involving input k (at all), divided by the variance.

Where the output does not vary (e.g. at t = 0 with a deterministic initial state), the
Sobol' indices are undefined and returned as NaN rather than as round-off noise.

Quantiles and densities come from sampling the surrogate, which is cheap.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.basis import PolynomialBasis
from pcmb.chaos.density import kernel_density
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import draw_germs

__all__ = ["ChaosExpansion"]

#: A standard deviation below this fraction of the output's RMS is round-off: Sobol' -> NaN.
_RELATIVE_NOISE = 1e-12
#: Surrogate evaluations per block when sampling (bounds memory at ~block × S doubles).
_BLOCK = 16_384


class ChaosExpansion:
    """A fitted polynomial chaos expansion of one output (any trailing shape).

    Parameters
    ----------
    coefficients:
        (S, ...) coefficients c_α.
    multi_index:
        (S, n) multi-indices; must contain the zero index (the mean term).
    distributions:
        The n inputs, germ order.
    names:
        Optional input names (for ``describe`` and reports).

    Raises
    ------
    ValueError
        If shapes disagree, an index repeats or the zero index is missing.
    """

    def __init__(
        self,
        coefficients: ArrayLike,
        multi_index: ArrayLike,
        distributions: Sequence[Distribution],
        names: Sequence[str] | None = None,
    ):
        self.coefficients = np.asarray(coefficients, dtype=float)
        self.distributions = tuple(distributions)
        self.basis = PolynomialBasis(tuple(d.family for d in self.distributions), multi_index)
        self.names = tuple(names) if names is not None else tuple(f"x{k}" for k in range(self.n))
        index = self.basis.multi_index
        if self.coefficients.ndim == 0 or self.coefficients.shape[0] != index.shape[0]:
            raise ValueError(
                f"coefficients must have one row per term ({index.shape[0]}),"
                f" got shape {self.coefficients.shape}"
            )
        if len(self.names) != self.n:
            raise ValueError(f"need {self.n} input names, got {len(self.names)}")
        if np.unique(index, axis=0).shape[0] != index.shape[0]:
            raise ValueError("multi-indices must be distinct")
        zero = np.flatnonzero(~index.any(axis=1))
        if zero.size != 1:
            raise ValueError("the multi-index set must contain the zero index (the mean term)")
        self._zero = int(zero[0])

    # -- structure --------------------------------------------------------------------------

    @property
    def n(self) -> int:
        """Number of inputs."""
        return len(self.distributions)

    @property
    def multi_index(self) -> NDArray[np.int64]:
        """(S, n) multi-indices."""
        return self.basis.multi_index

    @property
    def shape(self) -> tuple[int, ...]:
        """Trailing shape of the output (e.g. (T,))."""
        return self.coefficients.shape[1:]

    def __getitem__(self, key: Any) -> ChaosExpansion:
        """Expansion of a part of the output: ``expansion[k]`` is time k of an (S, T) output."""
        key = key if isinstance(key, tuple) else (key,)
        return ChaosExpansion(
            self.coefficients[(slice(None), *key)], self.multi_index, self.distributions, self.names
        )

    @cached_property
    def _fluctuations(self) -> NDArray[np.float64]:
        """(S, ...) coefficients with the mean term zeroed."""
        fluct = self.coefficients.copy()
        fluct[self._zero] = 0.0
        return fluct

    # -- moments ----------------------------------------------------------------------------

    def mean(self) -> NDArray[np.float64]:
        """E[y], shape (...)."""
        return self.coefficients[self._zero].copy()

    @cached_property
    def _squares(self) -> NDArray[np.float64]:
        """(S, P) squared fluctuation coefficients, trailing axes flattened (shared by Sobol')."""
        return (self._fluctuations**2).reshape(self.multi_index.shape[0], -1)

    def variance(self) -> NDArray[np.float64]:
        """Var[y] = Σ_{α≠0} c_α², shape (...)."""
        return self._squares.sum(axis=0).reshape(self.shape)

    def std(self) -> NDArray[np.float64]:
        """Standard deviation, shape (...)."""
        return np.sqrt(self.variance())

    def covariance(self, other: ChaosExpansion) -> NDArray[np.float64]:
        """Cov[y, z] = Σ_{α≠0} c_α d_α for another output z on the same basis, shape (...).

        Raises
        ------
        ValueError
            If the two expansions do not share the same multi-index set.
        """
        if not np.array_equal(self.multi_index, other.multi_index):
            raise ValueError("covariance needs two expansions on the same multi-index set")
        return np.einsum("s...,s...->...", self._fluctuations, other._fluctuations)

    # -- sensitivity ------------------------------------------------------------------------

    def _sobol(self, masks: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Σ c_α² over each row's mask, divided by the variance: (n, ...)."""
        partial = masks.astype(float) @ self._squares
        variance = self._squares.sum(axis=0)
        mean_square = self.coefficients[self._zero].reshape(-1) ** 2
        defined = variance > _RELATIVE_NOISE**2 * (variance + mean_square)
        with np.errstate(divide="ignore", invalid="ignore"):
            indices = np.where(defined, partial / variance, np.nan)
        return indices.reshape(self.n, *self.shape)

    def sobol_first(self) -> NDArray[np.float64]:
        """First-order Sobol' indices S_k, shape (n, ...); NaN where the output does not vary."""
        active = self.multi_index > 0
        only = active & (active.sum(axis=1) == 1)[:, None]
        return self._sobol(only.T)

    def sobol_total(self) -> NDArray[np.float64]:
        """Total Sobol' indices S_Tk, shape (n, ...); NaN where the output does not vary."""
        return self._sobol((self.multi_index > 0).T)

    # -- the surrogate ----------------------------------------------------------------------

    def evaluate_germ(self, xi: ArrayLike) -> NDArray[np.float64]:
        """The surrogate at germ points ξ.

        Parameters
        ----------
        xi:
            (M, n) germ coordinates.

        Returns
        -------
        ndarray
            (M, ...) surrogate values.
        """
        xi = np.asarray(xi, dtype=float)
        flat = self.coefficients.reshape(self.coefficients.shape[0], -1)
        out = np.empty((xi.shape[0], flat.shape[1]))
        for start in range(0, xi.shape[0], _BLOCK):
            block = slice(start, start + _BLOCK)
            out[block] = self.basis.evaluate(xi[block]) @ flat
        return out.reshape(xi.shape[0], *self.shape)

    def to_germ(self, theta: ArrayLike) -> NDArray[np.float64]:
        """Germ coordinates of physical points θ, (M, n) -> (M, n)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if theta.shape[1] != self.n:
            raise ValueError(f"physical points must be (M, {self.n}), got shape {theta.shape}")
        return np.column_stack([d.to_germ(theta[:, k]) for k, d in enumerate(self.distributions)])

    def __call__(self, theta: ArrayLike) -> NDArray[np.float64]:
        """The surrogate at physical points θ, (M, n) -> (M, ...)."""
        return self.evaluate_germ(self.to_germ(theta))

    def sample(self, size: int, seed: int | None = 0) -> NDArray[np.float64]:
        """Values of the surrogate at ``size`` random inputs, (size, ...).

        The inputs are drawn from their distributions; the same seed gives the same draw.
        """
        rng = np.random.default_rng(seed)
        xi = draw_germs(self.distributions, size, rng)
        return self.evaluate_germ(xi)

    def quantile(
        self, q: ArrayLike, size: int = 100_000, seed: int | None = 0
    ) -> NDArray[np.float64]:
        """Quantiles of y estimated from ``size`` surrogate samples, shape (len(q), ...)."""
        return np.quantile(self.sample(size, seed), np.asarray(q, dtype=float), axis=0)

    def pdf(self, points: ArrayLike, size: int = 100_000, seed: int | None = 0) -> NDArray:
        """Density of a scalar output at ``points``: a Gaussian KDE of surrogate samples.

        Select a scalar first, e.g. ``expansion[time_index].pdf(x)``. The estimate is
        :func:`pcmb.chaos.density.kernel_density` (Scott's bandwidth), the one stored in result
        files; it is zero beyond three bandwidths from the samples.

        Raises
        ------
        ValueError
            If the expansion is not scalar, or the output does not vary (its density is a
            Dirac mass and has no KDE).
        """
        if self.shape != ():
            raise ValueError(
                f"pdf needs a scalar output, got trailing shape {self.shape}: index it"
            )
        value, density, bandwidth = kernel_density(self.sample(size, seed))
        if not np.isfinite(bandwidth):
            raise ValueError("the output does not vary: its distribution is a point mass")
        return np.interp(np.asarray(points, dtype=float), value, density, left=0.0, right=0.0)
