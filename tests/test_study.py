"""The study pipeline from Python: statistics against closed forms, failure policies."""

import dataclasses
from typing import ClassVar

import numpy as np
import pytest

import pcmb
from pcmb.errors import ModelRunError, UsageError

TIMES = np.linspace(0.0, 2.0, 5)
INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}


@pcmb.pointwise(outputs=("y",))
def pointwise(params, times):
    """y = a t + b²: E y = 2t + 1, Var y = t²/3 + 2."""
    return {"y": params["a"] * times + params["b"] ** 2}


@pcmb.pointwise(outputs=("y",))
def failing(params, times):
    if params["a"] > 2.5 and params["b"] > 0.5:
        raise RuntimeError("diverged")
    return pointwise(params, times)


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
    # Chunks of one node, jobs 1: abort stops dispatching at the first failed chunk and names
    # its node, and the one chunk queued behind it; the nodes after those are not run.
    found = [f.index for f in error.value.failures]
    assert found[0] == bad[0] and set(found) <= set(bad.tolist())
    assert "diverged" in str(error.value) and f"node {bad[0]} (a=" in str(error.value)
    not_run = grid.size - bad[0] - 2
    assert (f"{not_run} node(s) not run" in str(error.value)) == (not_run > 0)


def test_regress_refits_on_survivors_and_says_so():
    study = pcmb.Study(
        failing, INPUTS, TIMES, order=3, params={"a": 2, "b": 0}, jobs=1, on_failure="regress"
    )
    with pytest.warns(pcmb.PcmbWarning):
        result = study.run()
    grid = study.node_set()
    bad = (grid.params[:, 0] > 2.5) & (grid.params[:, 1] > 0.5)
    assert bad.sum() == 2
    np.testing.assert_array_equal(result.status, np.where(bad, 2, 1))
    assert len(result.failures) == 2
    assert any(w.code == "nodes-failed" for w in result.warnings)
    assert any(w.code == "least-squares-fit" for w in result.warnings)
    # y is a degree-2 polynomial: the least-squares refit on 14 survivors is still exact.
    mean, var = _exact_mean_var(TIMES)
    np.testing.assert_allclose(result.mean("y"), mean, atol=1e-10)
    np.testing.assert_allclose(result.std("y") ** 2, var, atol=1e-10)


@pytest.mark.parametrize(
    "grid",
    [
        {"order": 3},
        {"grid": "smolyak", "level": 2},
        {"order": "auto", "max_runs": 9},
        {"kind": "adaptive", "tolerance": 1e-3, "max_runs": 30},
    ],
)
def test_the_file_records_the_least_squares_fit_of_a_grid_with_failed_nodes(tmp_path, grid):
    study = pcmb.Study(
        failing,
        INPUTS,
        TIMES,
        method={"kind": "collocation", **grid, "validation": 0},
        execution={"backend": "inprocess", "on_failure": "regress"},
    )
    with pytest.warns(pcmb.PcmbWarning):
        result = study.run(tmp_path / "out.h5")
    assert result.design.fit == "regression"
    assert pcmb.load(tmp_path / "out.h5").design.fit == "regression"


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
    with pytest.warns(pcmb.PcmbWarning):
        result = study.run()
    np.testing.assert_allclose(result.std("y") ** 2, _exact_mean_var(TIMES)[1], atol=1e-10)


def test_bad_study_settings_are_config_errors():
    with pytest.raises(UsageError, match="at least one input"):
        pcmb.Study(pointwise, {}, TIMES)
    with pytest.raises(UsageError, match="increasing"):
        pcmb.Study(pointwise, INPUTS, [0.0, 0.0])
    with pytest.raises(UsageError, match="samples"):
        pcmb.Study(pointwise, INPUTS, TIMES, method="montecarlo")
    with pytest.raises(UsageError, match="no order given"):
        pcmb.Study(pointwise, INPUTS, TIMES, order={"a": 2}).node_set()


