"""Verdicts that mean what they say: a degenerate design, budget messages that name the limit
hit, no "reliable" next to "not converged", recorded-only notes kept out of the warnings, and
remedies that fit the cause."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_process import pcmb_cli
from model_loading import model_class
from scipy.integrate import solve_ivp

import pcmb

# -- a degenerate design -----------------------------------------------------------------------

#: The Sobol' G-function's a_i of four inputs.
G_COEFFICIENTS = np.array([0.0, 1.0, 4.5, 9.0])
G_INPUTS = {f"x{i}": pcmb.Uniform(0.0, 1.0) for i in range(G_COEFFICIENTS.size)}
G_TIMES = np.linspace(0.0, 1.0, 3)


@pcmb.batched(outputs=("y",))
def g_function(params, times):
    """G(x) = Π (|4 x_i - 2| + a_i) / (1 + a_i), the same at every time."""
    x = np.column_stack([params[name] for name in G_INPUTS])
    value = np.prod((np.abs(4 * x - 2) + G_COEFFICIENTS) / (1 + G_COEFFICIENTS), axis=1)
    return {"y": np.repeat(value[:, None], times.size, axis=1)}


def _g_study(validation: int) -> pcmb.StudyResult:
    """Order 1: both Gauss points of every input sit symmetric about the kink at 1/2."""
    study = pcmb.Study(
        g_function, G_INPUTS, G_TIMES, order=1, backend="inprocess", validation=validation
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        return study.run()


def test_a_design_whose_runs_are_all_equal_is_unreliable_when_the_held_out_runs_vary():
    result = _g_study(validation=32)
    assert result.n_nodes == 16
    np.testing.assert_array_equal(result.std("y"), 0.0)
    found = result.diagnostics["y"]
    assert not found.reliable
    assert found.failing_from == 0.0
    (record,) = [w for w in result.warnings if w.code == "chaos-unreliable"]
    assert "16 runs" in record.message and "all equal" in record.message
    assert "32 held-out runs vary" in record.message
    # The true mean is 1; the expansion's is 1.3: the estimate sees a large error.
    assert found.estimate.max() > 0.2


def test_runs_all_equal_at_one_time_while_the_held_out_runs_vary_fail_the_verdict_there():
    from pcmb.analysis.diagnostics import diagnose
    from pcmb.chaos.nodes import TensorGrid, random_nodes
    from pcmb.chaos.recovery import project_tensor

    def response(xi):
        """ξ (t - 1/2) + |ξ| / 100: at t = 1/2 even, so order 1's two nodes agree there."""
        return np.outer(xi[:, 0], G_TIMES - 0.5) + np.abs(xi) / 100

    grid = TensorGrid((pcmb.Uniform(-1.0, 1.0),), (1,))
    values = response(grid.nodes)
    expansion = pcmb.ChaosExpansion(
        project_tensor(grid, values, grid.multi_index), grid.multi_index, grid.distributions
    )
    germ = random_nodes(grid.distributions, 32, "lhs", 1).nodes
    held_out = (expansion.evaluate_germ(germ), response(germ))
    found = diagnose("y", expansion, values, G_TIMES, held_out)
    # The error there is a small share of the largest std, but the design saw nothing.
    assert found.estimate[1] < found.tolerance
    assert found.failing_from == 0.5
    (record,) = [w for w in found.warnings if w.code == "chaos-unreliable"]
    assert "2 runs are all equal at 1 of 3 times" in record.message


def test_without_held_out_runs_a_record_says_the_runs_were_all_equal():
    result = _g_study(validation=0)
    (record,) = [w for w in result.warnings if w.code == "runs-all-equal"]
    assert record.output == "y"
    assert "16 runs" in record.message and "nothing about the spread" in record.message
    assert "the nominal run differs" in record.message  # G(1/2, ...) = 0
    assert "method.validation" in record.message
    with pytest.warns(pcmb.PcmbWarning, match="runs-all-equal"):
        pcmb.Study(g_function, G_INPUTS, G_TIMES, order=1, backend="inprocess", validation=0).run()


