"""Order refinement (method.order: auto) against closed forms: smooth exponentials stop once
the order indicator meets the tolerance, with the true error below it; the double well runs
out of orders and says so; errors name their key; a run killed between rounds resumes."""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import numpy as np
import pytest
from model_loading import model_class
from test_resume import (
    PYTHON_CONFIG,
    PYTHON_MODEL,
    assert_same_runs,
    inspected,
    resume_and_rerun,
    run_and_kill,
)

import pcmb
from pcmb.chaos.nodes import join_nodes
from pcmb.chaos.sparse import SparseGrid, box_index_set
from pcmb.config.schema import load_config
from pcmb.designs import MethodSettings, make_design
from pcmb.designs.refine import box_errors, error_ratio
from pcmb.designs.smolyak import nested_rules
from pcmb.errors import ConfigError, UsageError
from pcmb.references import double_well_moments
from pcmb.store import load
from pcmb.study import Study

TIMES = np.linspace(0.0, 1.0, 11)


def _exponential(high: float, c: float):
    """y = exp(a t + c b), a ~ U[0, high], b ~ N(0, 1), and its exact mean and std."""

    @pcmb.batched(outputs=("y",))
    def model(params, times):
        return {"y": np.exp(params["a"][:, None] * times + c * params["b"][:, None])}

    def moment(k: int):  # E[y^k]: E[e^{k a t}] E[e^{k c b}]
        rate = k * high * TIMES
        safe = np.where(rate > 0, rate, 1.0)
        return np.where(rate > 0, np.expm1(rate) / safe, 1.0) * np.exp((k * c) ** 2 / 2)

    mean = moment(1)
    return model, mean, np.sqrt(moment(2) - mean**2)


def _inputs(high: float) -> dict[str, pcmb.Distribution]:
    return {"a": pcmb.Uniform(0.0, high), "b": pcmb.Normal(0.0, 1.0)}


INPUTS = _inputs(1.0)
#: Relative errors below this are round-off: an estimate and a true error below it agree.
ROUND_OFF = 1e-12


def _error(result, mean, std) -> float:
    """The true error of the statistics, as the indicator measures it."""
    gap = np.maximum(np.abs(result.mean("y") - mean), np.abs(result.std("y") - std))
    return float(gap.max() / std.max())


@pytest.mark.parametrize(
    ("high", "c", "tolerance", "rounds"),
    [(1.0, 0.2, 0.05, 1), (6.0, 0.5, 0.05, 2), (6.0, 0.5, 1e-6, 3)],
)
def test_smooth_responses_stop_once_the_estimate_meets_the_tolerance(
    tmp_path, high, c, tolerance, rounds
):
    model, mean, std = _exponential(high, c)
    study = Study(
        model,
        _inputs(high),
        TIMES,
        order="auto",
        backend="inprocess",
        diagnostics_tolerance=tolerance,
    )
    result = study.run(tmp_path / "out.h5")
    history = result.refinement
    # Gauss–Patterson in a (1, 3, 7, 15 points; orders 2, 5, 11), Genz–Keister in b (1, 3, 9,
    # 19 points; orders 2, 7, 14): round l is the tensor grid of level l in both.
    points = {1: (3, 3), 2: (7, 9), 3: (15, 19)}
    degrees = {1: (2, 2), 2: (5, 7), 3: (11, 14)}
    assert result.design.orders == degrees[rounds]
    label = f" (order auto to {tolerance:g}, {result.n_nodes} runs)"
    assert result.design.label.startswith("chaos order") and result.design.label.endswith(label)
    np.testing.assert_array_equal(history.orders, [degrees[k] for k in range(1, rounds + 1)])
    assert history.indicator[-1] < tolerance and np.all(history.indicator[1:-1] >= tolerance)
    assert not [w for w in result.warnings if w.code == "order-budget"]
    # The first round may stop (9 runs where it never did: 63 runs for an error of 2e-13 at
    # tolerance 0.05); how close the estimate is to the true error is measured on these and
    # more responses by test_the_estimate_lies_within_10x_of_the_true_error.
    assert _error(result, mean, std) < tolerance
    # The grids are nested: each round runs only its new nodes, and every run is used.
    np.testing.assert_array_equal(history.runs, [np.prod(points[k]) for k in range(1, rounds + 1)])
    assert result.n_nodes == history.runs[-1] == result.design.samples
    assert np.count_nonzero(result.weights) == result.n_nodes
    np.testing.assert_allclose(result.weights @ result.values["y"], result.mean("y"), rtol=1e-12)
    stored = load(tmp_path / "out.h5")
    assert stored.design == result.design
    for field in ("orders", "runs", "indicator"):
        np.testing.assert_array_equal(getattr(stored.refinement, field), getattr(history, field))


