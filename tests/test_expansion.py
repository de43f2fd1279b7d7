"""ChaosExpansion statistics against closed forms (Ishigami) and an independent oracle."""

import statistics

import numpy as np
import pytest

from pcmb.chaos.basis import total_index_set
from pcmb.chaos.expansion import ChaosExpansion, sample_mean, sample_std
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


@pytest.mark.slow
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


# -- statistics at the edges of the floating-point range -------------------------------------

EDGE_TIMES = np.linspace(0.0, 2.0, 5)
EDGE_DISTS = [Uniform(1.0, 3.0), Normal(0.0, 1.0)]


def _edge_expansion(magnitude: float) -> ChaosExpansion:
    """y = B (1 + 0.1 a t + 0.05 b² t²), a ~ U[1, 3], b ~ N(0, 1): exact at orders (1, 2)."""
    grid = TensorGrid(EDGE_DISTS, [1, 2])
    a, b = grid.params[:, :1], grid.params[:, 1:]
    y = magnitude * (1.0 + 0.1 * a * EDGE_TIMES + 0.05 * b**2 * EDGE_TIMES**2)
    return ChaosExpansion(project_tensor(grid, y), grid.multi_index, EDGE_DISTS)


def _edge_exact(magnitude: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact std and first-order Sobol' indices (n, T) of :func:`_edge_expansion`."""
    part_a = (0.1 * EDGE_TIMES) ** 2 / 3.0  # Var(0.1 a t) / B²
    part_b = 2.0 * (0.05 * EDGE_TIMES**2) ** 2  # Var(0.05 b² t²) / B²
    with np.errstate(invalid="ignore"):
        sobol = np.array([part_a, part_b]) / (part_a + part_b)
    return magnitude * np.sqrt(part_a + part_b), sobol


@pytest.mark.parametrize("magnitude", [1e200, -1e200, 1e300, 1e-200, 1.0])
def test_statistics_of_huge_and_tiny_outputs_are_finite_and_exact(magnitude):
    expansion = _edge_expansion(magnitude)
    std, sobol = _edge_exact(abs(magnitude))
    found = expansion.std()
    assert np.isfinite(found).all()
    np.testing.assert_allclose(found[1:], std[1:], rtol=1e-12, atol=0.0)
    assert found[0] == 0.0  # y = B at t = 0 at every node: it does not vary
    first, total = expansion.sobol_first(), expansion.sobol_total()
    assert np.isfinite(first[:, 1:]).all() and np.isnan(first[:, 0]).all()
    np.testing.assert_allclose(first[:, 1:], sobol[:, 1:], rtol=1e-12)
    np.testing.assert_allclose(total[:, 1:], sobol[:, 1:], rtol=1e-12)  # no interaction
    assert expansion.varies().tolist() == [False, True, True, True, True]
    if abs(magnitude) > 1e160:  # the variance itself is beyond the largest float
        assert np.isinf(expansion.variance()[1:]).all()


def test_ordinary_outputs_keep_the_plain_arithmetic_bit_for_bit():
    # The scaling is for magnitudes beyond 1e±150 only: every other expansion gets exactly
    # the numbers of the plain formulas (so results files stay byte-identical).
    expansion = _edge_expansion(3.7)
    fluctuations = expansion.coefficients.copy()
    fluctuations[0] = 0.0
    squares = fluctuations**2
    variance = squares.sum(axis=0)
    np.testing.assert_array_equal(expansion.std()[1:], np.sqrt(variance)[1:])
    np.testing.assert_array_equal(expansion.variance()[1:], variance[1:])
    active = expansion.multi_index > 0
    only = active & (active.sum(axis=1) == 1)[:, None]
    np.testing.assert_array_equal(
        expansion.sobol_first()[:, 1:], (only.T.astype(float) @ squares / variance)[:, 1:]
    )
    np.testing.assert_array_equal(
        expansion.sobol_total()[:, 1:], (active.T.astype(float) @ squares / variance)[:, 1:]
    )


@pytest.mark.parametrize("value", [5.0, -0.3, 1e200, 0.0])
def test_a_constant_output_has_std_exactly_zero_and_no_sobol_indices(value):
    grid = TensorGrid(EDGE_DISTS, [3, 3])
    values = np.full((grid.size, 4), value)
    expansion = ChaosExpansion(project_tensor(grid, values), grid.multi_index, EDGE_DISTS)
    # The projection of a constant leaves round-off in the other terms; it is not variance.
    assert np.all(expansion.std() == 0.0) and np.all(expansion.variance() == 0.0)
    assert np.isnan(expansion.sobol_first()).all() and np.isnan(expansion.sobol_total()).all()
    assert not expansion.varies().any()
    np.testing.assert_allclose(expansion.mean(), value, rtol=1e-14)


def test_non_finite_coefficients_give_non_finite_statistics_not_zero():
    expansion = _edge_expansion(1.0)
    coefficients = expansion.coefficients.copy()
    coefficients[1, 2] = np.nan
    coefficients[0, 3] = np.inf
    broken = ChaosExpansion(coefficients, expansion.multi_index, EDGE_DISTS)
    std = broken.std()
    assert (
        np.isnan(std[2]) and not broken.varies()[2] and np.isnan(broken.sobol_first()[:, 2]).all()
    )
    assert np.isfinite(std[[1, 4]]).all()


@pytest.mark.parametrize("magnitude", [1e200, 1e300, 1e-200, 1.0])
def test_sample_statistics_are_finite_and_exact(magnitude):
    rng = np.random.default_rng(5)
    values = magnitude * (1.0 + 0.01 * rng.standard_normal((64, 3)))
    std, mean = sample_std(values), sample_mean(values)
    exact_std = [statistics.stdev(column) for column in values.T.tolist()]
    exact_mean = [statistics.fmean(column) for column in values.T.tolist()]
    np.testing.assert_allclose(std, exact_std, rtol=1e-12)
    np.testing.assert_allclose(mean, exact_mean, rtol=1e-14)
    if magnitude == 1.0:  # the plain arithmetic, bit for bit
        np.testing.assert_array_equal(std, values.std(axis=0, ddof=1))
        np.testing.assert_array_equal(mean, values.mean(axis=0))


def test_sample_statistics_of_constant_and_overflowing_sums():
    constant = np.full((7, 2), 0.1)  # numpy's mean of seven 0.1 is not 0.1 exactly
    assert np.all(sample_std(constant) == 0.0)
    near_the_top = np.array([[1.7e308], [1.5e308], [1.6e308]])  # the sum overflows
    np.testing.assert_allclose(sample_mean(near_the_top), [1.6e308], rtol=1e-15)
    np.testing.assert_allclose(sample_std(near_the_top), [1e307], rtol=1e-12)