# -- budget messages name the limit hit --------------------------------------------------------

KINK_INPUTS = {"x": pcmb.Uniform(-1.0, 1.0)}


@pcmb.batched(outputs=("y",))
def kink(params, times):
    """|x - 0.3|: a kink that no order resolves to round-off."""
    return {"y": np.abs(params["x"] - 0.3)[:, None] + 0 * times}


def _budget_record(code: str, **settings) -> tuple[pcmb.StudyResult, str]:
    """A study of the kink with ``settings``, and the message of its ``code`` record."""
    study = pcmb.Study(kink, KINK_INPUTS, G_TIMES, backend="inprocess", validation=0, **settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        result = study.run()
    (record,) = [w for w in result.warnings if w.code == code]
    return result, record.message


def test_order_auto_at_its_highest_order_names_that_limit_not_max_runs():
    from pcmb.designs.refine import MAX_ORDER

    result, message = _budget_record("order-budget", order="auto", diagnostics_tolerance=1e-9)
    assert result.refinement.orders.max() == MAX_ORDER
    assert f"order {MAX_ORDER} is the highest order" in message
    assert f"{result.n_nodes} of 1000 runs" in message
    assert "raise method.max_runs" not in message.lower()


def test_order_auto_stopped_by_max_runs_says_raise_max_runs():
    result, message = _budget_record(
        "order-budget", order="auto", diagnostics_tolerance=1e-9, max_runs=6
    )
    assert result.n_nodes == 5  # orders 1 and 2; order 3 would take 4 more
    assert "5 of 6 runs" in message and "raise method.max_runs" in message.lower()


def test_elements_auto_stopped_by_max_elements_names_it_with_the_numbers():
    result, message = _budget_record("element-budget", order=2, elements="auto", max_elements=2)
    assert result.partition.size == 2
    assert "2 of 2 elements" in message and "method.max_elements" in message
    assert f"{result.n_nodes} runs" in message


def test_adaptive_stopped_by_max_runs_names_it_with_the_numbers():
    result, message = _budget_record(
        "adaptive-budget", method="adaptive", tolerance=1e-9, max_runs=12
    )
    assert f"{result.n_nodes} of 12 runs" in message and "raise method.max_runs" in message


def test_regression_stopped_by_max_samples_names_it_with_the_numbers():
    result, message = _budget_record(
        "regression-budget",
        method="regression",
        order=4,
        samples=8,
        tolerance=1e-9,
        max_samples=16,
    )
    assert result.n_nodes == 16
    assert "16 of 16 runs" in message and "raise method.max_samples" in message


# -- no "reliable" next to "not converged" ------------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]


def _small_double_well(tmp_path: Path) -> Path:
    """configs/double_well_elements.yaml on 41 times, in process."""
    config = yaml.safe_load((ROOT / "configs" / "double_well_elements.yaml").read_text())
    config["model"]["entry"] = str(ROOT / "models" / "double_well.py") + ":DoubleWell"
    config["time"]["points"] = 41
    config["execution"] = {"jobs": 1, "backend": "inprocess", "on_failure": "abort"}
    config["output"] = "dw.h5"
    path = tmp_path / "dw.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


@pytest.mark.slow
def test_a_reliable_multi_element_result_is_never_called_not_converged(tmp_path):
    run = pcmb_cli("run", str(_small_double_well(tmp_path)), "--quiet", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    inspect = pcmb_cli("inspect", "dw.h5", cwd=tmp_path)
    assert inspect.returncode == 0, inspect.stderr
    assert "checked  x: reliable at every time" in inspect.stdout
    said = run.stderr + inspect.stdout
    assert "not converged" not in said
    # The elements' decay indicator is kept, as information, worded as an indicator.
    (note,) = [line for line in inspect.stdout.splitlines() if "[element-decay]" in line]
    assert note.startswith("note") and "indicator" in note
    assert "element-decay" in {w.code for w in pcmb.load(tmp_path / "dw.h5").warnings}


# -- a zero variance at the initial time is a note ---------------------------------------------


@pytest.mark.slow
def test_a_zero_variance_at_a_fixed_initial_state_is_recorded_not_warned(tmp_path):
    # The quarter car starts at rest whatever the terrain's amplitude: std 0 at t = 0.
    config = yaml.safe_load((ROOT / "configs" / "quarter_car.yaml").read_text())
    config["model"]["entry"] = str(ROOT / "models" / "quarter_car.py") + ":QuarterCar"
    config["time"]["points"] = 31
    config["inputs"] = {"A": config["inputs"]["A"]}
    config["method"] = {"kind": "collocation", "order": 2, "validation": 0}
    config["execution"] = {"jobs": 1, "backend": "inprocess", "on_failure": "abort"}
    config["output"] = "qc.h5"
    for section in ("analysis", "sweep"):
        config.pop(section, None)
    (tmp_path / "qc.yaml").write_text(yaml.safe_dump(config))
    run = pcmb_cli("run", "qc.yaml", "--quiet", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "sobol-undefined" not in run.stderr
    inspect = pcmb_cli("inspect", "qc.h5", cwd=tmp_path)
    listed = [line for line in inspect.stdout.splitlines() if "[sobol-undefined]" in line]
    assert listed and all(line.startswith("note ") for line in listed)
    assert "t in [0, 0]" in listed[0]
    kept = [w for w in pcmb.load(tmp_path / "qc.h5").warnings if w.code == "sobol-undefined"]
    assert kept and kept[0].time_range == (0.0, 0.0)


# -- remedies that fit the cause ---------------------------------------------------------------


def _remedy(result: pcmb.StudyResult) -> str:
    (record,) = [w for w in result.warnings if w.code == "chaos-unreliable"]
    return record.message.partition("; consider ")[2]


def test_a_jump_in_an_initial_condition_is_told_to_use_elements():
    double_well = model_class("double_well", "DoubleWell")
    study = pcmb.Study(
        double_well,
        {"x0": pcmb.Uniform(-0.625, 0.375)},
        np.linspace(0.0, 4.0, 81),
        order=5,
        backend="inprocess",
    )
    with pytest.warns(pcmb.PcmbWarning, match="chaos-unreliable"):
        remedy = _remedy(study.run())
    assert remedy.startswith("multi-element chaos (method.elements)")
    assert "along x0 fall algebraically" in remedy and "jump or a kink" in remedy


@pcmb.pointwise(outputs=("x",))
def van_der_pol(params, times):
    """x'' = μ (1 - x²) x' - x from x = 2 at rest: analytic in μ, its phase drifts."""

    def field(_, state):
        x, v = state
        return [v, params["mu"] * (1 - x**2) * v - x]

    span = (times[0], times[-1])
    solved = solve_ivp(field, span, [2.0, 0.0], t_eval=times, rtol=1e-9, atol=1e-9)
    return {"x": solved.y[0]}


@pytest.mark.slow
def test_an_analytic_response_is_told_to_raise_the_order():
    study = pcmb.Study(
        van_der_pol,
        {"mu": pcmb.Uniform(0.5, 3.0)},
        np.linspace(0.0, 30.0, 201),
        order=4,
        backend="inprocess",
    )
    with pytest.warns(pcmb.PcmbWarning, match="chaos-unreliable"):
        remedy = _remedy(study.run())
    assert remedy.startswith("raising the order of mu (method.order)")
    assert "along mu fall geometrically" in remedy and "smooth" in remedy


@pcmb.batched(outputs=("y",))
def constant(params, times):
    """1 at every time, whatever the inputs."""
    return {"y": np.ones((params["x0"].size, times.size))}


def test_runs_and_a_nominal_run_all_equal_without_held_out_runs_are_a_note():
    study = pcmb.Study(constant, G_INPUTS, G_TIMES, order=1, backend="inprocess", validation=0)
    result = study.run()  # no warning: the suite turns warnings into errors
    (record,) = [w for w in result.warnings if w.code == "output-constant"]
    assert result.is_note(record) and "looks constant" in record.message
    assert "runs-all-equal" not in {w.code for w in result.warnings}
