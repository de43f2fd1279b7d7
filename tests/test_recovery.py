"""Coefficient recovery: Kronecker projection, projection onto smaller sets, least squares."""

import numpy as np
import pytest
import scipy.stats as st

from pcmb.chaos.basis import PolynomialBasis, total_index_set
from pcmb.chaos.inputs import Beta, Gamma, Normal, Transformed, Uniform
from pcmb.chaos.nodes import TensorGrid, random_nodes
from pcmb.chaos.recovery import (
    evaluate_tensor,
    fit_largest_stable,
    fit_least_squares,
    project_tensor,
)
from pcmb.errors import IllPosedError


def _basis_matrix(grid, index=None):
    index = grid.multi_index if index is None else index
    families = tuple(d.family for d in grid.distributions)
    return PolynomialBasis(families, index).evaluate(grid.nodes)


@pytest.mark.parametrize(
    ("dists", "orders"),
    [
        ([Uniform(0.0, 1.0)], [6]),
        ([Uniform(0.0, 1.0), Normal(2.0, 0.3), Beta(2.0, 3.0, -1.0, 4.0)], [2, 3, 4]),
        ([Gamma(2.0, 1.0), Uniform(-1.0, 1.0), Normal(0.0, 1.0), Uniform(5.0, 6.0)], [3, 1, 2, 2]),
        ([Transformed(st.lognorm(0.3)), Uniform(0.0, 1.0)], [4, 4]),
    ],
)
def test_kronecker_projection_equals_dense_solve(dists, orders):
    """Part I Eq. 46 c = A⁻¹ y, without forming A, for values with a time axis."""
    grid = TensorGrid(dists, orders)
    values = np.random.default_rng(0).normal(size=(grid.size, 7))
    dense = np.linalg.solve(_basis_matrix(grid), values)
    np.testing.assert_allclose(project_tensor(grid, values), dense, atol=1e-12)


def test_any_trailing_shape_in_one_pass():
    grid = TensorGrid([Uniform(0.0, 1.0), Uniform(0.0, 1.0)], [3, 3])
    values = np.random.default_rng(1).normal(size=(grid.size, 4, 5))
    coef = project_tensor(grid, values)
    assert coef.shape == (16, 4, 5)
    np.testing.assert_allclose(coef[:, 2, 3], project_tensor(grid, values[:, 2, 3]), atol=1e-14)


def test_polynomial_response_is_recovered_exactly():
    """A response in the span of the tensor basis comes back with its exact coefficients."""
    dists = [Uniform(-1.0, 3.0), Normal(1.0, 2.0)]
    grid = TensorGrid(dists, [2, 3])
    true = np.random.default_rng(2).normal(size=grid.size)
    values = _basis_matrix(grid) @ true
    np.testing.assert_allclose(project_tensor(grid, values), true, atol=1e-12)


def test_total_degree_subset_by_projection():
    """Projecting onto the total-degree set of a degree-3 polynomial recovers it exactly."""
    dists = [Uniform(0.0, 1.0), Uniform(0.0, 1.0), Normal(0.0, 1.0)]
    grid = TensorGrid(dists, [3, 3, 3])
    index = total_index_set(3, 3)
    true = np.random.default_rng(3).normal(size=index.shape[0])
    values = _basis_matrix(grid, index) @ true
    np.testing.assert_allclose(project_tensor(grid, values, index), true, atol=1e-12)
    with pytest.raises(ValueError, match="cannot resolve"):
        project_tensor(grid, values, total_index_set(3, 4))


def test_least_squares_recovers_polynomial_on_random_nodes():
    dists = [Uniform(0.0, 1.0), Normal(0.0, 1.0)]
    index = total_index_set(2, 3)
    basis = PolynomialBasis(tuple(d.family for d in dists), index)
    nodes = random_nodes(dists, 60, "lhs", seed=4).nodes
    true = np.random.default_rng(4).normal(size=(index.shape[0], 3))
    fit = fit_least_squares(basis, nodes, basis.evaluate(nodes) @ true)
    np.testing.assert_allclose(fit.coefficients, true, atol=1e-10)
    assert 1.0 <= fit.condition < 100.0
    # The data are exactly representable: leave-one-out error is round-off.
    assert np.all(fit.loo_error < 1e-20)