@pytest.mark.filterwarnings("ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning")
@pytest.mark.filterwarnings("ignore:.*would decide.*:pcmb.errors.PcmbWarning")
def test_the_double_well_reuses_every_run():
    """x' = x - x³ to t = 8: the runs split between the wells ever more sharply. Gauss rules
    re-ran every order to 12, 85 runs of which 72 were discarded, and ended 0.096 off; the
    nested Gauss–Patterson grids meet 0.05 at level 2 (7 runs, order 5), every run used."""
    times = np.linspace(0.0, 8.0, 81)
    low, high = -0.625, 0.375
    study = Study(
        model_class("double_well", "DoubleWell"),
        {"x0": pcmb.Uniform(low, high)},
        times,
        order="auto",
        backend="inprocess",
        validation=0,  # 8 held-out runs cannot tell 2.5 % from 5 % here: not this test's subject
    )
    result = study.run()
    assert np.count_nonzero(result.weights) == result.n_nodes == 7
    np.testing.assert_array_equal(result.refinement.runs, [3, 7])
    mean, std = double_well_moments(times, low, high)
    error = np.maximum(np.abs(result.mean("x") - mean), np.abs(result.std("x") - std))
    error = error.max() / std.max()
    estimate = result.refinement.indicator[-1]
    assert estimate < study.diagnostics.tolerance and error < study.diagnostics.tolerance
    assert error / 10 <= estimate <= 10 * error


@pytest.mark.filterwarnings("ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning")
def test_max_runs_ends_the_rounds():
    model, _, _ = _exponential(6.0, 0.5)
    study = Study(
        model,
        _inputs(6.0),
        TIMES,
        order="auto",
        max_runs=100,
        backend="inprocess",
        validation=0,
        diagnostics_tolerance=1e-6,
    )
    with pytest.warns(pcmb.PcmbWarning, match="order-budget"):
        result = study.run()
    assert result.n_nodes == 63 and result.design.orders == (5, 7)  # level 3 needs 222 more
    (record,) = [w for w in result.warnings if w.code == "order-budget"]
    assert "63 of 100 runs (method.max_runs)" in record.message
    assert "raise method.max_runs" in record.message


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        ({"kind": "regression", "samples": 32}, "method.order"),
        ({"kind": "collocation", "elements": {"a": [0.5]}}, "method.order"),
        ({"kind": "collocation", "max_runs": 8}, "method.max_runs"),  # level 1: 9 runs
        ({"kind": "collocation", "tolerance": 0.01}, "method.tolerance"),
    ],
)
def test_unusable_settings_name_their_key(settings, key):
    with pytest.raises(ValueError, match=rf"^{key}:"):
        make_design(INPUTS, MethodSettings(orders="auto", diagnostics_tolerance=0.05, **settings))


@pytest.mark.parametrize(("inputs", "allowed"), [(3, True), (5, False)])
def test_the_smallest_budget_is_the_first_round(inputs, allowed):
    """max_runs 125 (a sweep's first value) allows 3 inputs (level 1: 27 runs; levels 1 and 2,
    343 runs, were required), not 5 (243 runs), refused at the key."""
    names = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(inputs)}
    settings = MethodSettings(
        "collocation", orders="auto", diagnostics_tolerance=0.05, max_runs=125
    )
    if allowed:
        assert make_design(names, settings).runs == 27
    else:
        with pytest.raises(ValueError, match=r"^method.max_runs: .*level 1 .* 243 runs"):
            make_design(names, settings)


def test_a_study_with_an_unknown_order_names_it():
    model, _, _ = _exponential(1.0, 0.2)
    with pytest.raises(UsageError) as caught:
        Study(model, INPUTS, TIMES, order="fine")
    assert [p.path for p in caught.value.problems] == ["method.order"]


def _write_config(folder, method: str):
    (folder / "model.py").write_text(
        PYTHON_MODEL.replace(
            '{"y": params["a"] * times + params["b"] ** 2}',
            '{"y": 1.0 / (1.0 + params["a"] * times + params["b"] ** 2)}',
        )
    )
    text = PYTHON_CONFIG.replace("method: {kind: collocation, order: 3}", f"method: {method}")
    (folder / "study.yaml").write_text(text)
    return folder / "study.yaml"


