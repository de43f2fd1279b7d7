"""Element partitions of the input space and the piecewise chaos expansion over them.

Multi-element chaos (Wan & Karniadakis, J. Comput. Phys. 209 (2005)) tiles the support of
the independent inputs with boxes of physical values, the *elements*, and fits one chaos
expansion per element in the element's own orthonormal basis
(:class:`pcmb.chaos.truncated.Conditional` inputs). The surrogate is the piecewise function
y(θ) = y_e(θ) for θ in element e. Its statistics combine the elements by their probabilities
P_e (Σ P_e = 1):

- mean = Σ_e P_e μ_e, variance by the law of total variance Σ_e P_e (σ_e² + (μ_e - μ)²);
- Sobol' indices exactly, from the orthonormal structure of a *tensor* partition (every
  element the product of one interval per input): within a slab of elements along input k
  (the other inputs' intervals fixed), the variance explained by input k is the energy of the
  terms of degree >= 1 in k plus the spread of the other terms' coefficients across the
  slab's intervals of k. Any other partition (from adaptive splitting) is first refined to the
  tensor product of all its split points, each element's expansion re-projected exactly onto
  its sub-elements (a polynomial restricted to a box stays a polynomial of the same degrees).
  Averaging the elements' own indices would be wrong: it ignores the variance *between*
  elements, which is where a jump puts most of it.

Quantiles and densities come from sampling the surrogate, as for :class:`ChaosExpansion`;
spectra from each element's coefficient spectra (:func:`piecewise_spectrum`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.expansion import RELATIVE_NOISE, ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import TensorGrid, draw_germs
from pcmb.chaos.recovery import project_tensor
from pcmb.chaos.spectral import ChaosSpectrum, chaos_spectrum
from pcmb.chaos.truncated import Conditional

__all__ = ["Partition", "PiecewiseExpansion", "piecewise_spectrum"]


class Partition:
    """Boxes of physical values tiling the joint support of independent inputs.

    Parameters
    ----------
    distributions:
        The n inputs, germ order.
    bounds:
        (E, n, 2) each element's [low, high] per input, physical units; the ends of an
        input's support (possibly infinite) are its outer bounds.

    Raises
    ------
    ValueError
        If the bounds are not (E, n, 2), an interval is empty or the probabilities do not
        sum to one (the boxes overlap or leave gaps).
    """

    def __init__(self, distributions: Sequence[Distribution], bounds: ArrayLike):
        self.distributions = tuple(distributions)
        self.bounds = np.array(bounds, dtype=float)
        n = len(self.distributions)
        if self.bounds.ndim != 3 or self.bounds.shape[1:] != (n, 2):
            raise ValueError(f"bounds must be (E, {n}, 2), got shape {self.bounds.shape}")
        if np.any(self.bounds[..., 0] >= self.bounds[..., 1]):
            raise ValueError("every element interval needs low < high")
        if abs(self.probability.sum() - 1.0) > 1e-10:
            raise ValueError(
                f"the elements' probabilities sum to {self.probability.sum()!r}, not 1: "
                "they overlap or leave gaps"
            )

    @classmethod
    def from_splits(
        cls, distributions: Sequence[Distribution], splits: Sequence[Sequence[float]]
    ) -> Partition:
        """The tensor partition cut at ``splits[k]`` (physical values) along input k, elements
        in C order of their intervals (last input fastest), as tensor grid nodes are.

        Raises
        ------
        ValueError
            If a split is not strictly inside its input's support or splits repeat.
        """
        distributions = tuple(distributions)
        edges = []
        for dist, cuts in zip(distributions, splits, strict=True):
            low, high = (float(v) for v in dist.physical.support())
            cuts = sorted(float(c) for c in cuts)
            if any(not low < c < high for c in cuts) or len(set(cuts)) != len(cuts):
                raise ValueError(f"splits must be distinct and inside ({low}, {high}), got {cuts}")
            points = [low, *cuts, high]
            edges.append(list(itertools.pairwise(points)))
        boxes = [list(box) for box in itertools.product(*edges)]
        return cls(distributions, np.array(boxes, dtype=float).reshape(-1, len(edges), 2))

    @classmethod
    def whole(cls, distributions: Sequence[Distribution]) -> Partition:
        """One element: the whole support."""
        return cls.from_splits(distributions, [[] for _ in distributions])

    @property
    def size(self) -> int:
        """Number of elements E."""
        return self.bounds.shape[0]

    @cached_property
    def inputs(self) -> tuple[tuple[Conditional, ...], ...]:
        """Per element, its n conditional inputs (the element's own distributions)."""
        return tuple(
            tuple(
                Conditional(d, low, high)
                for d, (low, high) in zip(self.distributions, box, strict=True)
            )
            for box in self.bounds
        )

    @cached_property
    def probability(self) -> NDArray[np.float64]:
        """(E,) element probabilities, summing to one."""
        return np.array([math.prod(c.probability for c in element) for element in self.inputs])

    def locate(self, theta: ArrayLike) -> NDArray[np.intp]:
        """(M,) the element of each of the (M, n) physical points; -1 outside every element.

        Elements are half-open [low, high) except at the ends of the support, so a point on
        a split belongs to the element above it.
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        support = np.array([d.physical.support() for d in self.distributions], dtype=float)
        low = np.where(self.bounds[..., 0] <= support[:, 0], -np.inf, self.bounds[..., 0])
        high = np.where(self.bounds[..., 1] >= support[:, 1], np.inf, self.bounds[..., 1])
        found = np.full(theta.shape[0], -1, dtype=np.intp)
        for e in range(self.size):
            inside = np.all((theta >= low[e]) & (theta < high[e]), axis=1)
            found[inside] = e
        return found

    def split(self, element: int, inputs: Sequence[int]) -> Partition:
        """The partition with ``element`` cut in two along each of ``inputs``: at the midpoint
        of a bounded interval, at the conditional median of an unbounded one. The children
        replace the element in place, in C order."""
        box = self.bounds[element]
        parts = []
        for k in range(len(self.distributions)):
            low, high = box[k]
            if k not in inputs:
                parts.append([(low, high)])
                continue
            if np.isfinite(low) and np.isfinite(high):
                cut = 0.5 * (low + high)
            else:
                cut = float(self.inputs[element][k].physical.median())
            parts.append([(low, cut), (cut, high)])
        children = np.array([list(c) for c in itertools.product(*parts)], dtype=float)
        bounds = np.concatenate([self.bounds[:element], children, self.bounds[element + 1 :]])
        return Partition(self.distributions, bounds)

    @cached_property
    def edges(self) -> tuple[NDArray[np.float64], ...]:
        """Per input, the sorted distinct interval ends over all elements."""
        return tuple(np.unique(self.bounds[:, k, :]) for k in range(len(self.distributions)))

    @property
    def is_tensor(self) -> bool:
        """Whether the elements are exactly the tensor product of :attr:`edges`, in C order."""
        tensor = Partition.from_splits(self.distributions, [e[1:-1] for e in self.edges])
        return tensor.size == self.size and np.array_equal(tensor.bounds, self.bounds)

    def describe(self, names: Sequence[str]) -> str:
        """In words: ``2 elements, split at x0 = 0`` (every split point of each input)."""
        splits = [
            f"{name} = {', '.join(f'{v:.6g}' for v in edges[1:-1])}"
            for name, edges in zip(names, self.edges, strict=True)
            if edges.size > 2
        ]
        where = f", split at {'; '.join(splits)}" if splits else ""
        return f"{self.size} element{'s' if self.size > 1 else ''}{where}"

    def tensor_refinement(self) -> tuple[Partition, NDArray[np.intp]]:
        """The tensor partition cut at every element edge, and (E',) the element of this
        partition that holds each of its elements."""
        tensor = Partition.from_splits(self.distributions, [e[1:-1] for e in self.edges])
        return tensor, self.locate(_interior_points(tensor.bounds))


def _interior_points(bounds: NDArray[np.float64]) -> NDArray[np.float64]:
    """(E, n) a point strictly inside each box of (E, n, 2) bounds (infinite ends allowed)."""
    low, high = bounds[..., 0], bounds[..., 1]
    return np.where(
        np.isfinite(low) & np.isfinite(high),
        0.5 * (low + high),
        np.where(np.isfinite(low), low + 1.0, np.where(np.isfinite(high), high - 1.0, 0.0)),
    )


class PiecewiseExpansion:
    """A multi-element chaos surrogate of one output (any trailing shape).

    Offers the statistics of :class:`ChaosExpansion` (mean, variance, std, covariance, Sobol'
    indices, evaluation, sampling, quantiles, densities) for the piecewise function.

    Parameters
    ----------
    partition:
        The elements.
    coefficients:
        (E, S, ...) coefficients of each element's expansion in its own basis.
    multi_index:
        (S, n) the terms, shared by every element; must contain the zero index.
    names:
        Optional input names.

    Raises
    ------
    ValueError
        If the shapes disagree (see also :class:`ChaosExpansion`).
    """

    def __init__(
        self,
        partition: Partition,
        coefficients: ArrayLike,
        multi_index: ArrayLike,
        names: Sequence[str] | None = None,
    ):
        self.partition = partition
        self.coefficients = np.asarray(coefficients, dtype=float)
        if self.coefficients.ndim < 2 or self.coefficients.shape[0] != partition.size:
            raise ValueError(
                f"coefficients must be (E={partition.size}, S, ...), "
                f"got shape {self.coefficients.shape}"
            )
        self.elements = tuple(
            ChaosExpansion(c, multi_index, inputs, names)
            for c, inputs in zip(self.coefficients, partition.inputs, strict=True)
        )
        self.names = self.elements[0].names

    # -- structure --------------------------------------------------------------------------

    @property
    def distributions(self) -> tuple[Distribution, ...]:
        """The n inputs (global), germ order."""
        return self.partition.distributions

    @property
    def n(self) -> int:
        return len(self.distributions)

    @property
    def multi_index(self) -> NDArray[np.int64]:
        """(S, n) the terms of every element."""
        return self.elements[0].multi_index

    @property
    def shape(self) -> tuple[int, ...]:
        """Trailing shape of the output."""
        return self.coefficients.shape[2:]

    def __getitem__(self, key: Any) -> PiecewiseExpansion:
        """Expansion of a part of the output: ``expansion[k]`` is time k of an (E, S, T) one."""
        key = key if isinstance(key, tuple) else (key,)
        part = self.coefficients[(slice(None), slice(None), *key)]
        return PiecewiseExpansion(self.partition, part, self.multi_index, self.names)

    # -- moments ----------------------------------------------------------------------------

    @cached_property
    def _spread(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:func:`_deviations` of this expansion: (P,) mean, (P,) scale, (E, S, P) deviations."""
        return _deviations(self.partition.probability, self.coefficients, self._zero)

    @cached_property
    def _zero(self) -> int:
        return int(np.flatnonzero(~self.multi_index.any(axis=1))[0])

    @cached_property
    def _scaled_variance(self) -> NDArray[np.float64]:
        """(P,) Var / scale², and where the output varies beyond round-off."""
        _, _, deviations = self._spread
        return np.einsum("e,esp->p", self.partition.probability, deviations**2)

    @cached_property
    def _varies(self) -> NDArray[np.bool_]:
        mean, scale, _ = self._spread
        scaled = self._scaled_variance
        with np.errstate(over="ignore", invalid="ignore"):
            return scaled > RELATIVE_NOISE**2 * (scaled + (mean / scale) ** 2)

    def mean(self) -> NDArray[np.float64]:
        """E[y] = Σ_e P_e μ_e, shape (...)."""
        return self._spread[0].reshape(self.shape)

    def varies(self) -> NDArray[np.bool_]:
        """Where the output varies beyond round-off, shape (...)."""
        return self._varies.reshape(self.shape)

    def variance(self) -> NDArray[np.float64]:
        """Var[y] = Σ_e P_e (σ_e² + (μ_e - μ)²), shape (...); 0 where the output does not vary."""
        scale = self._spread[1]
        with np.errstate(over="ignore"):
            variance = self._scaled_variance * scale**2
        return np.where(self._varies, variance, 0.0).reshape(self.shape)

    def std(self) -> NDArray[np.float64]:
        """Standard deviation, shape (...); exactly 0 where the output does not vary."""
        std = np.sqrt(self._scaled_variance) * self._spread[1]
        return np.where(self._varies, std, 0.0).reshape(self.shape)

    def covariance(self, other: PiecewiseExpansion) -> NDArray[np.float64]:
        """Cov[y, z] = Σ_e P_e (Cov_e[y, z] + (μ_e^y - μ^y)(μ_e^z - μ^z)), shape (...).

        Raises
        ------
        ValueError
            If the two do not share the partition and the terms.
        """
        if not (
            np.array_equal(self.partition.bounds, other.partition.bounds)
            and np.array_equal(self.multi_index, other.multi_index)
        ):
            raise ValueError("covariance needs two expansions on the same elements and terms")
        mine, theirs = self.coefficients.copy(), other.coefficients.copy()
        mine[:, self._zero] -= self.mean()
        theirs[:, self._zero] -= other.mean()
        return np.einsum("e,es...,es...->...", self.partition.probability, mine, theirs)

    # -- sensitivity ------------------------------------------------------------------------

    @cached_property
    def _sobol(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(n, P) first-order and total partial variances over the variance."""
        partition, coefficients = self.partition, self.coefficients
        if not partition.is_tensor:
            partition, coefficients = _restrict(self, *partition.tensor_refinement())
        _, _, deviations = _deviations(partition.probability, coefficients, self._zero)
        shares = [np.array([c.probability for c in _axis(partition, k)]) for k in range(self.n)]
        grid = deviations.reshape(*(s.size for s in shares), *deviations.shape[1:])
        first, total = np.empty((2, self.n, grid.shape[-1]))
        for k in range(self.n):
            first[k], total[k] = _partial_variances(grid, shares, self.multi_index, k)
        variance = np.einsum("e,esp->p", partition.probability, deviations**2)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (
                np.where(self._varies, first / variance, np.nan),
                np.where(self._varies, total / variance, np.nan),
            )

    def sobol_first(self) -> NDArray[np.float64]:
        """First-order Sobol' indices of the piecewise surrogate, (n, ...); NaN where the
        output does not vary."""
        return self._sobol[0].reshape(self.n, *self.shape)

    def sobol_total(self) -> NDArray[np.float64]:
        """Total Sobol' indices of the piecewise surrogate, (n, ...); NaN where the output
        does not vary."""
        return self._sobol[1].reshape(self.n, *self.shape)

    # -- the surrogate ----------------------------------------------------------------------

    def __call__(self, theta: ArrayLike) -> NDArray[np.float64]:
        """The surrogate at physical points θ, (M, n) -> (M, ...); NaN outside the support."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if theta.shape[1] != self.n:
            raise ValueError(f"physical points must be (M, {self.n}), got shape {theta.shape}")
        where = self.partition.locate(theta)
        out = np.full((theta.shape[0], *self.shape), np.nan)
        for e, element in enumerate(self.elements):
            inside = where == e
            if inside.any():
                out[inside] = element(theta[inside])
        return out

    def evaluate_germ(self, xi: ArrayLike) -> NDArray[np.float64]:
        """The surrogate at the inputs' (global) germ points ξ, (M, n) -> (M, ...)."""
        xi = np.atleast_2d(np.asarray(xi, dtype=float))
        return self(
            np.column_stack([d.to_physical(xi[:, k]) for k, d in enumerate(self.distributions)])
        )

    def sample(self, size: int, seed: int | None = 0) -> NDArray[np.float64]:
        """Values of the surrogate at ``size`` random inputs, (size, ...); the same draws as
        :meth:`ChaosExpansion.sample` with the same seed."""
        return self.evaluate_germ(draw_germs(self.distributions, size, np.random.default_rng(seed)))

    # Both use only ``sample`` and ``shape``: the same estimates as for one expansion.
    quantile = ChaosExpansion.quantile
    pdf = ChaosExpansion.pdf


def _deviations(
    probability: NDArray[np.float64], coefficients: NDArray[np.float64], zero: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The mean (P,), a power-of-two scale (P,) and (E, S, P) the coefficients over the scale
    with each mean term replaced by its deviation μ_e - μ, trailing axes flattened: the
    variance is Σ_e P_e Σ_s deviation² times scale², with no overflow or underflow."""
    flat = coefficients.reshape(*coefficients.shape[:2], -1)
    mean = probability @ flat[:, zero]
    deviations = flat.copy()
    deviations[:, zero] -= mean
    top = np.max(np.abs(np.where(np.isfinite(deviations), deviations, 0.0)), axis=(0, 1))
    scale = np.where(top > 0, np.ldexp(1.0, np.frexp(top)[1]), 1.0)
    return mean, scale, deviations / scale


def _axis(partition: Partition, k: int) -> list[Conditional]:
    """The intervals of input k of a tensor partition, as conditional inputs, in order."""
    edges = partition.edges[k]
    return [Conditional(partition.distributions[k], a, b) for a, b in itertools.pairwise(edges)]


def _partial_variances(
    grid: NDArray[np.float64],
    shares: Sequence[NDArray[np.float64]],
    multi_index: NDArray[np.int64],
    k: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """First-order and total partial variances (P,) of input k on a tensor partition.

    ``grid`` is (m_1, ..., m_n, S, P) scaled deviations (see :func:`_deviations`), ``shares[l]``
    the (m_l,) interval probabilities of input l. A slab is a choice of the other inputs'
    intervals, of probability w; along it, input k takes its m_k intervals.
    """
    moved = np.moveaxis(grid, k, 0)
    slabs = moved.reshape(moved.shape[0], -1, *moved.shape[-2:])  # (m_k, R, S, P)
    others = [shares[j] for j in range(len(shares)) if j != k]
    w = np.ones(1)
    for share in others:
        w = np.multiply.outer(w, share).ravel()
    p = shares[k]
    degree = multi_index[:, k]
    pure = ~np.delete(multi_index, k, axis=1).any(axis=1)
    # First order: E[y | θ_k] has coefficients averaged over the slabs, its variance the sum
    # of their squares (the mean term carries μ_i - μ).
    conditional = np.einsum("r,irsp->isp", w, slabs[:, :, pure])
    first = np.einsum("i,isp->p", p, conditional**2)
    # Total: E[Var(y | θ_~k)], per slab the energy of degree >= 1 in k and the spread across
    # the intervals of k of the other coefficients.
    active = np.einsum("i,r,irsp->p", p, w, slabs[:, :, degree > 0] ** 2)
    rest = slabs[:, :, degree == 0]
    centred = rest - np.einsum("i,irsp->rsp", p, rest)
    total = active + np.einsum("i,r,irsp->p", p, w, centred**2)
    return first, total


def _restrict(
    expansion: PiecewiseExpansion, tensor: Partition, parent: NDArray[np.intp]
) -> tuple[Partition, NDArray[np.float64]]:
    """Coefficients (E', S, P) of ``expansion`` on the elements of a finer tensor partition,
    each re-projected exactly from the element that holds it (a tensor Gauss grid of the
    basis' largest degrees integrates the products exactly)."""
    orders = tuple(int(p) for p in expansion.multi_index.max(axis=0))
    flat = expansion.coefficients.reshape(*expansion.coefficients.shape[:2], -1)
    restricted = np.empty((tensor.size, *flat.shape[1:]))
    for e, (inputs, holder) in enumerate(zip(tensor.inputs, parent, strict=True)):
        grid = TensorGrid(inputs, orders)
        values = expansion.elements[holder](grid.params).reshape(grid.size, -1)
        restricted[e] = project_tensor(grid, values, expansion.multi_index)
    return tensor, restricted


def piecewise_spectrum(
    expansion: PiecewiseExpansion, times: ArrayLike, window: str = "hann"
) -> ChaosSpectrum:
    """:func:`~pcmb.chaos.spectral.chaos_spectrum` of a piecewise (E, S, T) expansion.

    Each element's PSD is projected on its own tensor Gauss grid (of the basis' largest
    degrees, the grid it was recovered on); the mean PSD combines the elements by probability,
    ``psd_expansion`` is the :class:`PiecewiseExpansion` of the PSD and ``spectra`` (E, S, F)
    holds each element's coefficient spectra.
    """
    orders = tuple(int(p) for p in expansion.multi_index.max(axis=0))
    parts = [
        chaos_spectrum(element, TensorGrid(inputs, orders), times, window)
        for element, inputs in zip(expansion.elements, expansion.partition.inputs, strict=True)
    ]
    psd = PiecewiseExpansion(
        expansion.partition,
        np.stack([part.psd_expansion.coefficients for part in parts]),
        expansion.multi_index,
        expansion.names,
    )
    mean = expansion.partition.probability @ np.stack([part.mean for part in parts])
    spectra = np.stack([part.spectra for part in parts])
    return ChaosSpectrum(parts[0].frequency, mean, psd.std(), psd, spectra, parts[0].scale)