def test_regress_respects_anisotropic_orders():
    """On a grid with q_b = 2 the refit must not ask for b² (it would be aliased)."""

    @pcmb.pointwise(outputs=("y",))
    def model(params, times):
        if params["a"] > 2.8:
            raise RuntimeError("diverged")
        return {"y": params["a"] ** 2 + params["b"] + 0 * times}

    # 5 x 2 nodes, 2 fail: 8 survivors carry the 5 terms of degree <= 2 with b-degree <= 1.
    study = pcmb.Study(model, INPUTS, TIMES, order={"a": 4, "b": 1}, on_failure="regress")
    with pytest.warns(pcmb.PcmbWarning):
        result = study.run()
    assert np.sum(result.status == 2) == 2
    assert result.multi_index[:, 1].max() <= 1
    # y = a² + b is in the span of degree-2-in-a, degree-1-in-b terms: exact refit.
    # E[a²] = Var a + 4 = 13/3; Var y = Var a² + Var b with Var a² = E[a⁴] - E[a²]² = 121/5 - 169/9.
    np.testing.assert_allclose(result.mean("y"), 13 / 3, atol=1e-10)
    np.testing.assert_allclose(result.std("y") ** 2, 121 / 5 - 169 / 9 + 1, atol=1e-10)


def test_regress_with_nothing_left_to_fit_is_a_model_failure():
    @pcmb.pointwise(outputs=("y",))
    def model(params, times):
        raise RuntimeError("always")

    study = pcmb.Study(model, INPUTS, TIMES, order=2, on_failure="regress")
    with pytest.raises(ModelRunError, match="could not refit"):
        study.run()


def test_a_function_needs_no_nominal_values():
    @pcmb.pointwise(outputs=("y",))
    def model(params, times):
        return {"y": params["a"] * times}

    result = pcmb.Study(model, INPUTS, TIMES, order=1).run()
    np.testing.assert_allclose(result.mean("y"), 2 * TIMES, atol=1e-12)
    assert result.nominal_params == {"a": 2.0, "b": 0.0}


def test_an_input_naming_no_model_parameter_is_rejected_before_running(tmp_path):
    class Model:
        outputs = ("y",)
        parameters: ClassVar[dict[str, float]] = {"a": 1.0}

        def __init__(self, **params):
            self.ran = False

        def simulate(self, params, times):
            raise AssertionError("must not run")

    with pytest.raises(UsageError, match=r"input\(s\) \['b'\] name no parameter"):
        pcmb.Study(Model, INPUTS, TIMES, order=1).run(tmp_path / "x.h5")
    assert list(tmp_path.iterdir()) == []


def test_execution_settings_are_checked_where_declared_before_anything_is_written(tmp_path):
    with pytest.raises(UsageError, match=r"execution\.address: an address is only used with"):
        pcmb.Study(pointwise, INPUTS, TIMES, params={"a": 2, "b": 0}, address="tcp://x:1")
    assert list(tmp_path.iterdir()) == []


def test_misspelled_settings_are_rejected_at_their_keys():
    cases = [
        (
            {"method": {"kind": "collocation", "order": 2, "basis": "totl"}},
            "method.basis: expected",
        ),
        ({"execution": {"on_failure": "regres"}}, "execution.on_failure: expected"),
        ({"method": {"kind": "montecarl"}}, "method.kind: expected one of"),
        (
            {"method": {"kind": "collocation", "order": 2, "fit": "regression"}},
            r"method.fit: not a setting of kind collocation \(it belongs to montecarlo, lhs, sobol",
        ),
        ({"method": {"kind": "montecarlo", "samples": 1}}, "at least 2 samples"),
        ({"diagnostics": {"tolerance": 2.0}}, "diagnostics.tolerance: expected a value < 1"),
    ]
    for settings, message in cases:
        with pytest.raises(UsageError, match=message):
            pcmb.Study(pointwise, INPUTS, TIMES, **settings)


def test_the_keywords_of_pcmb_0x_still_work_with_a_deprecation_warning():
    new = pcmb.Study(
        pointwise,
        INPUTS,
        TIMES,
        method={"kind": "lhs", "samples": 16, "seed": 3, "fit": "regression", "order": 3},
        execution={"jobs": 1, "backend": "inprocess"},
        diagnostics={"tolerance": 0.1},
    )
    with pytest.warns(DeprecationWarning, match="keyword arguments of pcmb 0.x"):
        old = pcmb.Study(
            pointwise,
            INPUTS,
            TIMES,
            method="lhs",
            samples=16,
            seed=3,
            fit="regression",
            jobs=1,
            backend="inprocess",
            diagnostics_tolerance=0.1,
        )
    assert (old.method, old.execution, old.diagnostics) == (
        new.method,
        new.execution,
        new.diagnostics,
    )
    twin = new.replace(method={"kind": "montecarlo", "samples": 8})
    assert (twin.method.kind, twin.method.samples, twin.execution) == (
        "montecarlo",
        8,
        new.execution,
    )
    with pytest.warns(DeprecationWarning):
        again = new.replace(jobs=2, method="sobol")  # keeps the keys sobol takes
    assert (again.execution.jobs, again.method.kind, again.method.seed) == (2, "sobol", 3)


