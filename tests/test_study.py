"""The study pipeline from Python: statistics against closed forms, failure policies."""

import numpy as np
import pytest

import pcmb
from pcmb.errors import ConfigError, ModelRunError

TIMES = np.linspace(0.0, 2.0, 5)
INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}


def pointwise(params, times):
    """y = a t + b²: E y = 2t + 1, Var y = t²/3 + 2."""
    return {"y": params["a"] * times + params["b"] ** 2}


pointwise.outputs = ("y",)


def failing(params, times):
    if params["a"] > 2.5 and params["b"] > 0.5:
        raise RuntimeError("diverged")
    return pointwise(params, times)


failing.outputs = ("y",)


def _exact_mean_var(t):
    return 2 * t + 1, t**2 / 3 + 2


@pytest.mark.parametrize("basis", ["tensor", "total"])
def test_collocation_matches_closed_form(basis):
    study = pcmb.Study(
        pointwise, INPUTS, TIMES, order=2, basis=basis, params={"a": 2.0, "b": 0.0}, jobs=1
    )
    result = study.run()
    mean, var = _exact_mean_var(TIMES)
    np.testing.assert_allclose(result.mean("y"), mean, atol=1e-12)
    np.testing.assert_allclose(result.std("y") ** 2, var, atol=1e-12)
    # No interaction between a and b: first == total, and they sum to one (t > 0).
    first = result.sobol_first("y")
    np.testing.assert_allclose(first, result.sobol_total("y"), atol=1e-12)
    np.testing.assert_allclose(first[:, 1:].sum(axis=0), 1.0, atol=1e-12)
    expected_terms = 9 if basis == "tensor" else 6
    assert result.multi_index.shape == (expected_terms, 2)
    assert np.all(result.status == 1) and result.weights.sum() == pytest.approx(1.0)


def test_anisotropic_orders():
    study = pcmb.Study(pointwise, INPUTS, TIMES, order={"a": 1, "b": 2}, params={"a": 2, "b": 0})
    assert study.node_set().size == 6
    result = study.run()
    np.testing.assert_allclose(result.std("y") ** 2, _exact_mean_var(TIMES)[1], atol=1e-12)


def test_abort_names_every_failed_node():
    study = pcmb.Study(failing, INPUTS, TIMES, order=3, params={"a": 2.0, "b": 0.0}, jobs=1)
    with pytest.raises(ModelRunError) as error:
        study.run()
    grid = study.node_set()
    bad = np.flatnonzero((grid.params[:, 0] > 2.5) & (grid.params[:, 1] > 0.5))
    assert sorted(f.index for f in error.value.failures) == bad.tolist()
    assert "diverged" in str(error.value) and f"node {bad[0]} (a=" in str(error.value)


def test_regress_refits_on_survivors_and_says_so():
    study = pcmb.Study(
        failing, INPUTS, TIMES, order=3, params={"a": 2, "b": 0}, jobs=1, on_failure="regress"
    )
    result = study.run()
    grid = study.node_set()
    bad = (grid.params[:, 0] > 2.5) & (grid.params[:, 1] > 0.5)
    assert bad.sum() == 2
    np.testing.assert_array_equal(result.status, np.where(bad, 2, 1))
    assert len(result.failures) == 2
    assert any("failed and were left out" in w for w in result.warnings)
    assert any("least-squares" in w for w in result.warnings)
    # y is a degree-2 polynomial: the least-squares refit on 14 survivors is still exact.
    mean, var = _exact_mean_var(TIMES)
    np.testing.assert_allclose(result.mean("y"), mean, atol=1e-10)
    np.testing.assert_allclose(result.std("y") ** 2, var, atol=1e-10)


@pytest.mark.parametrize("method", ["montecarlo", "lhs", "sobol"])
def test_sampling_methods_share_the_pipeline(method):
    study = pcmb.Study(
        pointwise, INPUTS, TIMES, method=method, samples=1024, params={"a": 2, "b": 0}, jobs=1
    )
    result = study.run()
    assert result.weights is None and result.expansions == {}
    mean, var = _exact_mean_var(TIMES)
    # 1024 samples: standard error of the mean sqrt(var/1024) <= 0.06; allow 5 of them.
    assert np.all(np.abs(result.mean("y") - mean) < 5 * np.sqrt(var / 1024))


def test_sampling_with_regression_fit():
    study = pcmb.Study(
        pointwise,
        INPUTS,
        TIMES,
        method="lhs",
        samples=64,
        fit="regression",
        order=2,
        params={"a": 2, "b": 0},
        jobs=1,
    )
    result = study.run()
    np.testing.assert_allclose(result.std("y") ** 2, _exact_mean_var(TIMES)[1], atol=1e-10)


def test_bad_study_settings_are_config_errors():
    with pytest.raises(ConfigError, match="at least one input"):
        pcmb.Study(pointwise, {}, TIMES)
    with pytest.raises(ConfigError, match="increasing"):
        pcmb.Study(pointwise, INPUTS, [0.0, 0.0])
    with pytest.raises(ConfigError, match="samples"):
        pcmb.Study(pointwise, INPUTS, TIMES, method="montecarlo")
    with pytest.raises(ConfigError, match="no order given"):
        pcmb.Study(pointwise, INPUTS, TIMES, order={"a": 2}).node_set()