@pytest.mark.parametrize(
    ("method", "key"),
    [
        ("{kind: collocation, order: fine}", "method.order"),
        ("{kind: collocation, order: -1}", "method.order"),
        ("{kind: regression, order: auto, samples: 16}", "method.order"),
        ("{kind: collocation, order: auto, max_runs: 5}", "method.max_runs"),
    ],
)
def test_config_errors_name_the_key(tmp_path, method, key):
    path = _write_config(tmp_path, method)
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert [p.path for p in caught.value.problems] == [key]


@pytest.mark.slow
def test_a_run_killed_between_rounds_resumes_to_the_same_result(tmp_path):
    """Round 0 (level 1: 9 runs) journaled, killed in round 1; the resumed run writes what an
    uninterrupted one does, and inspect shows the rounds."""
    _write_config(tmp_path, "{kind: collocation, order: auto, max_runs: 300}")
    run_and_kill(tmp_path, after=9, nominal_first=True)
    journal = tmp_path / "out.h5.journal"
    assert len(list(journal.glob("record-*.npz"))) == 9
    first, second = resume_and_rerun(tmp_path)
    assert first.n_nodes == second.n_nodes >= 63 and first.design == second.design
    for field in ("orders", "runs", "indicator"):
        np.testing.assert_array_equal(
            getattr(first.refinement, field), getattr(second.refinement, field)
        )
    assert_same_runs(tmp_path, first, second)
    shown = inspected(tmp_path / "out.h5")
    assert first.design.label in shown
    assert "refined  order: indicator per round 2: " in shown


def test_a_failed_node_ends_the_rounds_naming_the_order_its_estimate_belongs_to():
    # exp(6 a t + 0.5 b): rounds of orders 2, (5, 7), (11, 14); a node of the third fails, so
    # the last estimate is that of order 7, while the recovery fits the grid of order 14.
    settings = MethodSettings(kind="collocation", orders="auto", diagnostics_tolerance=1e-6)
    design = make_design(_inputs(6.0), settings)

    def values_at(nodes, lost=()):
        found = np.exp(np.outer(nodes.params[:, 0], TIMES) + 0.5 * nodes.params[:, 1:])
        found[list(lost)] = np.nan
        return found

    nodes = design.nodes()
    values, ok = values_at(nodes), np.ones(nodes.size, dtype=bool)
    while (batch := design.more(nodes, {"y": values}, ok)) is not None:
        lost = [0] if nodes.size == 63 else []
        nodes, values = join_nodes(nodes, batch), np.vstack([values, values_at(batch, lost)])
        ok = np.concatenate([ok, ~np.isin(np.arange(batch.size), lost)])
    recovery = design.recover(nodes, {"y": values}, ok, TIMES)
    assert nodes.size == 285 and design.record().orders == (11, 14)
    (record,) = [w for w in recovery.warnings if w.code == "nodes-failed"]
    last = recovery.report.refinement
    assert last.orders[-1].tolist() == [5, 7]
    assert f"the estimated error of order 7 {last.indicator[-1]:.3g} above" in record.message
    assert "1 node(s) of level 3 failed" in record.message


def _refined(inputs, values_at, ok_at=lambda nodes: np.ones(nodes.size, dtype=bool)):
    """Run ``order: auto`` at diagnostics.tolerance 1e-6 on outputs ``values_at(nodes)``
    (name -> (N, T)); the design, its nodes and its recovery."""
    settings = MethodSettings(kind="collocation", orders="auto", diagnostics_tolerance=1e-6)
    design = make_design(inputs, settings)
    nodes = design.nodes()
    values, ok = values_at(nodes), ok_at(nodes)
    while (batch := design.more(nodes, values, ok)) is not None:
        found = values_at(batch)
        nodes = join_nodes(nodes, batch)
        values = {name: np.vstack([values[name], found[name]]) for name in values}
        ok = np.concatenate([ok, ok_at(batch)])
    return design, nodes, design.recover(nodes, values, ok, TIMES)


