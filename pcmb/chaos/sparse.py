"""Smolyak sparse grids on nested rules, recovered by sparse pseudo-spectral projection.

A sparse grid is a combination of small tensor rules. Its index set K is a downward-closed
set of level multi-indices i (one 1-D level i_k per input); the Smolyak operator is

    S_K = Σ_{i∈K} c_i Q^(i),   c_i = Σ_{z∈{0,1}^n, i+z∈K} (-1)^|z|,

with Q^(i) = Q^(i_1) ⊗ ... ⊗ Q^(i_n) the tensor product of the 1-D nested rules
(:mod:`pcmb.chaos.nested`); only the i with c_i ≠ 0 are ever built. The isotropic grid of
level L is K = {i : |i| <= L}; anisotropic weights w_k keep {i : Σ w_k i_k <= L min w}.

Recovery is sparse pseudo-spectral projection (Constantine, Eldred & Phipps, CMAME 229,
2012; Conrad & Marzouk, SIAM J. Sci. Comput. 35, 2013): each tensor rule projects onto the
box of terms α with α_k <= p(i_k) = ⌊e(i_k)/2⌋, so every product φ_α φ_β it needs is
integrated exactly, and the projections are combined with the c_i. The result is exact (to
round-off) for every expansion on the union of these boxes, :attr:`SparseGrid.multi_index`:
for α in the box of j ∈ K, the 1-D differences P_l - P_{l-1} vanish on α_k for l > j_k, so
only the i <= j contribute and their sum telescopes to the tensor projection of j, which
reproduces α. Direct quadrature of φ_α φ_β over the whole sparse set would alias instead:
the combined rule is not exact for the products of the highest terms.

Nodes are deduplicated exactly: every 1-D rule is a prefix of one point sequence, so a node
is named by integer positions in those sequences (no floating-point tolerance involved).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.basis import total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import NestedRule, nested_rule
from pcmb.chaos.nodes import _physical
from pcmb.chaos.recovery import _along_axes, _rows

__all__ = [
    "SparseGrid",
    "box_index_set",
    "combination_coefficients",
    "find_rows",
    "project_sparse",
    "smolyak_index_set",
]


def box_index_set(levels: Sequence[int]) -> NDArray[np.int64]:
    """(K, n) every level multi-index of the box 0..levels[k] in each input: a tensor grid."""
    return np.array(list(itertools.product(*(range(top + 1) for top in levels))), dtype=np.int64)


def smolyak_index_set(
    n: int, level: int, weights: Sequence[float] | None = None
) -> NDArray[np.int64]:
    """The Smolyak level set {i >= 0 : Σ_k w_k i_k <= level · min w}.

    Parameters
    ----------
    n:
        Number of inputs.
    level:
        Smolyak level L >= 0 (the highest 1-D level of the most important input).
    weights:
        (n,) positive importance weights; a larger weight gives an input fewer levels
        (input k reaches L min w / w_k). Default: isotropic, {i : |i| <= L}.

    Returns
    -------
    ndarray
        (K, n) level multi-indices, graded by |i|, starting with the zero index.

    Raises
    ------
    ValueError
        If n < 1, level < 0, or the weights are not n positive finite numbers.
    """
    index = total_index_set(n, level)
    if weights is None:
        return index
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,) or not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError(f"need {n} positive finite weights, got {weights!r}")
    # Σ w_k i_k <= L min w implies |i| <= L: the set is a subset of the total one.
    return index[index @ w <= level * w.min() * (1.0 + 1e-12)]


def combination_coefficients(index_set: ArrayLike) -> NDArray[np.int64]:
    """Smolyak combination coefficients c_i = Σ_{z∈{0,1}^n, i+z∈K} (-1)^|z| of a set K.

    Computed as Π_k (1 - S_k) applied to the indicator of K (S_k the forward shift in input
    k): n vectorised passes, exact in integers.

    Parameters
    ----------
    index_set:
        (K, n) downward-closed level multi-indices.

    Returns
    -------
    ndarray
        (K,) integer coefficients, in the rows' order; they sum to 1.

    Raises
    ------
    ValueError
        If the set is not downward closed (or has repeated or negative rows).
    """
    index = _downward_closed(index_set)
    table = _Lookup(index)
    coefficients = np.ones(index.shape[0], dtype=np.int64)
    for k in range(index.shape[1]):
        forward = table.find(index + np.eye(1, index.shape[1], k, dtype=np.int64))
        shifted = np.where(forward >= 0, coefficients[np.maximum(forward, 0)], 0)
        coefficients = coefficients - shifted
    return coefficients


@dataclass(frozen=True)
class SparseGrid:
    """The sparse grid of a downward-closed level set on nested 1-D rules.

    Attributes
    ----------
    distributions:
        One per input, germ order.
    index_set:
        (K, n) downward-closed level multi-indices.
    rules:
        One nested rule per input, with the levels the set uses.

    Build the usual grids with :meth:`smolyak`.
    """

    distributions: tuple[Distribution, ...]
    index_set: NDArray[np.int64]
    rules: tuple[NestedRule, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "distributions", tuple(self.distributions))
        object.__setattr__(self, "rules", tuple(self.rules))
        index = _downward_closed(self.index_set)
        object.__setattr__(self, "index_set", index)
        n = len(self.distributions)
        if index.shape[1] != n or len(self.rules) != n:
            raise ValueError(
                f"need one index column and one rule per input ({n}): index set "
                f"{index.shape}, {len(self.rules)} rules"
            )
        for rule, top in zip(self.rules, index.max(axis=0), strict=True):
            rule._check(int(top))

    @classmethod
    def smolyak(
        cls,
        distributions: Sequence[Distribution],
        level: int,
        rule: str = "auto",
        weights: Sequence[float] | None = None,
    ) -> SparseGrid:
        """The (an)isotropic Smolyak grid of ``level`` (see :func:`smolyak_index_set`), with
        the nested rule ``rule`` (:func:`pcmb.chaos.nested.nested_rule`) in every input.

        Raises
        ------
        ValueError
            Bad level, weights or rule (a rule that does not fit an input or lacks a level).
        """
        distributions = tuple(distributions)
        index = smolyak_index_set(len(distributions), level, weights)
        tops = index.max(axis=0)
        rules = tuple(
            nested_rule(d.family, rule, int(top))
            for d, top in zip(distributions, tops, strict=True)
        )
        return cls(distributions, index, rules)

    # -- size, known without building the nodes ----------------------------------------------

    @property
    def n(self) -> int:
        """Number of inputs."""
        return len(self.distributions)

    @cached_property
    def size(self) -> int:
        """Number of distinct nodes N = Σ_{i∈K} Π_k (m(i_k) - m(i_k - 1)), m(-1) = 0."""
        new = np.ones(self.index_set.shape[0], dtype=np.int64)
        for k, rule in enumerate(self.rules):
            sizes = np.array(
                [0] + [rule.size(level) for level in range(int(self.index_set[:, k].max()) + 1)]
            )
            new *= np.diff(sizes)[self.index_set[:, k]]
        return int(new.sum())

    # -- the combination ---------------------------------------------------------------------

    @cached_property
    def _tensors(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(J, n) levels and (J,) coefficients of the tensor rules with c_i ≠ 0."""
        coefficients = combination_coefficients(self.index_set)
        used = coefficients != 0
        return self.index_set[used], coefficients[used]

    @cached_property
    def _layout(
        self,
    ) -> tuple[NDArray[np.float64], list[NDArray[np.intp]], NDArray[np.int64]]:
        """(N, n) germ nodes, per tensor rule the rows of its nodes (C order), and (N, n) the
        nodes' positions in the rules' sequences."""
        levels, _ = self._tensors
        sizes = np.array(
            [
                [r.size(int(level)) for r, level in zip(self.rules, row, strict=True)]
                for row in levels
            ]
        )
        ids = np.concatenate([np.indices(s).reshape(self.n, -1).T for s in sizes])
        table, rows = np.unique(ids, axis=0, return_inverse=True)
        sequences = [rule.nodes(int(levels[:, k].max())) for k, rule in enumerate(self.rules)]
        germ = np.column_stack([seq[table[:, k]] for k, seq in enumerate(sequences)])
        return germ, np.split(rows.ravel(), np.cumsum(np.prod(sizes, axis=1))[:-1]), table

    @property
    def nodes(self) -> NDArray[np.float64]:
        """(N, n) germ coordinates ξ of the distinct nodes."""
        return self._layout[0]

    @property
    def node_ids(self) -> NDArray[np.int64]:
        """(N, n) each node's position in its inputs' nested sequences: exact names of the
        nodes, shared by every grid on the same rules (for incremental grids)."""
        return self._layout[2]

    @cached_property
    def params(self) -> NDArray[np.float64]:
        """(N, n) physical values θ = T(ξ) of the nodes."""
        return _physical(self.distributions, self.nodes)

    @cached_property
    def weights(self) -> NDArray[np.float64]:
        """(N,) sparse quadrature weights Σ_i c_i w^(i): they sum to one but some are
        negative, so they are no probability weights (and no least-squares weights)."""
        levels, coefficients = self._tensors
        out = np.zeros(self.size)
        for row, c, rows in zip(levels, coefficients, self._layout[1], strict=True):
            tensor = np.ones(())
            for rule, level in zip(self.rules, row, strict=True):
                tensor = np.multiply.outer(tensor, rule.weights(int(level)))
            out[rows] += c * tensor.ravel()
        return out

    def projection_degrees(self, levels: ArrayLike) -> NDArray[np.int64]:
        """(..., n) projection degrees p(i_k) = ⌊e(i_k)/2⌋ of level multi-indices (..., n)."""
        levels = np.asarray(levels, dtype=np.int64)
        out = np.empty_like(levels)
        for k, rule in enumerate(self.rules):
            table = np.array(
                [rule.projection_degree(level) for level in range(int(levels[..., k].max()) + 1)]
            )
            out[..., k] = table[levels[..., k]]
        return out

    @cached_property
    def _terms(self) -> tuple[NDArray[np.int64], list[NDArray[np.intp]]]:
        """(S, n) exact set (graded, zero first) and, per tensor rule, its box's rows."""
        levels, _ = self._tensors
        boxes = [np.indices(p + 1).reshape(self.n, -1).T for p in self.projection_degrees(levels)]
        union, rows = np.unique(np.concatenate(boxes), axis=0, return_inverse=True)
        graded = np.lexsort((*union.T[::-1], union.sum(axis=1)))
        rank = np.empty_like(graded)
        rank[graded] = np.arange(graded.size)
        rows = rank[rows.ravel()]
        return union[graded], np.split(rows, np.cumsum([box.shape[0] for box in boxes])[:-1])

    @property
    def multi_index(self) -> NDArray[np.int64]:
        """(S, n) the terms the grid recovers exactly: the union over K of the boxes
        {α : α_k <= p(i_k)}, graded by total degree, starting with the zero index."""
        return self._terms[0]

    def project(self, values: ArrayLike) -> NDArray[np.float64]:
        """Coefficients on :attr:`multi_index` by sparse pseudo-spectral projection.

        Parameters
        ----------
        values:
            (N, ...) values at :attr:`nodes` (e.g. (N, T), or (N, outputs, T)).

        Returns
        -------
        ndarray
            (S, ...) coefficients: one matrix product per input and tensor rule, over all
            trailing entries at once.
        """
        values = _rows(values, self.size)
        flat = values.reshape(self.size, -1)
        levels, coefficients = self._tensors
        out = np.zeros((self.multi_index.shape[0], flat.shape[1]))
        for row, c, nodes, terms in zip(
            levels, coefficients, self._layout[1], self._terms[1], strict=True
        ):
            # Inputs at level 0 have one node and the 1×1 projector [1]: skipped.
            active = [
                rule.projector(int(level))
                for rule, level in zip(self.rules, row, strict=True)
                if level > 0
            ]
            out[terms] += c * _along_axes(active, flat[nodes])
        return out.reshape(-1, *values.shape[1:])

    @cached_property
    def _node_lookup(self) -> _Lookup:
        return _Lookup(self.node_ids)

    def surplus(self, level: ArrayLike, values: ArrayLike) -> NDArray[np.float64]:
        """Coefficients the tensor difference Δ_i = ⊗_k (P_{i_k} - P_{i_k - 1}) of one level
        multi-index i of the set adds (its hierarchical surplus), by sparse projection.

        Parameters
        ----------
        level:
            (n,) a level multi-index of :attr:`index_set`.
        values:
            (N, ...) values at :attr:`nodes`.

        Returns
        -------
        ndarray
            (Π_k (p(i_k) + 1), ...) coefficients on the box {α : α_k <= p(i_k)}, C order.

        Raises
        ------
        ValueError
            If ``level`` is not in the set.
        """
        level = np.asarray(level, dtype=np.int64).reshape(1, self.n)
        if _Lookup(self.index_set).find(level)[0] < 0:
            raise ValueError(f"level {tuple(level[0])} is not in the index set")
        pairs = list(zip(self.rules, level[0].tolist(), strict=True))
        sizes = [rule.size(at) for rule, at in pairs]
        ids = np.indices(sizes).reshape(self.n, -1).T
        values = _rows(values, self.size)
        flat = values.reshape(self.size, -1)[self._node_lookup.find(ids)]
        # Inputs at level 0: the 1×1 operator [1], skipped as in :meth:`project`.
        active = [rule.difference(at) for rule, at in pairs if at > 0]
        return _along_axes(active, flat).reshape(-1, *values.shape[1:])


