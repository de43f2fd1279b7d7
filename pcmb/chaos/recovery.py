"""Recovery of chaos coefficients from model runs.

Values are (N, ...) arrays — one row per node, any trailing shape (typically (N, T), an
output over time) — and coefficients come back as (S, ...): every time point is
recovered in one pass.

- :func:`project_tensor`: tensor Gauss grid -> coefficients by the 1-D projections
  Vᵀ W applied along each axis of the Kronecker structure (Part I Eq. 46 without ever
  forming the S×S matrix: O(S Σ q_k) work per time point, O(S) memory). For the tensor
  basis of the grid's orders this equals the interpolation A⁻¹ y; for a smaller basis
  (e.g. total degree) it is the pseudo-spectral projection.
- :func:`fit_least_squares`: any node set (random samples, the surviving nodes of a
  grid after failures), with the condition number and a leave-one-out error reported,
  and :class:`pcmb.errors.IllPosedError` when the fit cannot be trusted.
- :func:`fit_largest_stable`: the largest total-degree fit that stays well posed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.basis import PolynomialBasis, total_index_set
from pcmb.chaos.expansion import RELATIVE_NOISE
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import TensorGrid
from pcmb.errors import IllPosedError

__all__ = [
    "LeastSquaresFit",
    "evaluate_tensor",
    "fit_largest_stable",
    "fit_least_squares",
    "project_tensor",
]

#: Largest condition number of the (weighted) basis matrix accepted by least squares.
MAX_CONDITION = 1e8
#: Nodes per term that :func:`fit_largest_stable` requires (oversampling for a stable fit).
OVERSAMPLING = 1.5


def _rows(values: ArrayLike, n_nodes: int) -> NDArray:
    """Values as a float (or complex) array with one row per node."""
    values = np.asarray(values)
    values = values if np.iscomplexobj(values) else values.astype(float, copy=False)
    if values.ndim == 0 or values.shape[0] != n_nodes:
        raise ValueError(f"values must have one row per node ({n_nodes}), got shape {values.shape}")
    return values


def project_tensor(
    grid: TensorGrid, values: ArrayLike, multi_index: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Chaos coefficients from values on a tensor Gauss grid.

    Parameters
    ----------
    grid:
        The tensor grid the values were computed on.
    values:
        (N, ...) model values at ``grid.nodes``.
    multi_index:
        (S, n) terms wanted; default the grid's full tensor set (``grid.multi_index``).
        Every α_k must be <= the grid's order P_k.

    Returns
    -------
    ndarray
        (S, ...) coefficients, in the order of ``multi_index``.

    Raises
    ------
    ValueError
        If values do not match the grid or a term exceeds the grid's orders.
    """
    values = _rows(values, grid.size)
    projectors = [
        (dist.family.evaluate(rule.nodes, order) * rule.weights[:, None]).T
        for dist, rule, order in zip(grid.distributions, grid.rules, grid.orders, strict=True)
    ]
    coef = _along_axes(projectors, values)
    if multi_index is None:
        return coef
    return coef[_tensor_positions(grid, multi_index)]


def evaluate_tensor(
    grid: TensorGrid, coefficients: ArrayLike, multi_index: ArrayLike | None = None
) -> NDArray:
    """The expansion Σ_α c_α φ_α at every node of a tensor grid, without the N×S matrix.

    The inverse of :func:`project_tensor`: the 1-D basis matrices V_k are applied along each
    axis, O(S Σ q_k) work per trailing entry instead of O(N S).

    Parameters
    ----------
    grid:
        The tensor grid.
    coefficients:
        (S, ...) coefficients, real or complex (e.g. coefficient spectra).
    multi_index:
        (S, n) their terms; default the grid's full tensor set. Every α_k <= P_k.

    Returns
    -------
    ndarray
        (N, ...) values at ``grid.nodes``.

    Raises
    ------
    ValueError
        If the coefficients do not match the terms or a term exceeds the grid's orders.
    """
    coefficients = np.asarray(coefficients)
    if multi_index is not None:
        positions = _tensor_positions(grid, multi_index)
        if coefficients.ndim == 0 or coefficients.shape[0] != positions.size:
            raise ValueError(
                f"need one coefficient row per term ({positions.size}), got {coefficients.shape}"
            )
        full = np.zeros((grid.size, *coefficients.shape[1:]), dtype=coefficients.dtype)
        full[positions] = coefficients
        coefficients = full
    coefficients = _rows(coefficients, grid.size)
    bases = [
        dist.family.evaluate(rule.nodes, order)
        for dist, rule, order in zip(grid.distributions, grid.rules, grid.orders, strict=True)
    ]
    return _along_axes(bases, coefficients)


def _along_axes(matrices: Sequence[NDArray], array: NDArray) -> NDArray:
    """Apply square matrices[k] along axis k of a C-ordered tensor stored as (N, ...)."""
    trailing = array.shape[1:]
    out = array.reshape(array.shape[0], -1)
    # Axis k of the C-ordered grid is the middle axis of a (left, q_k, right) view:
    # one batched matmul per axis, each result contiguous for the next.
    left, right = 1, out.size
    for matrix in matrices:
        right //= matrix.shape[1]
        out = np.matmul(matrix, out.reshape(left, matrix.shape[1], right))
        left *= matrix.shape[0]
    return out.reshape(-1, *trailing)


def _tensor_positions(grid: TensorGrid, multi_index: ArrayLike) -> NDArray[np.intp]:
    """Rows of the grid's C-ordered tensor set that hold the given terms."""
    index = np.asarray(multi_index, dtype=np.int64)
    if index.ndim != 2 or index.shape[1] != len(grid.orders):
        raise ValueError(f"multi_index must be (S, {len(grid.orders)}), got {index.shape}")
    if np.any(index > np.array(grid.orders)):
        raise ValueError(
            f"the grid of orders {grid.orders} cannot resolve terms up to {tuple(index.max(0))}"
        )
    return np.ravel_multi_index(tuple(index.T), grid.shape)