@pytest.mark.filterwarnings(
    "ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning"
)  # b held fixed
def test_order_zero_is_reported():
    study = pcmb.Study(pointwise, INPUTS, TIMES, order={"a": 2, "b": 0}, params={"a": 2, "b": 0})
    with pytest.warns(pcmb.PcmbWarning, match=r"\['b'\] have order 0"):
        result = study.run()
    assert any(w.code == "order-zero" and "order 0" in w.message for w in result.warnings)


@pytest.mark.slow
@pytest.mark.filterwarnings(
    "ignore:.*(polynomial chaos unreliable|cannot tell whether):pcmb.errors.PcmbWarning"
)  # order 2
def test_coefficients_are_bit_identical_for_one_or_two_workers():
    """The default quarter car (stacked solves, whose last bits depend on the batch) at order 2."""
    from pathlib import Path

    from pcmb.config.schema import load_config

    config = load_config(Path(__file__).resolve().parents[1] / "configs" / "quarter_car.yaml")
    study = pcmb.Study.from_config(config).replace(order=2, chunk_size=7, analysis=None)
    serial = study.replace(jobs=1).run()
    pooled = study.replace(jobs=2).run()
    for name in serial.outputs:
        np.testing.assert_array_equal(
            serial.expansions[name].coefficients, pooled.expansions[name].coefficients
        )


def test_api_errors_name_the_argument_not_a_config():
    with pytest.raises(UsageError) as caught:
        pcmb.Study(pointwise, INPUTS, TIMES, method={"kind": "montecarlo", "samples": 1})
    assert str(caught.value) == "Study: method.samples: montecarlo needs at least 2 samples, got 1"
    assert "<config>" not in str(caught.value)


def test_sobol_without_a_power_of_two_is_a_recorded_warning_not_scipys():
    study = pcmb.Study(pointwise, INPUTS, TIMES, method="sobol", samples=50, params={"a": 2})
    with pytest.warns(pcmb.PcmbWarning) as caught:
        result = study.run()
    assert [w.code for w in result.warnings] == ["sobol-balance"]
    assert all(issubclass(w.category, pcmb.PcmbWarning) for w in caught)


def test_the_result_names_node_values_and_its_design():
    result = pcmb.Study(pointwise, INPUTS, TIMES, order=2, params={"a": 2, "b": 0}).run()
    assert result.design == pcmb.Design(
        "collocation", "tensor-gauss", "tensor", (2, 2), fit="projection", label="chaos order 2"
    )
    np.testing.assert_array_equal(result.node_params["b"], result.params[:, 1])
    np.testing.assert_allclose(result.node_params["a"], 2.0 + result.germ[:, 0])
    with pytest.raises(ValueError, match="needs a chaos expansion"):
        pcmb.Study(pointwise, INPUTS, TIMES, method="lhs", samples=8).run().sobol_first("y")


def test_a_function_returning_a_scalar_fails_once_with_one_message(tmp_path):
    @pcmb.pointwise(outputs=("y",))
    def scalar(params, times):
        return {"y": params["a"] * params["b"]}

    inputs = {**INPUTS, "c": pcmb.Uniform(0.0, 1.0)}
    study = pcmb.Study(scalar, inputs, TIMES, order=2, params={"a": 2, "b": 0, "c": 0.5}, jobs=1)
    with pytest.raises(pcmb.ModelDefinitionError) as caught:
        study.run(tmp_path / "out.h5")
    message = str(caught.value)
    assert "\n" not in message and message.count("returned a float for output 'y'") == 1
    assert list(tmp_path.iterdir()) == []  # no result, no journal


class LoggedLine:
    """y = a t, appending each run's ``a`` to the file ``log``."""

    outputs = ("y",)

    def __init__(self, a: float = 2.0, log: str = "") -> None:
        self.parameters = {"a": a}
        self.log = log

    def simulate(self, params, times):
        a = np.asarray(params["a"], dtype=float)
        with open(self.log, "a") as file:
            file.write("".join(f"{float(x)!r}\n" for x in a))
        return {"y": a[:, None] * times}


def test_the_nominal_run_can_be_left_out(tmp_path):
    runs = {}
    for nominal_run in (True, False):
        log = tmp_path / f"runs-{nominal_run}.log"
        study = pcmb.Study(
            LoggedLine,
            {"a": pcmb.Uniform(1.0, 3.0)},
            TIMES,
            order=3,
            params={"a": 2.0, "log": str(log)},
            validation=0,
            nominal_run=nominal_run,
        )
        result = study.run()
        runs[nominal_run] = log.read_text().split()
        assert (result.nominal != {}) == nominal_run
    # The nodes and a = 2 (no node: 4 Gauss points), which runs beside the nodes.
    assert len(runs[True]) == 4 + 1 and runs[True].count("2.0") == 1
    assert len(runs[False]) == 4 and "2.0" not in runs[False]


