"""Node sets: tensor grids in the (N, n) convention, random and quasi-random samples."""

import numpy as np
import pytest

from pcmb.chaos.inputs import Normal, Uniform
from pcmb.chaos.nodes import TensorGrid, random_nodes


def test_tensor_grid_layout_and_weights():
    dists = [Uniform(0.0, 2.0), Normal(5.0, 0.1)]
    grid = TensorGrid(dists, [2, 1])
    assert grid.shape == (3, 2) and grid.size == 6
    assert grid.nodes.shape == grid.params.shape == (6, 2)
    assert grid.weights.sum() == pytest.approx(1.0, abs=1e-15)
    # C order: the last input varies fastest.
    np.testing.assert_array_equal(grid.nodes[:2, 0], [grid.nodes[0, 0]] * 2)
    np.testing.assert_allclose(grid.params[:, 0], 1.0 + grid.nodes[:, 0])
    np.testing.assert_allclose(grid.params[:, 1], 5.0 + 0.1 * grid.nodes[:, 1])
    # Quadrature of θ1 · θ2² is exact: E = 1 · (25 + 0.01).
    integrand = grid.params[:, 0] * grid.params[:, 1] ** 2
    assert grid.weights @ integrand == pytest.approx(25.01, rel=1e-14)


def test_tensor_grid_validation():
    with pytest.raises(ValueError, match="one order per input"):
        TensorGrid([Uniform(0.0, 1.0)], [1, 2])
    with pytest.raises(ValueError, match=">= 0"):
        TensorGrid([Uniform(0.0, 1.0)], [-1])


@pytest.mark.parametrize("method", ["montecarlo", "lhs", "sobol"])
def test_random_nodes_are_reproducible_and_in_law(method):
    dists = [Uniform(0.0, 2.0), Normal(5.0, 0.1)]
    a = random_nodes(dists, 256, method, seed=7)
    b = random_nodes(dists, 256, method, seed=7)
    np.testing.assert_array_equal(a.nodes, b.nodes)
    assert a.nodes.shape == a.params.shape == (256, 2)
    assert np.all((a.params[:, 0] >= 0) & (a.params[:, 0] <= 2))
    # Sample mean within 5 standard errors.
    assert abs(a.params[:, 1].mean() - 5.0) < 5 * 0.1 / 16


def test_lhs_is_stratified():
    nodes = random_nodes([Uniform(0.0, 1.0)], 50, "lhs", seed=0).params[:, 0]
    counts = np.histogram(nodes, bins=50, range=(0, 1))[0]
    assert np.all(counts == 1)


def test_unknown_method():
    with pytest.raises(ValueError, match="unknown sampling method"):
        random_nodes([Uniform(0.0, 1.0)], 4, "grid")
