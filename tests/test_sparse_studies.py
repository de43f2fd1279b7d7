"""Smolyak and sparse-regression studies end to end, from YAML (``pcmb run``) and from Python,
against closed forms (Ishigami) and the tensor grid of order 9 of the same model."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from cli_process import pcmb_here
from model_loading import CONFIGS_DIR
from test_resume import (
    PYTHON_CONFIG,
    PYTHON_MODEL,
    assert_same_runs,
    resume_and_rerun,
    run_and_kill,
)

import pcmb
from pcmb.config.schema import load_config
from pcmb.designs.regression import loo_statistics_error
from pcmb.errors import ConfigError, UsageError
from pcmb.references import ishigami, ishigami_moments
from pcmb.result import Design
from pcmb.store import load
from pcmb.study import Study

ISHIGAMI = {name: pcmb.Uniform(-np.pi, np.pi) for name in ("x1", "x2", "x3")}
TIMES = np.array([0.0, 1.0])
#: A regression in rounds of the two-input model of test_resume (16 runs first, 256 at most).
ROUNDS_METHOD = (
    "{kind: regression, samples: 16, order: 6, basis: total, tolerance: 1e-4, max_samples: 256}"
)


@pcmb.batched(outputs=("y",))
def ishigami_model(params, times):
    """The Ishigami function, the same at every time."""
    x = np.stack([params[name] for name in ISHIGAMI], axis=1)
    return {"y": np.repeat(ishigami(x)[:, None], times.size, axis=1)}


def ishigami_study(**method) -> Study:
    return Study(ishigami_model, ISHIGAMI, TIMES, backend="inprocess", **method)


@pytest.mark.filterwarnings("ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning")
@pytest.mark.filterwarnings("ignore:.*chaos-undecided:pcmb.errors.PcmbWarning")  # low levels
def test_smolyak_study_of_ishigami_converges_to_the_closed_form():
    exact = ishigami_moments()
    errors = []
    for level in (3, 4):
        result = ishigami_study(grid="smolyak", level=level).run()
        assert result.design.label == f"Smolyak level {level}, rule gauss-patterson"
        assert result.n_nodes == {3: 111, 4: 351}[level]
        # The mean is a sum of 1-D integrals of odd or separable terms, exact on the
        # symmetric nested rule; the variance converges spectrally (analytic integrand).
        np.testing.assert_allclose(result.mean("y"), exact.mean, atol=1e-12)
        errors.append(abs(result.std("y")[0] ** 2 / exact.variance - 1))
        total = result.sobol_total("y")[:, 0]
        if level == 4:
            np.testing.assert_allclose(total, exact.total, atol=1e-3)
    assert errors[1] < 1e-3 < errors[0] / 10  # 111 -> 351 runs: at least 100x more accurate


def test_lars_study_adds_rounds_until_the_estimated_error_meets_the_tolerance():
    tolerance = 1e-5
    study = ishigami_study(
        method="regression", samples=32, order=12, tolerance=tolerance, max_samples=2048
    )
    assert study.design.record().samples == 32  # the first round, before any run
    result = study.run()
    assert result.n_nodes > 32 and result.design.samples == result.n_nodes
    assert not [w for w in result.warnings if w.code.startswith("regression-")]
    # Sobol' points in rounds: the first N points of the one sequence.
    whole = pcmb.chaos.nodes.random_nodes(tuple(ISHIGAMI.values()), result.n_nodes, "sobol", 0)
    np.testing.assert_array_equal(result.germ, whole.nodes)
    # The tolerance is on the error of the mean and std relative to the std, which the
    # corrected LOO error ε gives as √ε σ (1/√N + √ε / 2): within 10x of the truth.
    fits = {"y": result.regression["y"]}
    exact = ishigami_moments()
    sigma = np.sqrt(exact.variance)
    error = max(abs(result.mean("y")[0] - exact.mean), abs(result.std("y")[0] - sigma)) / sigma
    relative = np.sqrt(np.max(fits["y"].loo))
    estimate = relative * (1 / np.sqrt(result.n_nodes) + relative / 2)
    assert estimate <= tolerance and error <= 10 * tolerance
    assert error / 10 <= estimate <= 10 * error


def test_a_budget_that_ends_before_the_tolerance_is_reported():
    study = ishigami_study(
        method="regression", samples=32, order=6, tolerance=1e-12, max_samples=100
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", pcmb.PcmbWarning)
        result = study.run()
    assert result.n_nodes == 100 == result.design.samples
    codes = {w.code for w in result.warnings}
    assert {"regression-budget", "regression-loo"} <= codes
    assert any("after 100 of 100 runs (method.max_samples)" in str(w.message) for w in caught)


def test_design_records_of_older_files_load_without_the_new_fields():
    old = (
        '{"kind": "collocation", "grid": "tensor-gauss", "basis": "tensor", "orders": [5, 5], '
        '"level": null, "elements": 1, "samples": null, "seed": null, "fit": "projection"}'
    )
    record = Design.from_description(old)
    assert (record.rule, record.q, record.tolerance, record.max_samples) == (None,) * 4
    assert record.label == "collocation"  # the label its design gave it came later


@pytest.mark.parametrize(
    ("method", "key", "message"),
    [
        ({"grid": "smolyak", "level": -1}, "level", "expected a value >= 0"),
        ({"method": "regression", "samples": 8, "tolerance": 0.0}, "tolerance", "a value > 0"),
        (
            {"method": "regression", "samples": 64, "tolerance": 1e-3, "max_samples": 64},
            "max_samples",
            "leaves none for a round after the first 64",
        ),
        ({"method": "regression", "samples": 64, "max_samples": 128}, "max_samples", "only"),
        (
            {"method": "regression", "samples": 64, "selection": "none", "basis": "total"},
            "samples",
            "needs at least 456 samples",
        ),
    ],
)
def test_unusable_python_settings_name_their_argument(method, key, message):
    with pytest.raises(UsageError, match=rf"{key}: .*{message}"):
        ishigami_study(order=12, **method)


def _write_config(tmp_path, method: str):
    text = PYTHON_CONFIG.replace("method: {kind: collocation, order: 3}", f"method: {method}")
    (tmp_path / "model.py").write_text(PYTHON_MODEL)
    (tmp_path / "study.yaml").write_text(text)
    return tmp_path / "study.yaml"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("method", "key"),
    [
        ("{kind: collocation, grid: smolyak, level: -1}", "method.level"),
        ("{kind: regression, samples: 64, order: 4, tolerance: 0}", "method.tolerance"),
        (
            "{kind: regression, samples: 64, order: 4, tolerance: 0.01, max_samples: 32}",
            "method.max_samples",
        ),
        (
            "{kind: regression, samples: 8, order: 4, selection: none, basis: total}",
            "method.samples",
        ),
        ("{kind: collocation, grid: smolyak, level: 2, order: 3}", "method.order"),
    ],
)
def test_unusable_config_settings_are_located_at_their_key_exit_2(tmp_path, method, key):
    path = _write_config(tmp_path, method)
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert [problem.path for problem in caught.value.problems] == [key]
    found = pcmb_here("validate", str(path))
    assert found.returncode == 2 and f"{key}:" in found.stderr, found.stderr


@pytest.mark.slow
def test_validate_prints_the_first_round_and_the_budget(tmp_path):
    path = _write_config(tmp_path, ROUNDS_METHOD)
    shown = pcmb_here("validate", str(path))
    assert shown.returncode == 0, shown.stderr
    assert "LARS on total order 6, 16 samples (to 0.0001, at most 256)" in shown.stdout
    assert "16 model runs in the first round, at most 256 in all" in shown.stdout


# --------------------------------------------------------------------------- the quarter car


def _quarter_car(stem: str) -> Study:
    return Study.from_config(load_config(CONFIGS_DIR / f"{stem}.yaml")).replace(analysis=None)


@pytest.fixture(scope="module")
def reference():
    """The tensor grid of order 9 (1000 runs) of configs/quarter_car.yaml."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        return _quarter_car("quarter_car").replace(order=9).run()