def test_a_non_finite_output_at_a_node_run_ends_the_rounds_naming_the_output_and_node():
    """NaN at a node counted as run made the estimate NaN, which never met the tolerance: the
    rounds went on to max_runs (1000) or the highest order."""

    def values_at(nodes):
        y = np.exp(np.outer(nodes.params[:, 0], TIMES) + 0.5 * nodes.params[:, 1:])
        z = y.copy()
        z[nodes.params[:, 0] == 3.0, 4] = np.nan  # the middle node in a (0, 3 or 6 at level 1)
        return {"y": y, "z": z}

    _, nodes, recovery = _refined(_inputs(6.0), values_at)
    assert nodes.size == 9  # level 1 only
    (record,) = [w for w in recovery.warnings if "order refinement" in w.message]
    assert record.code == "statistic-non-finite" and record.output == "z"
    middle = np.flatnonzero(nodes.params[:, 0] == 3.0)
    assert [f"node {i} (a=3, b=" in record.message for i in middle] == [True] * 3
    assert "order-budget" not in {w.code for w in recovery.warnings}


def test_a_non_finite_output_is_recorded_once():
    """The rounds' end and the statistics each recorded ``statistic-non-finite`` for the
    same output: two records of one problem."""

    def values_at(nodes):
        y = np.exp(np.outer(nodes.params[:, 0], TIMES) + 0.5 * nodes.params[:, 1:])
        y[nodes.params[:, 0] == 3.0, 4] = np.nan
        return {"y": y}

    *_, recovery = _refined(_inputs(6.0), values_at)
    (record,) = [w for w in recovery.warnings if w.code == "statistic-non-finite"]
    assert record.output == "y" and record.time_range == (TIMES[4], TIMES[4])
    assert "order refinement ended at order 2 after 9 runs" in record.message
    assert "its Sobol' indices there are NaN" in record.message


def test_a_failed_node_ending_the_rounds_is_not_called_a_budget():
    def values_at(nodes):
        return {"y": np.exp(np.outer(nodes.params[:, 0], TIMES) + 0.5 * nodes.params[:, 1:])}

    *_, recovery = _refined(_inputs(6.0), values_at, lambda nodes: nodes.params[:, 0] != 3.0)
    codes = [w.code for w in recovery.warnings]
    assert "order-budget" not in codes
    (record,) = [w for w in recovery.warnings if "order refinement" in w.message]
    assert record.code == "nodes-failed"
    assert "node(s) of level 1 failed" in record.message
    assert "method.max_runs" not in record.message


def _cubic(nodes) -> dict[str, np.ndarray]:
    """a³ t + a b² - b t², of degrees 3 in a and 2 in b: exact on the grid of level 2."""
    a, b = nodes.params[:, :1], nodes.params[:, 1:]
    return {"y": a**3 * TIMES + a * b**2 - b * TIMES**2}


@pytest.mark.parametrize(
    "settings",
    [
        MethodSettings("collocation", orders="auto", diagnostics_tolerance=1e-6),
        MethodSettings("adaptive", tolerance=1e-6, basis="tensor"),
    ],
    ids=["order-auto", "adaptive-tensor"],
)
def test_a_polynomial_response_stops_on_the_grid_that_resolves_it(settings):
    """The grid of level 2 (orders 5, 7) holds the response exactly: along a, odd, its norms
    of degrees 2, 4 and 5 are round-off, and the single norm left (degree 3) told no decay, so
    the estimate stayed at the change from level 1 (4.5e-3) and both variants ran a level
    more (285 and 135 runs)."""
    inputs = {"a": pcmb.Uniform(-1.0, 1.0), "b": pcmb.Normal(0.0, 1.0)}
    design = make_design(inputs, settings)
    nodes = design.nodes()
    values, ok = _cubic(nodes), np.ones(nodes.size, dtype=bool)
    while (batch := design.more(nodes, values, ok)) is not None:
        nodes = join_nodes(nodes, batch)
        values = {"y": np.vstack([values["y"], _cubic(batch)["y"]])}
        ok = np.ones(nodes.size, dtype=bool)
    assert nodes.size == 63 and design.record().orders == (5, 7)