def test_a_result_prints_as_a_summary_not_its_arrays():
    result = pcmb.Study(pointwise, INPUTS, TIMES, order=2, params={"a": 2.0, "b": 0.0}).run()
    text = repr(result)
    assert text == str(result) and len(text) < 600
    assert text.splitlines()[:-1] == [
        "StudyResult 'study': chaos order 2",
        f"  runs: 9 design (9 ok), {len(result.held_out.ok)} held-out, 1 nominal; "
        f"{result.seconds:.2f} s",
        "  input a ~ uniform(low=1, high=3)",
        "  input b ~ normal(mean=0, std=1)",
        "  outputs: y (5 times in [0, 2])",
    ]
    assert text.splitlines()[-1].startswith(f"  warnings: {len(result.warnings)}")


def test_a_configs_source_is_given_at_construction_and_kept_by_replace():
    from pathlib import Path

    from pcmb.config.schema import load_config
    from pcmb.study import StudySource

    config = load_config(Path(__file__).resolve().parents[1] / "configs" / "quarter_car.yaml")
    study = pcmb.Study.from_config(config)
    assert study.source.address_key == "execution.address"
    assert '"method"' in study.source.settings  # the run-relevant config is fingerprinted
    assert study.replace(execution={"jobs": 1}).source == study.source
    dask = study.replace(execution={"backend": "dask"})
    assert dask.replace(address="tcp://h:1").source.address_key == "address"
    flagged = pcmb.Study.from_config(
        config, {"backend": "dask", "address": "tcp://h:1"}, "--address"
    )
    assert flagged.source == dataclasses.replace(study.source, address_key="--address")
    assert (flagged.execution.backend, flagged.address) == ("dask", "tcp://h:1")
    assert flagged.execution.on_failure == study.execution.on_failure  # the config's, kept
    nodes = study.node_set()
    plain = study.replace(source=StudySource())
    assert plain.fingerprint(nodes, ["x1"]).digest != study.fingerprint(nodes, ["x1"]).digest


def test_a_run_makes_and_checks_its_nodes_once(monkeypatch):
    """The design's nodes are made once and checked for overflow once; the held-out runs'
    nodes once too."""
    study = pcmb.Study(pointwise, INPUTS, TIMES, execution={"backend": "inprocess"})
    made, checked = [], []
    real_nodes = type(study.design).nodes
    monkeypatch.setattr(
        type(study.design), "nodes", lambda design: made.append(1) or real_nodes(design)
    )
    real_check = pcmb.study.overflowing_inputs
    monkeypatch.setattr(
        pcmb.study,
        "overflowing_inputs",
        lambda nodes, names: checked.append(nodes.size) or real_check(nodes, names),
    )
    result = study.run()
    assert len(made) == 1
    assert checked == [result.n_nodes, len(result.held_out.ok)]


def test_a_journaled_run_digests_the_models_files_once_for_all_its_journals(tmp_path, monkeypatch):
    """Every journal folder of a run (nodes, each round, held-out runs) records the same
    digests of the model's files, taken once."""
    study = pcmb.Study(
        pointwise,
        INPUTS,
        TIMES,
        method={"kind": "adaptive", "tolerance": 1e-3, "max_runs": 60},
        execution={"backend": "inprocess"},
    )
    digested = []
    real = pcmb.study.digest_files
    monkeypatch.setattr(pcmb.study, "digest_files", lambda paths: digested.append(1) or real(paths))
    result = study.run(tmp_path / "r.h5")
    assert result.design.samples > study.design.nodes().size  # rounds were journaled
    assert len(digested) == 1


