"""Node sets: tensor Gauss grids for collocation, random and quasi-random samples.

Axis convention, used everywhere in pcmb: node arrays are (N, n) — nodes × inputs, in the
inputs' germ order. Tensor grid nodes are in C order (last input varies fastest), so
values of shape (N, ...) reshape to (q_1, ..., q_n, ...).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.basis import tensor_index_set
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.polynomials import GaussRule

__all__ = [
    "NodeSet",
    "TensorGrid",
    "draw_germs",
    "latin_hypercube",
    "overflowing_inputs",
    "random_nodes",
    "unit_nodes",
]

SamplingMethod = Literal["montecarlo", "lhs", "sobol"]


def _physical(distributions: Sequence[Distribution], germ: NDArray[np.float64]) -> NDArray:
    return np.column_stack([d.to_physical(germ[:, k]) for k, d in enumerate(distributions)])


def draw_germs(
    distributions: Sequence[Distribution], size: int, rng: np.random.Generator
) -> NDArray[np.float64]:
    """(size, n) independent germ draws, one column per input (Monte Carlo, surrogate sampling)."""
    return np.column_stack([d.sample_germ(size, rng) for d in distributions])


@dataclass(frozen=True)
class TensorGrid:
    """The tensor product of 1-D Gauss rules, q_k = orders[k] + 1 points per input.

    With the tensor basis of the same orders the collocation system is square and
    interpolation equals pseudo-spectral projection (:func:`pcmb.chaos.recovery.project_tensor`).

    Attributes
    ----------
    distributions:
        One per input, germ order.
    orders:
        Chaos order P_k per input (anisotropic allowed).
    """

    distributions: tuple[Distribution, ...]
    orders: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "distributions", tuple(self.distributions))
        object.__setattr__(self, "orders", tuple(int(p) for p in self.orders))
        if len(self.orders) != len(self.distributions):
            raise ValueError(
                f"need one order per input: {len(self.distributions)} inputs, "
                f"{len(self.orders)} orders"
            )
        if not self.orders:
            raise ValueError("a grid needs at least one input")
        if min(self.orders) < 0:
            raise ValueError(f"orders must be >= 0, got {self.orders}")

    @property
    def shape(self) -> tuple[int, ...]:
        """Points per input, (q_1, ..., q_n)."""
        return tuple(p + 1 for p in self.orders)

    @property
    def size(self) -> int:
        """Number of nodes N = Π q_k."""
        return int(np.prod(self.shape))

    @cached_property
    def rules(self) -> tuple[GaussRule, ...]:
        """The 1-D Gauss rules, one per input."""
        return tuple(
            d.family.gauss_rule(q) for d, q in zip(self.distributions, self.shape, strict=True)
        )

    @cached_property
    def nodes(self) -> NDArray[np.float64]:
        """(N, n) germ coordinates ξ of the nodes."""
        axes = np.meshgrid(*[r.nodes for r in self.rules], indexing="ij")
        return np.stack([a.ravel() for a in axes], axis=1)

    @cached_property
    def weights(self) -> NDArray[np.float64]:
        """(N,) probability weights (products of the 1-D weights), summing to one."""
        weights = np.ones(())
        for rule in self.rules:
            weights = np.multiply.outer(weights, rule.weights)
        return weights.ravel()

    @cached_property
    def params(self) -> NDArray[np.float64]:
        """(N, n) physical values θ = T(ξ) of the nodes."""
        return _physical(self.distributions, self.nodes)

    @cached_property
    def multi_index(self) -> NDArray[np.int64]:
        """(N, n) the tensor index set matching the grid (same C order)."""
        return tensor_index_set(self.orders)


@dataclass(frozen=True)
class NodeSet:
    """An arbitrary set of nodes, e.g. random samples.

    Attributes
    ----------
    distributions:
        One per input, germ order.
    nodes:
        (N, n) germ coordinates.
    params:
        (N, n) physical values.
    """

    distributions: tuple[Distribution, ...]
    nodes: NDArray[np.float64]
    params: NDArray[np.float64]

    @property
    def size(self) -> int:
        return self.nodes.shape[0]


def random_nodes(
    distributions: Sequence[Distribution],
    samples: int,
    method: SamplingMethod = "montecarlo",
    seed: int | None = 0,
) -> NodeSet:
    """Random or quasi-random nodes for sampling studies and least-squares fits.

    Parameters
    ----------
    distributions:
        The inputs, germ order.
    samples:
        Number of nodes N >= 1.
    method:
        ``"montecarlo"`` (independent draws), ``"lhs"`` (Latin hypercube) or ``"sobol"``
        (scrambled Sobol'; N should be a power of two for its balance properties).
    seed:
        Seed of the random generator; the same seed gives the same nodes.

    Returns
    -------
    NodeSet

    Raises
    ------
    ValueError
        If samples < 1 or the method is unknown.
    """
    distributions = tuple(distributions)
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    n = len(distributions)
    rng = np.random.default_rng(seed)
    if method == "montecarlo":
        germ = draw_germs(distributions, samples, rng)
    elif method in ("lhs", "sobol"):
        if method == "lhs":
            u = latin_hypercube(samples, n, rng)
        else:
            from scipy.stats import qmc  # deferred: scipy.stats is slow to import

            with warnings.catch_warnings():
                # Balance with N not a power of two: the sampling design reports it.
                warnings.filterwarnings(
                    "ignore", message=".*balance properties", category=UserWarning
                )
                u = qmc.Sobol(d=n, scramble=True, rng=rng).random(samples)
        return unit_nodes(distributions, u)
    else:
        raise ValueError(f"unknown sampling method {method!r}: use montecarlo, lhs or sobol")
    return NodeSet(distributions, germ, _physical(distributions, germ))


def latin_hypercube(samples: int, inputs: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """(samples, inputs) points in the unit cube, one in each of ``samples`` equal slices of
    every input, drawn from ``rng``."""
    slices = np.column_stack([rng.permutation(samples) for _ in range(inputs)])
    return (slices + rng.random((samples, inputs))) / samples


def unit_nodes(distributions: Sequence[Distribution], u: ArrayLike) -> NodeSet:
    """The nodes of points ``u`` (N, n) in the unit cube, mapped through each input's germ
    quantile (how quasi-random and stratified designs reach the inputs)."""
    u = np.asarray(u, dtype=float)
    distributions = tuple(distributions)
    germ = np.column_stack([d.family.quantile(u[:, k]) for k, d in enumerate(distributions)])
    return NodeSet(distributions, germ, _physical(distributions, germ))


def overflowing_inputs(
    nodes: TensorGrid | NodeSet, names: Sequence[str]
) -> Iterator[tuple[str, str]]:
    """``(name, what is wrong)`` for each input (``names`` in germ order) whose value is not
    a finite number at some node: a distribution too wide for floating point (a normal of
    std 1e307) overflows in its map from the germ."""
    with np.errstate(over="ignore", invalid="ignore"):  # the overflow is what this reports
        params = nodes.params
    for k, name in enumerate(names):
        values = params[:, k]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = bad[0]
            yield (
                name,
                f"at {bad.size} of {values.size} node(s) its value is not a finite number "
                f"(germ value {nodes.nodes[i, k]:.6g} gives {values[i]}): the distribution is "
                "too wide for floating point; give this parameter in other units",
            )


def join_nodes(first: TensorGrid | NodeSet, second: TensorGrid | NodeSet) -> NodeSet:
    """The nodes of ``first`` followed by those of ``second`` (same inputs), as a NodeSet."""
    return NodeSet(
        first.distributions,
        np.concatenate([first.nodes, second.nodes]),
        np.concatenate([first.params, second.params]),
    )