def project_sparse(
    grid: SparseGrid, values: ArrayLike, names: Sequence[str] | None = None
) -> ChaosExpansion:
    """The chaos expansion of values on a sparse grid, by sparse pseudo-spectral projection.

    Parameters
    ----------
    grid:
        The grid the values were computed on.
    values:
        (N, ...) values at ``grid.nodes``.
    names:
        Optional input names.

    Returns
    -------
    ChaosExpansion
        On ``grid.multi_index``, with the values' trailing shape.
    """
    return ChaosExpansion(grid.project(values), grid.multi_index, grid.distributions, names)


def find_rows(table: ArrayLike, rows: ArrayLike) -> NDArray[np.intp]:
    """Positions of integer ``rows`` (M, n) in ``table`` (K, n) of distinct rows, -1 where
    absent: exact lookups of level multi-indices or :attr:`SparseGrid.node_ids`."""
    table = np.asarray(table, dtype=np.int64)
    return _Lookup(table).find(np.asarray(rows, dtype=np.int64).reshape(-1, table.shape[1]))


class _Lookup:
    """Positions of integer rows in a table of distinct rows (-1 where absent)."""

    def __init__(self, table: NDArray[np.int64]):
        self._keys = _keys(table)
        self._order = np.argsort(self._keys)
        self._sorted = self._keys[self._order]

    def find(self, rows: NDArray[np.int64]) -> NDArray[np.intp]:
        keys = _keys(rows)
        at = np.minimum(np.searchsorted(self._sorted, keys), self._sorted.size - 1)
        return np.where(self._sorted[at] == keys, self._order[at], -1)


def _keys(rows: NDArray[np.int64]) -> NDArray[np.void]:
    """Each int64 row as one opaque key, for sorting and exact lookups."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    return rows.view(np.dtype((np.void, 8 * rows.shape[1]))).ravel()


def _downward_closed(index_set: ArrayLike) -> NDArray[np.int64]:
    """The set as a (K, n) int64 array, checked: distinct, non-negative, downward closed."""
    index = np.asarray(index_set, dtype=np.int64)
    if index.ndim != 2 or index.shape[0] == 0 or index.shape[1] == 0:
        raise ValueError(f"an index set is a non-empty (K, n) array, got shape {index.shape}")
    if index.min() < 0:
        raise ValueError("level multi-indices must be non-negative")
    if np.unique(_keys(index)).size != index.shape[0]:
        raise ValueError("level multi-indices must be distinct")
    table = _Lookup(index)
    for k in range(index.shape[1]):
        has = index[:, k] > 0
        back = table.find(index[has] - np.eye(1, index.shape[1], k, dtype=np.int64))
        if np.any(back < 0):
            missing = index[has][back < 0][0]
            raise ValueError(
                f"the index set is not downward closed: {tuple(missing)} lacks its "
                f"backward neighbour in input {k}"
            )
    return index