def test_least_squares_loo_error_flags_an_underfit():
    dists = [Uniform(-1.0, 1.0)]
    nodes = random_nodes(dists, 32, "sobol", seed=0).nodes
    values = np.abs(nodes[:, 0])  # a kink: a degree-2 fit cannot represent it
    fit = fit_least_squares(
        PolynomialBasis((dists[0].family,), total_index_set(1, 2)), nodes, values
    )
    assert fit.loo_error > 1e-3


def test_least_squares_refuses_ill_posed_problems():
    dists = [Uniform(0.0, 1.0)]
    basis = PolynomialBasis((dists[0].family,), total_index_set(1, 5))
    with pytest.raises(IllPosedError, match="6 terms"):
        fit_least_squares(basis, np.zeros((3, 1)), np.zeros(3))
    clustered = np.linspace(0.0, 1e-3, 20)[:, None]
    with pytest.raises(IllPosedError, match="ill conditioned"):
        fit_least_squares(basis, clustered, np.zeros(20))


def test_largest_stable_fit_on_surviving_grid_nodes():
    """After losing nodes of a 6x6 grid, the refit keeps the largest well-posed order."""
    dists = [Uniform(0.0, 1.0), Uniform(0.0, 1.0)]
    grid = TensorGrid(dists, [5, 5])
    x = grid.params
    values = 1.0 + x[:, 0] - 2.0 * x[:, 1] ** 2 + x[:, 0] * x[:, 1]
    keep = np.ones(grid.size, bool)
    keep[[3, 17, 20]] = False
    index, fit = fit_largest_stable(dists, grid.nodes[keep], values[keep], 5, grid.weights[keep])
    assert index.shape[0] * 1.5 <= keep.sum()
    assert index.sum(axis=1).max() >= 2
    # The response is a degree-2 polynomial: the refit is exact.
    exact = project_tensor(grid, values, index)
    np.testing.assert_allclose(fit.coefficients, exact, atol=1e-10)


def test_weighted_loo_error_does_not_depend_on_an_offset():
    """The relative LOO error is a property of the fit's shape error, not of the data's level."""
    dists = [Uniform(-1.0, 1.0)]
    grid = TensorGrid(dists, [7])
    basis = PolynomialBasis((dists[0].family,), total_index_set(1, 2))
    y = np.abs(grid.nodes[:, 0])
    plain = fit_least_squares(basis, grid.nodes, y, grid.weights).loo_error
    shifted = fit_least_squares(basis, grid.nodes, y + 5.0, grid.weights).loo_error
    assert plain == pytest.approx(shifted, rel=1e-9)
    assert plain > 1e-3  # |x| is not a quadratic


@pytest.mark.parametrize("total", [False, True])
def test_evaluation_on_the_grid_equals_the_dense_basis_matrix(total):
    """The Kronecker evaluation is Φ(nodes) @ c, also for a subset of terms and complex c."""
    dists = [Uniform(0.0, 1.0), Normal(2.0, 0.3), Beta(2.0, 3.0, -1.0, 4.0)]
    grid = TensorGrid(dists, [2, 3, 4])
    index = total_index_set(3, 2) if total else grid.multi_index
    rng = np.random.default_rng(5)
    coef = rng.normal(size=(index.shape[0], 6)) + 1j * rng.normal(size=(index.shape[0], 6))
    dense = _basis_matrix(grid, index) @ coef
    np.testing.assert_allclose(evaluate_tensor(grid, coef, index), dense, atol=1e-12)


def test_evaluation_inverts_the_projection():
    grid = TensorGrid([Uniform(0.0, 1.0), Gamma(2.0, 1.0)], [5, 3])
    values = np.random.default_rng(6).normal(size=(grid.size, 3))
    np.testing.assert_allclose(
        evaluate_tensor(grid, project_tensor(grid, values)), values, atol=1e-12
    )