def test_a_converging_response_at_the_last_level_is_not_called_discontinuous():
    """1/(1.05 - a): analytic, its estimate falls ~1e-4 per level to the rule's last; the
    record told it order alone may not converge, "a steep, discontinuous or chaotic response"
    (the kink of test_verdicts keeps that advice: its estimate stalls)."""
    settings = MethodSettings("collocation", orders="auto", diagnostics_tolerance=1e-14)
    design = make_design({"a": pcmb.Uniform(0.0, 1.0)}, settings)
    nodes = design.nodes()

    def pole(nodes):
        return 1 / (1.05 - nodes.params) + 0 * TIMES

    values = pole(nodes)
    while (batch := design.more(nodes, {"y": values}, np.ones(nodes.size, bool))) is not None:
        nodes, values = join_nodes(nodes, batch), np.vstack([values, pole(batch)])
    recovery = design.recover(nodes, {"y": values}, np.ones(nodes.size, bool), TIMES)
    (record,) = [w for w in recovery.warnings if w.code == "order-budget"]
    indicator = recovery.report.refinement.indicator
    assert indicator[-1] < 1e-3 * indicator[-2]
    assert "discontinuous" not in record.message
    assert f"fell from {indicator[-2]:.3g} to {indicator[-1]:.3g}" in record.message
    assert "method.elements" in record.message


def test_a_converging_response_stopped_by_max_runs_is_told_to_raise_it_only():
    """A damped oscillator's phase drift to t = 8: its estimate falls 1.6 -> 7.8e-3 over
    level 2; the record stopped by max_runs added "order alone may not converge for a steep,
    discontinuous or chaotic response"."""
    times = np.linspace(0.0, 8.0, 81)
    inputs = {"omega": pcmb.Uniform(1.5, 2.5), "zeta": pcmb.Uniform(0.02, 0.1)}
    settings = MethodSettings(
        "collocation", orders="auto", diagnostics_tolerance=1e-4, max_runs=100
    )
    design = make_design(inputs, settings)

    def swing(nodes):
        omega, zeta = nodes.params[:, :1], nodes.params[:, 1:]
        return np.exp(-zeta * omega * times) * np.cos(omega * np.sqrt(1 - zeta**2) * times)

    nodes = design.nodes()
    values = swing(nodes)
    while (batch := design.more(nodes, {"y": values}, np.ones(nodes.size, bool))) is not None:
        nodes, values = join_nodes(nodes, batch), np.vstack([values, swing(batch)])
    recovery = design.recover(nodes, {"y": values}, np.ones(nodes.size, bool), times)
    (record,) = [w for w in recovery.warnings if w.code == "order-budget"]
    before, last = recovery.report.refinement.indicator
    assert nodes.size == 49 and "49 of 100 runs (method.max_runs)" in record.message
    assert f"raise method.max_runs: the estimate fell from {before:.3g} to {last:.3g}" in (
        record.message
    )
    assert "discontinuous" not in record.message


