"""Multi-index sets and evaluation of the multivariate chaos basis.

A basis function is a tensor product φ_α(ξ) = Π_k p_{α_k}(ξ_k) of the inputs' 1-D
orthonormal polynomials. Index sets are (S, n) integer arrays, one row per term, and
always start with the zero multi-index (the mean term).

- ``tensor_index_set(orders)``: 0 <= α_k <= P_k, S = Π (P_k + 1) (Part I Eq. 27). Rows in
  C order (last input varies fastest), the same order as :class:`pcmb.chaos.nodes.TensorGrid`
  nodes, so tensor coefficients reshape to (P_1+1, ..., P_n+1).
- ``total_index_set(n, order)``: |α| <= P, S = (n+P)! / (n! P!) (Part I Eq. 26), graded by
  total degree.
- ``hyperbolic_index_set(n, order, q)``: (Σ α_k^q)^(1/q) <= P, a subset of the total set
  that drops high-order interactions (q = 1 is the total set).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.polynomials import OrthonormalFamily

__all__ = [
    "PolynomialBasis",
    "hyperbolic_index_set",
    "tail_terms",
    "tensor_index_set",
    "total_index_set",
]


def _check_orders(orders: Sequence[int]) -> tuple[int, ...]:
    orders = tuple(int(p) for p in orders)
    if not orders:
        raise ValueError("an index set needs at least one input")
    if min(orders) < 0:
        raise ValueError(f"orders must be >= 0, got {orders}")
    return orders


def tensor_index_set(orders: Sequence[int]) -> NDArray[np.int64]:
    """All α with 0 <= α_k <= orders[k], in C order.

    Returns
    -------
    ndarray
        (S, n) with S = Π (orders[k] + 1).

    Raises
    ------
    ValueError
        If no order is given or one is negative.
    """
    orders = _check_orders(orders)
    grids = np.meshgrid(*[np.arange(p + 1) for p in orders], indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1).astype(np.int64)


def total_index_set(n: int, order: int) -> NDArray[np.int64]:
    """All α in n inputs with |α| <= order, by total degree, then ascending lexicographic.

    Returns
    -------
    ndarray
        (S, n) with S = C(n + order, n).

    Raises
    ------
    ValueError
        If n < 1 or order < 0.
    """
    if n < 1:
        raise ValueError(f"an index set needs at least one input, got n={n}")
    if order < 0:
        raise ValueError(f"order must be >= 0, got {order}")
    rows: list[tuple[int, ...]] = []
    for degree in range(order + 1):
        # Compositions of `degree` into n parts, via stars and bars.
        for bars in itertools.combinations(range(degree + n - 1), n - 1):
            edges = (-1, *bars, degree + n - 1)
            rows.append(tuple(edges[i + 1] - edges[i] - 1 for i in range(n)))
    return np.array(rows, dtype=np.int64).reshape(-1, n)


def hyperbolic_index_set(n: int, order: int, q: float) -> NDArray[np.int64]:
    """The α of the total set with q-quasi-norm (Σ α_k^q)^(1/q) <= order, 0 < q <= 1.

    Raises
    ------
    ValueError
        If q is not in (0, 1].
    """
    if not 0.0 < q <= 1.0:
        raise ValueError(f"q must be in (0, 1], got {q}")
    total = total_index_set(n, order)
    norm = np.sum(total.astype(float) ** q, axis=1) ** (1.0 / q)
    # A tolerance keeps the boundary terms that round-off pushes just above `order`.
    return total[norm <= order * (1.0 + 1e-12)]


@dataclass(frozen=True)
class PolynomialBasis:
    """The tensor-product orthonormal basis {φ_α} over a multi-index set.

    Attributes
    ----------
    families:
        One 1-D family per input (germ order).
    multi_index:
        (S, n) non-negative integers.
    """

    families: tuple[OrthonormalFamily, ...]
    multi_index: NDArray[np.int64]

    def __post_init__(self) -> None:
        index = np.asarray(self.multi_index)
        if index.ndim != 2 or index.shape[1] != len(self.families):
            raise ValueError(
                f"multi_index must be (S, {len(self.families)}), got shape {index.shape}"
            )
        if index.size and index.min() < 0:
            raise ValueError("multi-indices must be non-negative")
        object.__setattr__(self, "families", tuple(self.families))
        object.__setattr__(self, "multi_index", index.astype(np.int64))

    @property
    def size(self) -> int:
        """Number of terms S."""
        return self.multi_index.shape[0]

    def evaluate(self, xi: ArrayLike) -> NDArray[np.float64]:
        """The basis matrix Φ with Φ[i, j] = φ_{α_j}(ξ_i).

        Parameters
        ----------
        xi:
            (M, n) germ points.

        Returns
        -------
        ndarray
            (M, S).

        Raises
        ------
        ValueError
            If xi is not (M, n).
        """
        xi = self._germ_points(xi)
        # Φ[:, j] = Π_k p_{α_jk}(ξ_k), multiplied in input order k = 0, 1, ... (inputs of
        # degree 0 contribute the factor 1 and are skipped). The first factor is taken as is
        # instead of 1·p: the same numbers, without filling and rescanning a ones matrix.
        factors = []
        for k, family in enumerate(self.families):
            top = int(self.multi_index[:, k].max(initial=0))
            if top > 0:
                factors.append((k, family.evaluate(xi[:, k], top)))
        if not factors:
            return np.ones((xi.shape[0], self.size))
        if self._tensor_orders is not None:
            # Full tensor set in C order: Φ is the outer product of the factors, built by
            # broadcasting, with no gather of (M, S) columns.
            out = factors[0][1]
            for _, values in factors[1:]:
                product = out[:, :, None] * values[:, None, :]
                out = product.reshape(xi.shape[0], out.shape[1] * values.shape[1])
            return out
        out = None
        for k, values in factors:
            column = np.take(values, self.multi_index[:, k], axis=1)
            if out is None:
                out = column
            else:
                out *= column
        return out

    def series(self, xi: ArrayLike, coefficients: ArrayLike) -> NDArray[np.float64]:
        """Σ_j c_jk φ_j(ξ_m): ``evaluate(xi) @ coefficients`` for (S, K) ``coefficients``.

        On a full tensor set with at most as many columns as the first input has degrees,
        the sum is contracted one input at a time (the first by one matrix product, the
        others per point), without the (M, S) matrix Φ, whose making is most of the cost of
        a few columns at many points (a study's PDFs: 10^5 draws, one column per time).
        """
        coefficients = np.asarray(coefficients, dtype=float)
        orders = self._tensor_orders
        if orders is None or coefficients.shape[1] > orders[0] + 1:
            return self.evaluate(xi) @ coefficients
        xi = self._germ_points(xi)
        columns = coefficients.shape[1]
        factors = [
            family.evaluate(xi[:, k], order)
            for k, (family, order) in enumerate(zip(self.families, orders, strict=True))
        ]
        # (M, rest · K) after the first input, then one input less per step.
        partial = factors[0] @ coefficients.reshape(orders[0] + 1, -1)
        for factor in factors[1:]:
            partial = np.matmul(
                factor[:, None, :], partial.reshape(xi.shape[0], factor.shape[1], -1)
            )
        return partial.reshape(xi.shape[0], columns)

    def _germ_points(self, xi: ArrayLike) -> NDArray[np.float64]:
        """``xi`` as (M, n) floats; ValueError if it is not (M, n)."""
        xi = np.asarray(xi, dtype=float)
        n = len(self.families)
        if xi.ndim != 2 or xi.shape[1] != n:
            raise ValueError(f"germ points must be (M, {n}), got shape {xi.shape}")
        return xi

    @cached_property
    def _tensor_orders(self) -> tuple[int, ...] | None:
        """The orders when the index set is the full tensor set in C order, else None."""
        orders = tuple(int(p) for p in self.multi_index.max(axis=0, initial=0))
        # The count first: a sparse basis of high orders in many inputs would otherwise build a
        # tensor set of prod(p + 1) terms just to be told apart (12^8 terms for Smolyak L3, 8D).
        if self.multi_index.shape[0] != math.prod(p + 1 for p in orders):
            return None
        if np.array_equal(self.multi_index, tensor_index_set(orders)):
            return orders
        return None


def tail_terms(multi_index: ArrayLike, depth: int = 2, lowest: int = 2) -> NDArray[np.bool_]:
    """(S,) the terms of total degree >= ``lowest`` in the outer ``depth`` layers of an index
    set.

    α is in the tail when α + depth·e_k leaves the set for some input k that the set varies
    (largest degree >= 1): for a total set of order P that is |α| >= P - depth + 1, for a
    tensor set α_k >= P_k - depth + 1 for some k. Terms of total degree 0 and 1 are never in
    it by default, so a response linear in its inputs has an empty tail at every order (an
    order below 3 has fewer than two layers above the linear ones).
    """
    index = np.asarray(multi_index, dtype=np.int64)
    present = {tuple(row) for row in index}
    tail = np.zeros(index.shape[0], dtype=bool)
    for k in np.flatnonzero(index.max(axis=0) >= 1):
        shifted = index.copy()
        shifted[:, k] += depth
        tail |= np.array([tuple(row) not in present for row in shifted])
    return tail & (index.sum(axis=1) >= lowest)
