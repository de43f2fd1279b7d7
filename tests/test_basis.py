"""Index sets and the multivariate basis."""

import math

import numpy as np
import pytest

from pcmb.chaos.basis import (
    PolynomialBasis,
    hyperbolic_index_set,
    tensor_index_set,
    total_index_set,
)
from pcmb.chaos.inputs import Normal, Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.polynomials import Hermite, Legendre


@pytest.mark.parametrize(
    ("n", "counts"), [(5, (6, 21, 56)), (10, (11, 66, 286)), (20, (21, 231, 1771))]
)
def test_total_degree_counts_of_part_one_table_one(n, counts):
    for order, expected in zip((1, 2, 3), counts, strict=True):
        index = total_index_set(n, order)
        assert index.shape == (expected, n)
        assert expected == math.comb(n + order, order)


def test_total_set_is_graded_distinct_and_complete():
    index = total_index_set(3, 4)
    degrees = index.sum(axis=1)
    assert np.all(np.diff(degrees) >= 0)
    assert np.unique(index, axis=0).shape[0] == index.shape[0]
    brute = {a for a in np.ndindex(5, 5, 5) if sum(a) <= 4}
    assert {tuple(r) for r in index} == brute
    assert not index[0].any()


def test_tensor_set_is_anisotropic_c_order():
    index = tensor_index_set([1, 2])
    np.testing.assert_array_equal(index, [[0, 0], [0, 1], [0, 2], [1, 0], [1, 1], [1, 2]])
    assert tensor_index_set([5, 5, 5]).shape == (216, 3)


def test_hyperbolic_set():
    assert np.array_equal(hyperbolic_index_set(4, 3, 1.0), total_index_set(4, 3))
    reduced = hyperbolic_index_set(4, 4, 0.5)
    # q < 1 keeps every univariate term up to the order but prunes interactions.
    assert {tuple(r) for r in reduced} >= {(4, 0, 0, 0), (0, 0, 0, 4), (1, 1, 0, 0)}
    assert (2, 2, 0, 0) not in {tuple(r) for r in reduced}
    assert reduced.shape[0] < total_index_set(4, 4).shape[0]


def test_invalid_index_sets():
    with pytest.raises(ValueError, match=">= 0"):
        tensor_index_set([2, -1])
    with pytest.raises(ValueError, match="order"):
        total_index_set(3, -1)
    with pytest.raises(ValueError, match="q must be"):
        hyperbolic_index_set(3, 2, 1.5)


def test_basis_is_discretely_orthonormal_on_its_grid():
    dists = [Uniform(0.0, 1.0), Normal(0.0, 1.0), Uniform(-2.0, 5.0)]
    grid = TensorGrid(dists, [3, 2, 4])
    basis = PolynomialBasis(tuple(d.family for d in dists), grid.multi_index)
    phi = basis.evaluate(grid.nodes)
    gram = phi.T @ (grid.weights[:, None] * phi)
    np.testing.assert_allclose(gram, np.eye(grid.size), atol=1e-13)


def test_basis_evaluation_is_the_product_of_1d_values():
    dists = [Uniform(0.0, 1.0), Normal(0.0, 1.0)]
    basis = PolynomialBasis(tuple(d.family for d in dists), [[0, 0], [2, 1], [0, 3]])
    xi = np.array([[0.3, -1.2], [-0.7, 0.4]])
    leg = dists[0].family.evaluate(xi[:, 0], 3)
    her = dists[1].family.evaluate(xi[:, 1], 3)
    expected = np.column_stack([np.ones(2), leg[:, 2] * her[:, 1], her[:, 3]])
    np.testing.assert_allclose(basis.evaluate(xi), expected)
    with pytest.raises(ValueError, match=r"\(M, 2\)"):
        basis.evaluate(np.zeros((3, 3)))


@pytest.mark.parametrize(
    "index",
    [tensor_index_set((5, 5, 5)), tensor_index_set((0, 3, 2)), total_index_set(3, 4)],
    ids=["tensor", "tensor-with-order-0", "total"],
)
def test_evaluate_is_the_product_of_the_factors_in_input_order(index):
    """The fast paths give exactly the numbers of the plain product p_a0(x0) p_a1(x1) p_a2(x2)."""
    families = (Legendre(), Hermite(), Legendre())
    xi = np.random.default_rng(1).uniform(-1, 1, size=(50, 3))
    expected = np.ones((50, index.shape[0]))
    for k, family in enumerate(families):
        top = int(index[:, k].max())
        if top:
            expected *= family.evaluate(xi[:, k], top)[:, index[:, k]]
    found = PolynomialBasis(families, index).evaluate(xi)
    assert found.tobytes() == expected.tobytes()


@pytest.mark.parametrize(
    "index", [tensor_index_set((5, 5, 5)), tensor_index_set((3, 0, 2)), total_index_set(3, 4)]
)
@pytest.mark.parametrize("columns", [1, 4, 7])
def test_the_series_is_the_basis_matrix_times_the_coefficients(index, columns):
    """Contracted input by input on a tensor set (few columns) or through Φ: the same sums."""
    families = (Hermite(), Legendre(), Hermite())
    basis = PolynomialBasis(families, index)
    rng = np.random.default_rng(columns)
    xi = rng.uniform(-1.0, 1.0, size=(500, 3))
    coefficients = rng.normal(size=(basis.size, columns))
    expected = basis.evaluate(xi) @ coefficients
    assert np.allclose(basis.series(xi, coefficients), expected, rtol=0, atol=1e-12)