def test_the_error_estimate_does_not_depend_on_the_outputs_scale():
    """The estimate is relative to the std: the same response in other units gives the same
    estimate (near 1e300 the squares of the coefficients overflowed: 2.1e-3 for 2.1e-7; at
    1e150 they did not, so that scale tested nothing)."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(-1.0, 1.0)}
    grid = SparseGrid(tuple(inputs.values()), box_index_set((2, 2)), nested_rules(inputs, "auto"))
    values = (1 / (1.2 + grid.params[:, 0] + 0.6 * grid.params[:, 1]))[:, None, None]
    np.testing.assert_allclose(
        box_errors(grid, 1e300 * values), box_errors(grid, values), rtol=1e-9
    )


@pytest.mark.parametrize("c", [1.0, 0.5])
def test_the_std_error_of_an_entire_hermite_response_counts_its_truncated_squares(c):
    """e^(c b), b ~ N(0, 1), on the 9 Genz–Keister nodes (degree 7): its Hermite coefficients
    fall like c^q / sqrt(q!), and the std's error is what the squares past degree 7 add to it,
    not the degree-16 term the ratios read (0.086x and 0.095x of the true error before)."""
    inputs = {"b": pcmb.Normal(0.0, 1.0)}
    grid = SparseGrid((inputs["b"],), box_index_set((2,)), nested_rules(inputs, "auto"))
    values = np.exp(c * grid.params)[:, None, :]
    expansion = pcmb.ChaosExpansion(grid.project(values), grid.multi_index, grid.distributions)
    mean, std = np.exp(c**2 / 2), np.sqrt(np.exp(2 * c**2) - np.exp(c**2))
    error = max(abs(expansion.mean()[0, 0] - mean), abs(expansion.std()[0, 0] - std)) / std
    assert error / 10 <= box_errors(grid, values)[0] <= 10 * error


def _calibration():
    """scripts/calibrate_order_auto.py, whose cases carry their closed forms."""
    path = Path(__file__).resolve().parents[1] / "scripts" / "calibrate_order_auto.py"
    spec = importlib.util.spec_from_file_location("calibrate_order_auto", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


CALIBRATION = _calibration()


#: 3 nodes in a cannot see sqrt's branch point 0.002 off the interval: their norms (0.77, 0.11
#: of the std at degrees 1, 2) are those of exp(a t + b/5) (0.82, 0.10), whose first round's
#: true error is 60x smaller, so no reading of them is within 10x of both (docs/methods.md).
BLIND_FIRST_ROUND = pytest.mark.xfail(
    strict=True, reason="the first round cannot tell sqrt(a + 0.002) from exp(a)"
)


@pytest.mark.parametrize(
    ("case", "tolerance"),
    [
        pytest.param(
            case,
            tolerance,
            marks=BLIND_FIRST_ROUND if case == "sqrt(a + 0.002) e^b" and tolerance >= 1e-3 else (),
        )
        for case in CALIBRATION.CASES
        for tolerance in CALIBRATION.TOLERANCES
    ],
)
def test_the_estimate_lies_within_10x_of_the_true_error(case, tolerance):
    """On entire, near-singular, kinked and discontinuous responses alike, the last round's
    estimate lies within 10x of the true error on either side (before: 50x careful on
    exp(6 a t), 15x over-confident on abs(a - 0.3) + b)."""
    _, estimate, error, _ = CALIBRATION.run(case, tolerance)
    estimate, error = max(estimate, ROUND_OFF), max(error, ROUND_OFF)
    assert error / 10 <= estimate <= 10 * error


def test_the_error_ratio_reads_geometric_faster_and_oscillating_decays():
    """Geometric norms: ρ per degree over the 2 Δp degrees the error falls by; an entire
    function's (ratios 1.5/q, exp(3x)'s) fall further; a lucky small norm does not."""
    geometric = [0.5**q for q in range(6)]
    assert error_ratio(geometric, 2) == pytest.approx(0.5**6)
    entire = np.cumprod([1.0] + [1.5 / q for q in range(1, 6)])
    assert error_ratio(list(entire), 2) < 0.1 * error_ratio(geometric, 2)
    # abs(a - 0.3)'s norms at degree 5, whose true error fell 5x at that level: the raw
    # slope read 0.0135 (15x over-confident); its envelope reads within 10x of the fall.
    lucky = [1.0, 0.16, 0.098, 0.051, 0.0072, 0.017]
    envelope = [1.0, 0.16, 0.098, 0.051, 0.017, 0.017]
    true_fall = 1 / 5
    assert error_ratio(lucky, 2) == error_ratio(envelope, 2) >= true_fall / 10
    # abs(a - 0.2)'s: ratios 0.67, 0.38, 0.15 fall far faster than an entire function's (a
    # lucky small norm at the top; the next are 0.0026-0.0081): read geometrically, as
    # before, not 1e-4 times lower.
    steep = [1.1, 0.23, 0.058, 0.039, 0.015, 0.0022]
    slope = np.polyfit(np.arange(2, 6), np.log(steep[2:]), 1)[0]
    assert error_ratio(steep, 2) == pytest.approx(np.exp(6 * slope))


def test_without_held_out_runs_an_estimate_within_its_calibration_leaves_the_time_undecided():
    """Logistic growth (scripts/calibrate_order_auto.py --held-out) to 1e-2, ``validation:
    0``: order: auto stops at 9 runs with an estimate of 7.8e-3 while the decay says 0.1 and
    the true error is 1.8e-2. Vouched for by the estimate at face value before; now
    undecided, as the estimate fell to 0.15 of the truth in its calibration
    (docs/methods.md)."""
    inputs, function, times, mean, std = CALIBRATION.HELD_OUT["logistic growth"]()
    names = list(inputs)

    @pcmb.batched(outputs=("y",))
    def model(params, times):
        return {"y": function(np.column_stack([params[name] for name in names]))}

    study = Study(
        model,
        inputs,
        times,
        method={"kind": "collocation", "order": "auto", "validation": 0},
        execution={"backend": "inprocess"},
        diagnostics={"tolerance": 1e-2},
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        result = study.run()
    gap = np.maximum(np.abs(result.mean("y") - mean), np.abs(result.std("y") - std))
    assert result.report.statistics_error(result, "y") <= 1e-2 < gap.max() / std.max()
    found = result.diagnostics["y"]
    assert not found.vouched and np.isnan(found.failing_from)
    assert "chaos-undecided" in {w.code for w in result.warnings}