def _run_config(stem: str, folder) -> pcmb.StudyResult:
    """``pcmb run configs/<stem>.yaml`` into ``folder``, then ``pcmb inspect``; the result."""
    output = folder / f"{stem}.h5"
    ran = pcmb_here("run", str(CONFIGS_DIR / f"{stem}.yaml"), "-o", str(output), "--quiet")
    assert ran.returncode == 0, ran.stderr
    shown = pcmb_here("inspect", str(output))
    assert shown.returncode == 0, shown.stderr
    result = load(output)
    assert result.design.label in shown.stdout
    for name, fit in result.regression.items():
        assert f"fit      {name}: {fit.selected.shape[0]} terms selected" in shown.stdout
    return result


def _same_values(result: pcmb.StudyResult, again: pcmb.StudyResult) -> None:
    """The YAML and the Python route make the same nodes and runs, and the same statistics to
    round-off (a fit's last bits depend on how the BLAS of each process splits its sums)."""
    np.testing.assert_array_equal(result.germ, again.germ)
    for name in result.outputs:
        np.testing.assert_array_equal(result.values[name], again.values[name])
        scale = result.std(name).max()
        np.testing.assert_allclose(result.mean(name), again.mean(name), rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(result.std(name), again.std(name), rtol=0, atol=1e-12 * scale)


@pytest.mark.slow
def test_smolyak_config_from_yaml_and_python_agrees_with_the_tensor_grid(tmp_path, reference):
    result = _run_config("quarter_car_smolyak", tmp_path)
    assert result.design.label == "Smolyak level 3, rule gauss-patterson"
    assert result.n_nodes == 111 and result.weights.min() < 0  # a signed combination
    _same_values(result, _quarter_car("quarter_car_smolyak").run())
    # Level 3 is exact for polynomials of total degree 2·3+1 on Gauss–Patterson levels: about
    # as accurate as the tensor grid of order 5 (216 runs), whose error is below 1 % of the
    # largest std; the order-3 tensor grid's is 3 %.
    for name in result.outputs:
        scale = reference.std(name).max()
        assert np.abs(result.mean(name) - reference.mean(name)).max() < 1e-2 * scale
        assert np.abs(result.std(name) - reference.std(name)).max() < 1e-2 * scale


@pytest.mark.slow
def test_lars_config_from_yaml_and_python_agrees_with_the_tensor_grid(tmp_path, reference):
    result = _run_config("quarter_car_lars", tmp_path)
    method = load_config(CONFIGS_DIR / "quarter_car_lars.yaml").method
    assert method.samples < result.n_nodes <= method.max_samples
    assert result.design.samples == result.n_nodes
    assert result.design.label.startswith("LARS on hyperbolic order 12, q=0.75, ")
    _same_values(result, _quarter_car("quarter_car_lars").run())
    for name, fit in result.regression.items():
        # Met before the budget ended: the error of the mean and std estimated from the LOO.
        estimate = loo_statistics_error(fit.loo, result.std(name), result.n_nodes)
        assert estimate <= method.tolerance
        # Every time: |Δμ|, |Δσ| <= σ √ε (ε the LOO estimate of ‖f - f̂‖²/Var f), with a
        # factor 3 for the estimate and 1e-3 σ_max for the reference's own error.
        sigma = reference.std(name)
        bound = 3 * sigma * np.sqrt(np.nan_to_num(fit.loo)) + 1e-3 * sigma.max()
        assert np.all(np.abs(result.mean(name) - reference.mean(name)) <= bound)
        assert np.all(np.abs(result.std(name) - reference.std(name)) <= bound)
        kept = result.expansions[name].multi_index
        assert {tuple(row) for row in fit.selected} <= {tuple(row) for row in kept}


# --------------------------------------------------------------------------- resuming rounds


@pytest.mark.slow
def test_a_run_killed_between_and_inside_rounds_resumes_to_the_same_result(tmp_path):
    """Rounds 0 and 1 journaled in out.h5.journal and out.h5.journal/round-1: killed after
    round 0 and again inside round 1, the resumed run writes what an uninterrupted one does."""
    path = _write_config(tmp_path, ROUNDS_METHOD)
    # y = 1/(1 + a t + b²): analytic, not polynomial, so 16 runs miss the tolerance.
    path.parent.joinpath("model.py").write_text(
        PYTHON_MODEL.replace(
            '{"y": params["a"] * times + params["b"] ** 2}',
            '{"y": 1.0 / (1.0 + params["a"] * times + params["b"] ** 2)}',
        )
    )
    run_and_kill(
        tmp_path, after=16, nominal_first=True
    )  # round 0 journaled, killed at round 1's first node
    journal = tmp_path / "out.h5.journal"
    assert len(list(journal.glob("record-*.npz"))) == 16
    run_and_kill(tmp_path, "--resume", after=3, nominal_first=True)  # 3 nodes of round 1 journaled
    assert len(list((journal / "round-1").glob("record-*.npz"))) == 3
    first, second = resume_and_rerun(tmp_path)
    assert first.n_nodes == second.n_nodes > 32 and first.design == second.design
    assert_same_runs(tmp_path, first, second)
    for name in first.outputs:
        np.testing.assert_array_equal(first.regression[name].loo, second.regression[name].loo)


@pcmb.pointwise(outputs=("y",))
def _ramp(params, times):
    return {"y": params["a"] * times + params["b"] ** 2}


@pytest.mark.slow
def test_the_fits_of_outputs_on_other_axes_join_one_report(tmp_path):
    # y on time and its peak, a scalar, are recovered apart; the report holds both fits.
    inputs = {"a": pcmb.Uniform(1.0, 2.0), "b": pcmb.Uniform(-1.0, 1.0)}
    method = {"kind": "regression", "samples": 32, "order": 3}
    derived = {"peak": {"max_abs": "y"}}
    study = Study(_ramp, inputs, np.linspace(0, 1, 5), method=method, derived=derived)
    result = study.run(tmp_path / "r.h5", progress=False)
    assert list(result.regression) == ["y", "peak"]
    assert result.regression["y"].loo.shape == (5,) and result.regression["peak"].loo.shape == (1,)
    back = load(tmp_path / "r.h5").regression
    for name, fit in result.regression.items():
        np.testing.assert_array_equal(back[name].loo, fit.loo)
        np.testing.assert_array_equal(back[name].selected, fit.selected)