@dataclass(frozen=True)
class LeastSquaresFit:
    """Result of a least-squares chaos fit.

    Attributes
    ----------
    coefficients:
        (S, ...) fitted coefficients.
    condition:
        2-norm condition number of the (weighted) basis matrix.
    loo_error:
        (...) relative leave-one-out error, mean of squared LOO residuals divided by the
        variance of the values (NaN where the values do not vary): the honest estimate
        of how well the expansion predicts a run it has not seen.
    """

    coefficients: NDArray[np.float64]
    condition: float
    loo_error: NDArray[np.float64]


def fit_least_squares(
    basis: PolynomialBasis,
    nodes: ArrayLike,
    values: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    max_condition: float = MAX_CONDITION,
) -> LeastSquaresFit:
    """Fit coefficients by (weighted) least squares on arbitrary nodes.

    Parameters
    ----------
    basis:
        The chaos basis (S terms).
    nodes:
        (N, n) germ coordinates.
    values:
        (N, ...) model values.
    weights:
        (N,) optional positive weights (e.g. quadrature weights of surviving grid nodes).
    max_condition:
        Largest acceptable condition number of the weighted basis matrix.

    Returns
    -------
    LeastSquaresFit

    Raises
    ------
    IllPosedError
        If there are fewer nodes than terms, or the basis matrix is too ill conditioned.
    """
    nodes = np.asarray(nodes, dtype=float)
    values = _rows(values, nodes.shape[0])
    n_nodes, n_terms = nodes.shape[0], basis.size
    if n_nodes < n_terms:
        raise IllPosedError(
            f"least squares needs at least as many nodes as terms: {n_nodes} nodes, {n_terms} terms"
        )
    trailing = values.shape[1:]
    rhs = values.reshape(n_nodes, -1)
    matrix = basis.evaluate(nodes)
    share = np.full((n_nodes, 1), 1.0 / n_nodes)
    if weights is not None:
        share = np.asarray(weights, dtype=float)[:, None] / np.sum(weights)
    root = np.sqrt(share)
    weighted, scaled = matrix * root, rhs * root
    q, r = np.linalg.qr(weighted)
    singular = np.linalg.svd(r, compute_uv=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else np.inf
    if not condition <= max_condition:
        raise IllPosedError(
            f"the least-squares basis matrix is ill conditioned (condition number {condition:.3g}"
            f" > {max_condition:.3g}) with {n_nodes} nodes and {n_terms} terms: use fewer terms"
            " or more, better spread nodes"
        )
    coefficients = np.linalg.solve(r, q.T @ scaled)
    # Leave-one-out residuals of the weighted fit, (y_i - ŷ_i) / (1 - h_i), in the units of
    # y, averaged with the same weights and relative to the weighted variance of y.
    residual = rhs - matrix @ coefficients
    leverage = np.einsum("ij,ij->i", q, q)
    with np.errstate(divide="ignore", invalid="ignore"):
        loo = np.sum(share * (residual / (1.0 - leverage)[:, None]) ** 2, axis=0)
        spread = np.sum(share * (rhs - np.sum(share * rhs, axis=0)) ** 2, axis=0)
        # A std below 1e-12 of the RMS is round-off (runs equal but for the last bit).
        varies = spread > RELATIVE_NOISE**2 * np.sum(share * rhs**2, axis=0)
        loo_error = np.where(varies, loo / spread, np.nan)
    return LeastSquaresFit(
        coefficients=coefficients.reshape(n_terms, *trailing),
        condition=condition,
        loo_error=loo_error.reshape(trailing),
    )


def fit_largest_stable(
    distributions: Sequence[Distribution],
    nodes: ArrayLike,
    values: ArrayLike,
    max_order: int,
    weights: ArrayLike | None = None,
    *,
    orders: Sequence[int] | None = None,
    max_condition: float = MAX_CONDITION,
) -> tuple[NDArray[np.int64], LeastSquaresFit]:
    """The highest total-degree least-squares fit (order <= max_order) that is well posed.

    Used by the ``regress`` failure policy: a grid with failed nodes is refitted on the
    survivors with a basis small enough to have ``OVERSAMPLING`` nodes per term and a
    condition number below ``max_condition``. ``orders`` caps the degree per input (an
    anisotropic grid with q_k points cannot resolve degree q_k in input k: those columns
    would be aliased or, for q_k = 1, zero).

    Returns
    -------
    multi_index, fit
        The (S, n) total-degree set chosen and its fit.

    Raises
    ------
    IllPosedError
        If not even the constant (order 0) fit is possible.
    """
    distributions = tuple(distributions)
    nodes = np.asarray(nodes, dtype=float)
    families = tuple(d.family for d in distributions)
    last_problem = "no nodes"
    caps = None if orders is None else np.asarray(orders)
    for order in range(max_order, -1, -1):
        index = total_index_set(len(distributions), order)
        if caps is not None:
            index = index[np.all(index <= caps, axis=1)]
        if nodes.shape[0] < OVERSAMPLING * index.shape[0] and order > 0:
            continue
        try:
            fit = fit_least_squares(
                PolynomialBasis(families, index),
                nodes,
                values,
                weights,
                max_condition=max_condition,
            )
        except IllPosedError as error:
            last_problem = str(error)
            continue
        return index, fit
    raise IllPosedError(f"no stable least-squares fit exists: {last_problem}")
