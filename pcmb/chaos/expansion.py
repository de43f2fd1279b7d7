"""The chaos expansion y(ξ) = Σ_α c_α φ_α(ξ) and its statistics.

Coefficients have shape (S, ...): one row per basis term, any trailing shape (an output
over time is (S, T)). Every statistic is vectorised over the trailing axes and computed
from the coefficients alone, because the basis is orthonormal:

- mean = c_0, variance = Σ_{α≠0} c_α² (never E[y²] - E[y]², which cancels catastrophically),
- covariance of two outputs on the same basis = Σ_{α≠0} c_α d_α,
- Sobol' first index of input k = Σ c_α² over α involving only input k, divided by the variance;
  total index = Σ c_α² over α involving input k (at all), divided by the variance.

Where the output does not vary (e.g. at t = 0 with a deterministic initial state), its
standard deviation is exactly 0 and its Sobol' indices are undefined, returned as NaN rather
than as round-off noise: "does not vary" is a variance below (1e-12)² of the output's mean
square, :meth:`ChaosExpansion.varies`.

No statistic overflows where the exact one is representable: coefficients beyond ±1e150
(whose squares could overflow) or below ±1e-150 (whose squares lose digits to underflow) are
divided by a power of two near their size before squaring, column by column, which leaves
the other columns — every ordinary output — to the plain arithmetic, bit for bit. The
standard deviation of an output near 1e200 is then finite (its variance, 1e400, is not).
:func:`sample_mean` and :func:`sample_std` do the same for the statistics of sampled runs.

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

__all__ = [
    "ChaosExpansion",
    "power_of_two",
    "root_sum_of_squares",
    "sample_mean",
    "sample_std",
    "unsafe_to_square",
]

#: A standard deviation below this fraction of the output's RMS is round-off: the output does
#: not vary there (std 0, Sobol' NaN).
RELATIVE_NOISE = 1e-12
#: Magnitudes beyond which squares may overflow (1e150² = 1e300, with room for 1e8 terms),
#: and below which they underflow into subnormals: such columns are scaled before squaring.
_HUGE, _TINY = 1e150, 1e-150
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
    def _scale(self) -> NDArray[np.float64] | None:
        """(P,) powers of two to divide each column by before squaring, trailing axes
        flattened; ``None`` when no column needs it (then the plain arithmetic is used)."""
        return _power_of_two_scale(self.coefficients.reshape(self.multi_index.shape[0], -1))

    @cached_property
    def _squares(self) -> NDArray[np.float64]:
        """(S, P) squared fluctuation coefficients, trailing axes flattened (shared by Sobol'),
        of the coefficients divided by :attr:`_scale` when there is one."""
        if self._scale is None:
            return (self._fluctuations**2).reshape(self.multi_index.shape[0], -1)
        return (self._fluctuations.reshape(self.multi_index.shape[0], -1) / self._scale) ** 2

    @cached_property
    def _sum_of_squares(self) -> NDArray[np.float64]:
        """(P,) Σ_{α≠0} c_α², scaled like :attr:`_squares`."""
        return self._squares.sum(axis=0)

    @cached_property
    def _defined(self) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """(P,) where the variance is above round-off, and (P,) where it is not (neither
        where it is NaN or infinite)."""
        variance = self._sum_of_squares
        mean = self.coefficients[self._zero].reshape(-1)
        if self._scale is not None:
            mean = mean / self._scale
        with np.errstate(over="ignore", invalid="ignore"):
            threshold = RELATIVE_NOISE**2 * (variance + mean**2)
        return variance > threshold, np.isfinite(variance) & (variance <= threshold)

    def varies(self) -> NDArray[np.bool_]:
        """Where the output varies beyond round-off, shape (...): elsewhere its std is 0 and its
        Sobol' indices are NaN. False where a coefficient is not finite."""
        return self._defined[0].reshape(self.shape)

    def variance(self) -> NDArray[np.float64]:
        """Var[y] = Σ_{α≠0} c_α², shape (...); 0 where the output does not vary, inf where the
        variance exceeds the largest float (the std may still be finite)."""
        variance = self._sum_of_squares
        if self._scale is not None:
            with np.errstate(over="ignore"):
                scaled = (np.sqrt(variance) * self._scale) ** 2
            variance = np.where(self._scale == 1.0, variance, scaled)
        return np.where(self._defined[1], 0.0, variance).reshape(self.shape)

    def std(self) -> NDArray[np.float64]:
        """Standard deviation, shape (...); exactly 0 where the output does not vary."""
        std = np.sqrt(self._sum_of_squares)
        if self._scale is not None:
            with np.errstate(over="ignore"):
                std = std * self._scale
        return np.where(self._defined[1], 0.0, std).reshape(self.shape)

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
        variance = self._sum_of_squares
        with np.errstate(divide="ignore", invalid="ignore"):
            indices = np.where(self._defined[0], partial / variance, np.nan)
        return indices.reshape(masks.shape[0], *self.shape)

    def sobol_first(self) -> NDArray[np.float64]:
        """First-order Sobol' indices S_k, shape (n, ...); NaN where the output does not vary."""
        active = self.multi_index > 0
        only = active & (active.sum(axis=1) == 1)[:, None]
        return self._sobol(only.T)

    def sobol_total(self) -> NDArray[np.float64]:
        """Total Sobol' indices S_Tk, shape (n, ...); NaN where the output does not vary."""
        return self._sobol((self.multi_index > 0).T)

    def sobol_total_group(self, group: Sequence[int]) -> NDArray[np.float64]:
        """Total Sobol' index of a group of inputs (the germs of one random process): the
        share of the variance in the terms that involve any of them, shape (...); NaN where
        the output does not vary."""
        involved = (self.multi_index[:, list(group)] > 0).any(axis=1)
        return self._sobol(involved[None, :])[0]

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
            out[block] = self.basis.series(xi[block], flat)
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
        :func:`pcmb.chaos.density.kernel_density`, the one stored in result files; it is zero
        beyond three bandwidths from the samples, and beyond an end where they pile up.

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


# -- overflow-safe squares ---------------------------------------------------------------------


def power_of_two(top: NDArray[np.float64]) -> NDArray[np.float64]:
    """The power of two 2^(e-1) with top = m 2^e, 0.5 <= m < 1: top / 2^(e-1) is in [1, 2),
    and 2^(e-1) is a float for every finite top > 0 (2^e is not for top near 1.8e308)."""
    return np.ldexp(1.0, np.frexp(top)[1] - 1)


def _power_of_two_scale(columns: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """(P,) a power of two near the largest |value| of each column of (M, P) values whose
    squares could overflow or underflow (1 for the other columns), or ``None`` when there is
    none.

    Dividing by a power of two is exact, so a scaled column keeps every digit; the scale is
    that of the column's finite values (its NaN and inf stay what they are).
    """
    magnitude = np.abs(columns)
    magnitude = np.where(np.isfinite(magnitude), magnitude, 0.0)
    top = np.max(magnitude, axis=0) if columns.shape[0] else np.zeros(columns.shape[1])
    risky = (top > _HUGE) | ((top < _TINY) & (top > 0))
    if not risky.any():
        return None
    return np.where(risky, power_of_two(np.where(risky, top, 1.0)), 1.0)


def unsafe_to_square(values: ArrayLike) -> bool:
    """Whether some finite values are so large (> 1e150) or so small (< 1e-150, not 0) in
    magnitude that their squares could overflow or lose digits to underflow."""
    values = np.asarray(values, dtype=float)
    return _power_of_two_scale(values.reshape(1, -1)) is not None


def root_sum_of_squares(values: ArrayLike) -> NDArray[np.float64]:
    """sqrt(Σ values²) over the first axis of (M, ...) values, computed on values scaled by a
    power of two where their squares could overflow or underflow."""
    values = np.asarray(values, dtype=float)
    columns = values.reshape(values.shape[0], -1)
    scale = _power_of_two_scale(columns)
    if scale is None:
        return np.sqrt(np.sum(values**2, axis=0))
    with np.errstate(over="ignore"):
        norms = np.sqrt(np.sum((columns / scale) ** 2, axis=0)) * scale
    return norms.reshape(values.shape[1:])


def sample_mean(values: ArrayLike) -> NDArray[np.float64]:
    """Mean over the first axis of (M, ...) values, ``values.mean(axis=0)`` unless that
    overflows with finite values, where the values are scaled by a power of two first."""
    values = np.asarray(values, dtype=float)
    with np.errstate(over="ignore"):
        mean = np.asarray(values.mean(axis=0))
    flat, columns = mean.reshape(-1), values.reshape(values.shape[0], -1)
    overflowed = np.isinf(flat) & np.isfinite(columns).all(axis=0)
    if overflowed.any():
        scale = power_of_two(np.max(np.abs(columns[:, overflowed]), axis=0))
        flat[overflowed] = (columns[:, overflowed] / scale).mean(axis=0) * scale
    return flat.reshape(mean.shape)


def sample_std(values: ArrayLike, ddof: int = 1) -> NDArray[np.float64]:
    """Standard deviation over the first axis of (M, ...) values, ``values.std(axis=0,
    ddof=ddof)``, exactly 0 where every value is the same, and computed on values scaled by
    a power of two where their squares could overflow or underflow."""
    values = np.asarray(values, dtype=float)
    columns = values.reshape(values.shape[0], -1)
    scale = _power_of_two_scale(columns)
    if scale is None:
        std = values.std(axis=0, ddof=ddof)
    else:
        with np.errstate(over="ignore"):
            std = (columns / scale).std(axis=0, ddof=ddof) * scale
        std = std.reshape(values.shape[1:])
    if values.shape[0]:
        constant = np.all(values == values[:1], axis=0)
        std = np.where(constant, 0.0, std)
    return np.asarray(std, dtype=float)