def test_a_quarter_car_like_study_makes_no_more_model_calls_than_its_workers():
    """216 design nodes, 8 held-out runs and the nominal run of a model preferring chunks of
    128 (as the stacked ODE models do) go to 2 workers in 2 calls of 113 and 112 runs, not in
    5 (128 + 88 nodes, 4 + 4 held-out runs, the nominal run alone): each run says the size of
    the batch it was part of, so the calls are the sum of 1 / batch size."""
    from executor_models import StackedRamp

    inputs = {name: pcmb.Uniform(1.0, 3.0) for name in ("a", "b", "c")}
    study = pcmb.Study(
        StackedRamp,
        inputs,
        TIMES,
        method={"kind": "collocation", "order": 5},
        execution={"jobs": 2, "backend": "loky"},
        outputs=["y", "batch_size"],
        diagnostics={"outputs": ["y"]},  # the batch sizes vary by node: no chaos of them
    )
    result = study.run()
    sizes = np.concatenate(
        [
            result.values["batch_size"][:, 0],
            result.held_out.values["batch_size"][:, 0],
            result.nominal["batch_size"][:1],
        ]
    )
    assert sizes.size == 216 + 8 + 1
    assert round(np.sum(1 / sizes)) <= study.execution.jobs
    assert sorted(set(sizes)) == [112, 113]
    assert np.array_equal(result.values["y"][:, -1], 2.0 * result.params[:, 0])


def test_a_resumed_study_reruns_only_what_its_joined_campaign_left(tmp_path):
    """The design's nodes, the held-out runs and the nominal run go in one campaign, each set
    journaled in its own folder: a run stopped by a failed held-out run (on_failure: abort)
    resumes with that run, those never started and the nominal run (never journaled) only,
    and every run keeps its own values (a ramp: y = a t)."""
    from executor_models import SwitchedRamp

    inputs = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Uniform(0.0, 1.0)}
    settings = {
        "method": {"kind": "collocation", "order": 2},
        "outputs": ["y"],
        "nominal": {"a": 1.5, "b": 0.25},  # no node's
        "execution": {"backend": "inprocess", "on_failure": "abort"},
    }
    switch = tmp_path / "switch"
    plain = pcmb.Study(SwitchedRamp, inputs, TIMES, params={"bad": [], "switch": ""}, **settings)
    held_out = [tuple(row) for row in plain.run().held_out.params.tolist()]
    switch.touch()
    params = {"bad": [held_out[3][0]], "switch": str(switch)}
    study = pcmb.Study(SwitchedRamp, inputs, TIMES, params=params, **settings)
    SwitchedRamp.RAN.clear()
    # Named as a held-out run (its index is among those runs, not the design's nodes).
    with pytest.raises(ModelRunError, match=r"failed at 1 of 8 held-out run\(s\)"):
        study.run(tmp_path / "r.h5")
    assert not (tmp_path / "r.h5").exists()
    never = [row for row in held_out if row not in SwitchedRamp.RAN]
    switch.unlink()
    SwitchedRamp.RAN.clear()
    result = study.run(tmp_path / "r.h5", resume=True)
    assert sorted(SwitchedRamp.RAN) == sorted([held_out[3], *never, (1.5, 0.25)])
    assert np.array_equal(result.values["y"], result.params[:, :1] * TIMES)
    assert np.array_equal(result.held_out.values["y"], result.held_out.params[:, :1] * TIMES)
    assert np.array_equal(result.nominal["y"], 1.5 * TIMES)


@pytest.mark.parametrize(
    "method",
    [{"kind": "collocation", "order": 2}, {"kind": "collocation", "order": "auto"}],
    ids=["joined", "after-rounds"],
)
def test_a_failed_held_out_run_names_both_journals(tmp_path, method):
    """A held-out run that stops a study (on_failure: abort) keeps the design's nodes in the
    journal and the held-out runs in its ``validation`` folder: the error names both, and
    that ``--resume`` keeps both (with or without rounds before the held-out runs)."""
    from executor_models import SwitchedRamp

    inputs = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Uniform(0.0, 1.0)}
    settings = {
        "method": method,
        "outputs": ["y"],
        "execution": {"backend": "inprocess", "on_failure": "abort"},
    }
    plain = pcmb.Study(SwitchedRamp, inputs, TIMES, params={"bad": [], "switch": ""}, **settings)
    bad = plain.run().held_out.params[3, 0]
    switch = tmp_path / "switch"
    switch.touch()
    params = {"bad": [bad], "switch": str(switch)}
    study = pcmb.Study(SwitchedRamp, inputs, TIMES, params=params, **settings)
    with pytest.raises(ModelRunError) as raised:
        study.run(tmp_path / "r.h5")
    journal = tmp_path / "r.h5.journal"
    assert f"the design's nodes are kept in {journal} and the " in str(raised.value)
    assert f"finished held-out run(s) in {journal / 'validation'}" in str(raised.value)
    assert "--resume keeps both" in str(raised.value)
    # The failed run is numbered among the held-out runs, and called one (not "node 3").
    assert "held-out run 3 (a=" in str(raised.value) and "node 3" not in str(raised.value)
