"""ChaosExpansion statistics against closed forms (Ishigami) and an independent oracle."""

import numpy as np
import pytest

from pcmb.chaos.basis import total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Normal, Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.references import ishigami, ishigami_moments

PI = np.pi


@pytest.fixture(scope="module")
def ishigami_expansion():
    dists = [Uniform(-PI, PI)] * 3
    # sin needs high degree; x3 enters only as x3^4, exact at order 4.
    grid = TensorGrid(dists, [21, 21, 4])
    return ChaosExpansion(project_tensor(grid, ishigami(grid.params)), grid.multi_index, dists)


def test_ishigami_moments_and_sobol_indices(ishigami_expansion):
    mean, variance, first, total = ishigami_moments()
    exp = ishigami_expansion
    assert exp.mean() == pytest.approx(mean, abs=1e-6)
    assert exp.variance() == pytest.approx(variance, abs=1e-6)
    np.testing.assert_allclose(exp.sobol_first(), first, atol=1e-6)
    np.testing.assert_allclose(exp.sobol_total(), total, atol=1e-6)


def test_surrogate_reproduces_the_function(ishigami_expansion):
    x = np.random.default_rng(0).uniform(-PI, PI, size=(200, 3))
    np.testing.assert_allclose(ishigami_expansion(x), ishigami(x), atol=1e-6)


def _time_expansion():
    """y(t; a, b) = a·t + b²: closed-form moments for a ~ U[1, 3], b ~ N(0, 1)."""
    dists = [Uniform(1.0, 3.0), Normal(0.0, 1.0)]
    grid = TensorGrid(dists, [2, 3])
    t = np.linspace(0.0, 2.0, 5)
    a, b = grid.params[:, :1], grid.params[:, 1:]
    return ChaosExpansion(
        project_tensor(grid, a * t + b**2), grid.multi_index, dists, ["a", "b"]
    ), t


def test_statistics_are_vectorised_over_time():
    exp, t = _time_expansion()
    # E[a] = 2, Var a = 1/3; E[b²] = 1, Var b² = 2.
    np.testing.assert_allclose(exp.mean(), 2 * t + 1, atol=1e-13)
    np.testing.assert_allclose(exp.variance(), t**2 / 3 + 2, atol=1e-13)
    first = exp.sobol_first()
    assert first.shape == (2, 5)
    np.testing.assert_allclose(first[0], (t**2 / 3) / (t**2 / 3 + 2), atol=1e-13)
    # No interaction: first == total.
    np.testing.assert_allclose(exp.sobol_total(), first, atol=1e-13)
    assert exp[3].mean() == pytest.approx(exp.mean()[3])


def test_covariance_between_outputs():
    dists = [Uniform(1.0, 3.0), Normal(0.0, 1.0)]
    grid = TensorGrid(dists, [2, 2])
    a, b = grid.params[:, 0], grid.params[:, 1]
    y = ChaosExpansion(project_tensor(grid, a + b), grid.multi_index, dists)
    z = ChaosExpansion(project_tensor(grid, a - 2 * b), grid.multi_index, dists)
    # Cov(a + b, a - 2b) = Var a - 2 Var b = 1/3 - 2.
    assert y.covariance(z) == pytest.approx(1 / 3 - 2, abs=1e-13)
    assert y.covariance(y) == pytest.approx(y.variance())


def test_sobol_is_nan_where_the_output_does_not_vary():
    dists = [Uniform(0.0, 1.0)]
    grid = TensorGrid(dists, [3])
    values = np.column_stack([np.full(4, 2.0), grid.params[:, 0]])
    first = ChaosExpansion(project_tensor(grid, values), grid.multi_index, dists).sobol_first()
    assert np.isnan(first[0, 0]) and first[0, 1] == pytest.approx(1.0)


def test_quantiles_and_pdf_from_the_surrogate():
    """y = θ with θ ~ N(1, 2²): quantiles and density of a Gaussian."""
    from scipy.stats import norm

    dists = [Normal(1.0, 2.0)]
    grid = TensorGrid(dists, [1])
    exp = ChaosExpansion(project_tensor(grid, grid.params[:, 0]), grid.multi_index, dists)
    q = exp.quantile([0.1, 0.5, 0.9], size=200_000)
    # Sampling error of a quantile with 2e5 samples: ~ 2·sqrt(p(1-p)/n)/pdf ≈ 0.02.
    np.testing.assert_allclose(q, norm(1, 2).ppf([0.1, 0.5, 0.9]), atol=0.03)
    x = np.array([-1.0, 1.0, 3.0])
    # KDE bias (bandwidth ~ 0.17·σ) and noise: a few percent of the peak density.
    np.testing.assert_allclose(exp.pdf(x), norm(1, 2).pdf(x), atol=0.005)
    with pytest.raises(ValueError, match="scalar"):
        _time_expansion()[0].pdf([0.0])


def test_sobol_indices_match_chaospy_oracle():
    """Independent implementation (chaospy, test-only): total-degree projection on Gauss nodes."""
    chaospy = pytest.importorskip("chaospy")
    dists = [Uniform(-PI, PI)] * 3
    # Order 3 keeps chaospy's symbolic Sobol' computation to seconds.
    grid = TensorGrid(dists, [3, 3, 3])
    index = total_index_set(3, 3)
    coef = project_tensor(grid, ishigami(grid.params), index)
    exp = ChaosExpansion(coef, index, dists)
    joint = chaospy.J(*[chaospy.Uniform(-PI, PI) for _ in range(3)])
    expansion = chaospy.generate_expansion(3, joint, normed=True)
    nodes, weights = chaospy.generate_quadrature(3, joint, rule="gaussian")
    surrogate = chaospy.fit_quadrature(expansion, nodes, weights, ishigami(nodes.T))
    # Both are the same discrete projection: agreement to round-off.
    np.testing.assert_allclose(exp.mean(), chaospy.E(surrogate, joint), atol=1e-10)
    np.testing.assert_allclose(exp.std(), chaospy.Std(surrogate, joint), atol=1e-10)
    np.testing.assert_allclose(exp.sobol_first(), chaospy.Sens_m(surrogate, joint), atol=1e-10)
    np.testing.assert_allclose(exp.sobol_total(), chaospy.Sens_t(surrogate, joint), atol=1e-10)


def test_invalid_expansions():
    dists = [Uniform(0.0, 1.0)]
    with pytest.raises(ValueError, match="one row per term"):
        ChaosExpansion(np.zeros((3, 2)), [[0], [1]], dists)
    with pytest.raises(ValueError, match="zero index"):
        ChaosExpansion(np.zeros(2), [[1], [2]], dists)
    with pytest.raises(ValueError, match="distinct"):
        ChaosExpansion(np.zeros(3), [[0], [1], [1]], dists)
