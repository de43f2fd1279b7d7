"""The held-out check sized to the study, its runs feeding the answer, and verdicts that weigh
their noise (issue 23, items 2-4).

References are closed forms: lognormal moments for exp(a z), z ~ N(0, 1); the double well's
solution x0 eᵗ / √(1 + x0² (e^{2t} - 1)) integrated by a 4000-point Gauss rule; a bouncing
ball's parabolas between impacts.
"""

from __future__ import annotations

import math
import runpy
import warnings
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.analysis.diagnostics import (
    TOLERANCE,
    HeldOutCheck,
    element_importance,
    held_out_budget,
    held_out_draws,
    held_out_placed,
    held_out_placed_elements,
    holdout_error,
    placed_check,
    verdict,
)
from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.nodes import TensorGrid
from pcmb.cli import main
from pcmb.references import bouncing_ball, double_well, double_well_moments, lognormal_moments

#: scripts/calibrate_diagnostics.py's closed-form models, shared: exp(z t / 2), the double
#: well x' = x - x³ in closed form, a ball dropped from h0, a damped oscillator (its inputs and
#: its reference moments by numpy's Gauss–Legendre rule).
CALIBRATION = runpy.run_path(
    str(Path(__file__).parents[1] / "scripts" / "calibrate_diagnostics.py")
)
lognormal, well, ball = (CALIBRATION[name] for name in ("lognormal", "well", "ball"))
oscillator, oscillator_inputs, oscillator_moments = (
    CALIBRATION[name] for name in ("oscillator", "oscillator_inputs", "oscillator_moments")
)


def _run(model, inputs, times, **settings) -> pcmb.StudyResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        return pcmb.Study(model, inputs, times, backend="inprocess", **settings).run()


def _true_error(result, name, mean, std):
    found = result.diagnostics[name]
    return np.fmax(abs(result.mean(name) - mean), abs(result.std(name) - std)) / found.scale


# -- a check sized to the study ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("inputs", "order", "nodes"),
    [({"x0": pcmb.Uniform(-0.625, 0.375)}, 3, 4), ({"z": pcmb.Normal(0.0, 1.0)}, 4, 5)],
)
def test_the_check_of_a_small_design_makes_at_most_eight_runs(
    tmp_path, capsys, inputs, order, nodes
):
    model = well if "x0" in inputs else lognormal
    times = np.linspace(0.0, 1.0, 11)  # short: both hold, and the check says so
    study = pcmb.Study(model, inputs, times, order=order, backend="inprocess")
    study.run(tmp_path / "out.h5")
    assert main(["inspect", str(tmp_path / "out.h5")]) == 0
    (runs,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("runs")]
    assert f"{nodes + 8 + 1} in all: {nodes} of the design, 8 held-out (8 ok), 1 nominal" in runs


def test_method_validation_fixes_the_count():
    times = np.linspace(0.0, 4.0, 41)
    result = _run(well, {"x0": pcmb.Uniform(-0.625, 0.375)}, times, order=3, validation=5)
    assert result.held_out.germ.shape[0] == 5


def test_one_held_out_run_leaves_the_verdict_undecided_without_failing():
    """One run has no spread: its noise is infinite, every time undecided, and the runs
    that would decide are the first batch's, not an overflow."""
    times = np.linspace(0.0, 4.0, 41)
    result = _run(well, {"x0": pcmb.Uniform(-0.625, 0.375)}, times, order=3, validation=1)
    assert result.held_out.germ.shape[0] == 1
    (record,) = [w for w in result.warnings if w.code == "chaos-undecided"]
    assert "about 7 more held-out runs would decide (method.validation: 8)" in record.message


@pcmb.batched(outputs=("x",))
def _along_a_direction(params, times):
    """exp(0.4 (z + w) t): a tail along a direction of two normal inputs, which no one input
    carries (its check stays drawn)."""
    return {"x": np.exp(0.4 * np.outer(np.asarray(params["z"]) + params["w"], times))}


def test_a_second_batch_is_drawn_only_where_the_first_leaves_the_verdict_undecided():
    # An input the response ignores beside the two: 125 runs, at most 31 held-out (a quarter,
    # rounded down).
    normal = pcmb.Normal(0.0, 1.0)
    inputs = {"z": normal, "w": normal, "v": pcmb.Uniform(0.0, 1.0)}
    times = np.linspace(0.0, 4.5, 91)
    assert pcmb.Study(_along_a_direction, inputs, times, order=4).held_out_runs(125) == (8, 31)
    # To t = 2 the expansion holds and 8 runs say so.
    assert _run(_along_a_direction, inputs, times[:41], order=4, seed=1).held_out.ok.size == 8
    # To t = 4.5 its std fails from t = 3.8: the first 8 leave times undecided, more follow.
    assert 8 < _run(_along_a_direction, inputs, times, order=4, seed=1).held_out.ok.size <= 31


def test_a_response_of_one_normal_input_beside_others_is_checked_along_it():
    """exp(z t/2) beside two uniform inputs it ignores, tensor order 4 (125 runs): the std fails
    from t = 3.6 (lognormal moments). Its expansion's tail lies in z's own terms, so the first
    batch's 8 runs are placed along z (the others at their centre), and the flag comes at the
    truth with no time undecided. Before, they were drawn and all 31 of the budget made
    (seeds 0-4): flagged at 3.85-4.35 or never (seed 2), undecided from 3.4-3.55."""
    times = np.linspace(0.0, 5.0, 101)
    inputs = {"z": pcmb.Normal(0.0, 1.0), "u": pcmb.Uniform(0.0, 1.0), "v": pcmb.Uniform(0, 1)}
    result = _run(lognormal, inputs, times, order=4)
    mean, std = lognormal_moments(0.5 * times)
    crossing = times[np.argmax(_true_error(result, "x", mean, std) > 0.05)]
    assert crossing == pytest.approx(3.6)
    found = result.diagnostics["x"]
    assert result.held_out.placed and result.held_out.ok.size == 8
    assert abs(found.failing_from - crossing) <= 0.05 * times[-1]
    assert not found.undecided.any()


@pcmb.batched(outputs=("y",))
def _step_beside_a_line(params, times):
    """1(z > 1/2) + z1/10: a jump along one normal input beside a linear one."""
    z, z1 = np.asarray(params["z"])[:, None], np.asarray(params["z1"])[:, None]
    return {"y": np.where(z > 0.5, 1.0, 0.0) + 0.1 * z1 + 0.0 * times}


def test_a_jump_along_the_line_is_flagged_by_its_interpolant_s_unseen_mean():
    """A jump at z = 1/2 beside 0.1 z1, z, z1 ~ N(0, 1), tensor order 6 (7 Gauss-Hermite points
    in z): the mean's error is 7.9 % of the std (P(z > 1/2) = 1 - Φ(1/2) against the rule's
    weights beyond 1/2). The expansion's tail lies in z's own terms, so the check is placed
    along z; the polynomial through the line's nodes and 8 runs errs on the mean too, from the
    degrees beyond it, and that error is the check's as a one-input placed check's (before:
    "its mean and std hold there", estimated error at most 4.5 %)."""
    times = np.linspace(0.0, 1.0, 3)
    inputs = {"z": pcmb.Normal(0.0, 1.0), "z1": pcmb.Normal(0.0, 1.0)}
    result = _run(_step_beside_a_line, inputs, times, order=6)
    above = 0.5 * math.erfc(0.5 / math.sqrt(2))
    std = math.sqrt(above * (1 - above) + 0.01)
    mean_error = abs(result.mean("y")[0] - above) / std
    assert mean_error == pytest.approx(0.079, abs=1e-3)
    assert result.held_out.placed
    assert result.diagnostics["y"].failing_from == 0.0


@pcmb.batched(outputs=("y",))
def _tail_times_a_wave(params, times):
    """exp(0.3 z t) (1 + 0.6 cos(2.5 z2)): a lognormal tail along z times a factor of z2."""
    z, z2 = np.asarray(params["z"]), np.asarray(params["z2"])
    return {"y": np.exp(0.3 * np.outer(z, times)) * (1 + 0.6 * np.cos(2.5 * z2))[:, None]}


def test_an_odd_order_whose_line_misses_the_nodes_keeps_the_drawn_check():
    """At tensor order 3 no Gauss-Hermite node of z2 lies at its centre, so the line z2 = 0
    passes between the nodes, where the expansion errs by z2's interpolation error, which a
    correction pinned to 0 at the nodes takes for an error along z. The true error (closed
    form: E cos(2.5 z2) = e^{-3.125}, E cos² = (1 + e^{-12.5}) / 2) passes 5 % at t = 3.5;
    placed along z, the check flagged it from t = 0 (10.5 % for a true 1.7 %). Now its runs
    are drawn and no flag comes before the crossing."""
    times = np.linspace(0.0, 6.0, 61)
    inputs = {"z": pcmb.Normal(0.0, 1.0), "z2": pcmb.Normal(0.0, 1.0)}
    result = _run(_tail_times_a_wave, inputs, times, order=3)
    a = 0.3 * times
    wave, wave2 = math.exp(-3.125), (1 + math.exp(-12.5)) / 2
    mean = np.exp(a * a / 2) * (1 + 0.6 * wave)
    std = np.sqrt(np.exp(2 * a * a) * (1 + 1.2 * wave + 0.36 * wave2) - mean**2)
    crossing = times[np.argmax(_true_error(result, "y", mean, std) > 0.05)]
    assert crossing == pytest.approx(3.5)
    assert not result.held_out.placed
    assert not result.diagnostics["y"].failing_from < crossing - 0.05 * times[-1]


@pcmb.batched(outputs=("y",))
def _quadratic_beside_a_sigmoid(params, times):
    """z1²/2 + tanh(3 z2)/2: a curved tail along z1 beside an odd sigmoid in z2."""
    z1, z2 = np.asarray(params["z1"]), np.asarray(params["z2"])
    return {"y": (0.5 * z1**2 + 0.5 * np.tanh(3 * z2))[:, None] + 0.0 * times}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_response_additive_in_another_input_is_not_vouched_for_along_one_line(seed):
    """At order 2 the odd tanh(3 z2) shows only as a z2 term: no curved term says it errs, and
    its std errs by 8.5 % of the std (a 150-point Gauss-Hermite rule). The terms of z2 alone
    hold 29 % of the variance, which a line along z1 does not see: placed along it, the check
    vouched for the output (estimate 1e-16); now the runs are drawn, and it is not."""
    inputs = {"z1": pcmb.Normal(0.0, 1.0), "z2": pcmb.Normal(0.0, 1.0)}
    result = _run(_quadratic_beside_a_sigmoid, inputs, np.linspace(0.0, 1.0, 3), seed=seed, order=2)
    z, w = np.polynomial.hermite_e.hermegauss(150)
    std = math.sqrt(0.5 + 0.25 * (w / w.sum()) @ np.tanh(3 * z) ** 2)
    found = result.diagnostics["y"]
    assert abs(result.std("y")[0] - std) / found.scale == pytest.approx(0.085, abs=1e-3)
    assert not result.held_out.placed
    assert not found.vouched


# -- no run wasted -----------------------------------------------------------------------------


def test_the_held_out_runs_correct_the_mean_and_std_within_their_standard_error(tmp_path):
    times = np.linspace(0.0, 4.0, 21)
    study = pcmb.Study(lognormal, {"z": pcmb.Normal(0.0, 1.0)}, times, order=2, backend="inprocess")
    study = study.replace(validation=64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        study.run(tmp_path / "out.h5")
    result = pcmb.load(tmp_path / "out.h5")  # what the file holds
    mean, std = lognormal_moments(0.5 * times)
    checked = result.diagnostics["x"].holdout
    # Order 2 misses most of the spread late: the corrected values are closer to the truth
    # and, at 3 standard errors, cover it.
    late = times >= 2.0
    assert np.all(abs(checked.corrected_std - std)[late] < abs(result.std("x") - std)[late])
    assert np.all(abs(checked.corrected_mean - mean) <= 3 * checked.corrected_mean_se + 1e-12)
    assert np.all(abs(checked.corrected_std - std) <= 3 * checked.corrected_std_se + 1e-12)


def test_the_corrected_mean_is_unbiased_and_its_standard_error_fair():
    # Over 400 checks of 8 runs each, the corrected mean of exp(z) at order 1 (true mean
    # e^{1/2}) averages to the truth, and its standard error covers it in about 90 % of them.
    grid = TensorGrid((pcmb.Normal(0.0, 1.0),), (1,))
    values = np.exp(grid.nodes)
    coefficients = grid.weights @ (values * np.column_stack([np.ones(2), grid.nodes[:, 0]]))
    expansion = pcmb.ChaosExpansion(coefficients[:, None], [[0], [1]], grid.distributions)
    truth = np.exp(0.5)
    found = []
    for seed in range(400):
        draws, weights = held_out_draws(grid.distributions, 8, seed)
        checked = holdout_error(
            expansion.evaluate_germ(draws.nodes),
            np.exp(draws.nodes),
            expansion.mean(),
            expansion.std(),
            float(expansion.std()[0]),
            weights=weights,
            germ=draws.nodes,
        )
        found.append((checked.corrected_mean[0], checked.corrected_mean_se[0]))
    means, errors = np.array(found).T
    assert abs(expansion.mean()[0] - truth) > 0.1
    assert means.mean() == pytest.approx(truth, abs=3 * means.std() / np.sqrt(400))
    assert np.mean(abs(means - truth) <= 1.645 * errors) >= 0.85


# -- verdicts with their noise -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("model", "inputs", "stop", "truth", "elements"),
    [
        (well, {"x0": pcmb.Uniform(-0.625, 0.375)}, 4.0, double_well, "auto"),
        # The quarters elements: auto reached when its estimate was 5x careful; it now stops
        # at three elements (20 runs), 3.7 % off, within the 5 % asked.
        (ball, {"h0": pcmb.Uniform(0.5, 1.5)}, 3.0, None, {"h0": [0.75, 1.0, 1.25]}),
    ],
)
def test_a_repaired_result_is_not_flagged_on_noise(model, inputs, stop, truth, elements):
    times = np.linspace(0.0, stop, 101)
    fine = TensorGrid(tuple(inputs.values()), (3999,))
    (name,) = model.outputs
    exact = truth(times, fine.params[:, 0]) if truth else bouncing_ball(fine.params[:, 0], times)
    mean = fine.weights @ exact
    std = np.sqrt(fine.weights @ (exact - mean) ** 2)
    for seed in range(10):
        result = _run(
            model,
            inputs,
            times,
            order=3,
            elements=elements,
            max_elements=4,
            seed=seed,
            validation=8,
        )
        # the elements repaired it to within 2 % (28 runs)...
        assert _true_error(result, name, mean, std).max() < 0.02
        # ... and 8 held-out runs, whose estimate may pass 5 % by chance, flag nothing.
        assert result.diagnostics[name].reliable, seed


def test_a_failing_expansion_is_still_flagged_near_its_true_crossing():
    times = np.linspace(0.0, 4.0, 201)
    inputs = {"x0": pcmb.Uniform(-0.625, 0.375)}
    fine = TensorGrid(tuple(inputs.values()), (3999,))
    exact = double_well(times, fine.params[:, 0])
    mean = fine.weights @ exact
    std = np.sqrt(fine.weights @ (exact - mean) ** 2)
    results = [_run(well, inputs, times, order=3, seed=seed, validation=64) for seed in range(5)]
    # The seed moves only the held-out runs: the expansion, and its true crossing, are one.
    crossing = verdict(times, _true_error(results[0], "x", mean, std), 0.05)
    for result in results:
        assert abs(result.diagnostics["x"].failing_from - crossing) <= 0.05 * times[-1]


def test_an_undecided_check_says_how_many_runs_would_decide():
    times = np.linspace(0.0, 4.0, 81)
    # An input the response ignores: two inputs, so the 8 runs are drawn, not placed.
    inputs = {"x0": pcmb.Uniform(-0.625, 0.375), "u": pcmb.Uniform(0.0, 1.0)}
    result = _run(well, inputs, times, order=3)
    found = result.diagnostics["x"]
    assert found.reliable and found.undecided.any()
    (record,) = [w for w in result.warnings if w.code == "chaos-undecided"]
    assert "cannot tell" in record.message and "8 held-out runs" in record.message
    assert "more held-out runs would decide (method.validation: " in record.message


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_an_estimate_at_the_tolerance_itself_is_not_promised_a_decision_by_one_more_run():
    # The pendulum of release angle θ0 ~ U[0.5, 2] at order 10: at t = 23.5 its estimated
    # error was 4.97 % ± 0.055 % (truth 5.3 %), undecided only as it sat within a tenth of the
    # tolerance of it. The record said "about 1 more held-out runs would decide
    # (method.validation: 9)"; with 9 runs t = 24 was undecided the same way (4.86 % ± 0.15 %).
    # Since the placed check's noise counts its convergence it decides there; judged at a
    # tolerance equal to its estimate where it flags, that time sits at the tolerance itself.
    found = CALIBRATION["_run_case"]("pendulum", "order 10", None).diagnostics["theta"]
    at = float(found.estimate[np.flatnonzero(found.estimate > found.tolerance)[0]])
    result = CALIBRATION["_run_case"]("pendulum", "order 10", at)
    (record,) = [w for w in result.warnings if w.code == "chaos-undecided"]
    assert "would decide" not in record.message
    assert "within a tenth of the tolerance" in record.message


# -- heavy tails -------------------------------------------------------------------------------


def test_a_lognormal_response_is_never_called_reliable_past_its_true_crossing():
    # x = exp(z t / 2) at Hermite order 4 (5 runs): its std passes 5 % of the largest at
    # t = 3.60 (closed form). Its 8 held-out runs, placed (Leja points reaching the tails),
    # flag it or call it undecided from then on (within 5 % of the horizon), with every seed.
    times = np.linspace(0.0, 5.0, 201)
    mean, std = lognormal_moments(0.5 * times)
    results = [
        _run(lognormal, {"z": pcmb.Normal(0.0, 1.0)}, times, order=4, seed=seed)
        for seed in range(10)
    ]
    crossing = verdict(times, _true_error(results[0], "x", mean, std), 0.05)  # one expansion
    assert crossing == pytest.approx(3.6, abs=times[1])
    for seed, result in enumerate(results):
        found = result.diagnostics["x"]
        warned = found.undecided | (times >= found.failing_from)
        assert warned[times >= crossing + 0.05 * times[-1]].all(), seed  # within 5 %
        assert not found.failing_from < crossing - 0.05 * times[-1], seed  # no false alarm
        # The point estimate itself crosses within 5 % of the horizon of the truth.
        assert abs(verdict(times, found.estimate, 0.05) - crossing) <= 0.05 * times[-1], seed


def test_a_response_linear_in_its_widened_normal_input_is_never_called_reliable_past_its_crossing():
    # x'' + c x' + k x = 0 from rest at x0 ~ N(1, 0.1²), k ~ U[0.5, 1.5], c ~ U[0.05, 0.25]
    # at order 4 (125 runs): its error passes 5 % of the largest std at t = 17 (the phase
    # drifts with k). x is linear in x0, whose germ is drawn from N(0, 4.2²); weighted back by
    # importance, seed 3's first 8 runs counted as 3 and called t = 18-30 reliable (std error
    # 0.8 % estimated at t = 22, truth 12 %). Judged by moment weights, it is flagged or
    # undecided from the crossing on.
    times = np.linspace(0.0, 30.0, 151)
    stiffness = (0.5, 1.5)
    mean, std = oscillator_moments(times, stiffness)
    result = _run(oscillator, oscillator_inputs(stiffness), times, order=4, seed=3)
    found = result.diagnostics["x"]
    crossing = verdict(times, _true_error(result, "x", mean, std), 0.05)
    assert crossing == pytest.approx(17.0, abs=times[1])
    warned = found.undecided | (times >= found.failing_from)
    assert warned[times >= crossing + 0.05 * times[-1]].all()
    assert not found.failing_from < crossing - 0.05 * times[-1]  # no false alarm
    assert result.held_out.ok.size <= held_out_budget(result.n_nodes)


# -- a one-input design checked by points placed to extend it -----------------------------------


@pytest.mark.parametrize(
    ("model", "inputs", "order", "stop", "crossing", "within"),
    [
        (lognormal, {"z": pcmb.Normal(0.0, 1.0)}, 4, 5.0, 3.60, 0.25),
        (well, {"x0": pcmb.Uniform(-0.625, 0.375)}, 3, 4.0, 2.16, 0.2),
    ],
)
def test_the_default_check_of_a_one_input_design_flags_on_time(
    model, inputs, order, stop, crossing, within
):
    # The true crossings: the lognormal's std by its closed form (asserted above), the
    # well's mean by a 4000-point Gauss rule of its closed form (issue 23's table).
    times = np.linspace(0.0, stop, 201)
    for seed in range(5):
        result = _run(model, inputs, times, order=order, seed=seed)
        found = result.diagnostics[model.outputs[0]]
        assert abs(found.failing_from - crossing) <= within, seed
        assert result.held_out.ok.size == held_out_budget(result.n_nodes) == 8


def test_a_one_input_design_places_its_whole_check_at_once():
    times = np.linspace(0.0, 1.0, 3)
    one = pcmb.Study(lognormal, {"z": pcmb.Normal(0.0, 1.0)}, times, order=39)
    assert one.places_held_out() and one.held_out_runs(40) == (10, 10)
    two = {"z": pcmb.Normal(0.0, 1.0), "u": pcmb.Uniform(0.0, 1.0)}
    assert pcmb.Study(lognormal, two, times, order=39).held_out_runs(1600) == (8, 400)
    # The seed moves drawn runs, not placed ones.
    placed = [_run(well, {"x0": pcmb.Uniform(-1, 1)}, times, order=3, seed=s) for s in (0, 1)]
    assert np.array_equal(placed[0].held_out.germ, placed[1].held_out.germ)


def test_placed_runs_make_the_interpolant_exact_for_a_polynomial_of_their_degree():
    # z⁶ at Hermite order 2 (3 nodes): mean 15 and std √(10395 - 225) (normal moments), which
    # nodes and 8 placed runs, a polynomial of degree 10, reproduce to round-off.
    grid = TensorGrid((pcmb.Normal(0.0, 1.0),), (2,))
    values = grid.nodes**6
    basis = grid.distributions[0].family.evaluate(grid.nodes[:, 0], 2)
    expansion = pcmb.ChaosExpansion(
        basis.T @ (grid.weights[:, None] * values), [[0], [1], [2]], grid.distributions
    )
    draws, weights = held_out_placed(grid.distributions[0], grid.nodes, 8)
    assert np.all(weights == 1) and not np.isin(draws.nodes, grid.nodes).any()
    found = placed_check(expansion, grid.nodes, values, draws.nodes, draws.nodes**6, 1.0)
    assert found.corrected_mean[0] == pytest.approx(15.0, rel=1e-9)
    assert found.corrected_std[0] == pytest.approx(np.sqrt(10395.0 - 225.0), rel=1e-9)
    assert found.mean_error[0] == pytest.approx(abs(15.0 - expansion.mean()[0]), rel=1e-9)
    assert found.spread[0] < 1e-6  # nothing moves without the last two: exact already


def test_the_unseen_mean_is_fitted_from_the_spectrum_s_peak_on():
    # sin(ω x + 1), x ~ U[-1, 1], ω = 10 and 12, at order 7 (8 Gauss nodes) and 8 placed
    # runs: the interpolant's Legendre energies rise to degree ~ω and fall fast after it.
    # Fitted from degree 1, the rise holds the line up: the estimates were 0.15 and 0.35 of
    # the largest std, 50 and 13 times the design's true mean errors (0.003 and 0.028: a
    # false alarm at 5 %); from the peak on 4.2 and 1.7 times. The truth: E sin(ω x + 1) =
    # sin(1) sin(ω) / ω.
    omegas = np.array([10.0, 12.0])
    grid = TensorGrid((pcmb.Uniform(-1.0, 1.0),), (7,))

    def response(germ):
        return np.sin(np.outer(np.ravel(germ), omegas) + 1.0)  # the germ is x here

    values = response(grid.nodes)
    basis = grid.distributions[0].family.evaluate(grid.nodes[:, 0], 7)
    expansion = pcmb.ChaosExpansion(
        basis.T @ (grid.weights[:, None] * values), [[p] for p in range(8)], grid.distributions
    )
    draws, _ = held_out_placed(grid.distributions[0], grid.nodes, 8)
    scale = float(expansion.std().max())
    found = placed_check(expansion, grid.nodes, values, draws.nodes, response(draws.nodes), scale)
    true = abs(expansion.mean() - np.sin(1.0) * np.sin(omegas) / omegas) / scale
    assert np.all(true <= found.mean_error) and np.all(found.mean_error <= 10 * true)


@pytest.mark.parametrize(
    ("settings", "at", "low"),
    [({"order": 7}, 3.14, 1 / 2), ({"grid": "smolyak", "level": 3}, 4.0, 1 / 4)],
)
def test_a_placed_check_sees_the_mean_error_of_a_gauss_design_beyond_its_held_out_degrees(
    settings, at, low
):
    # 8 placed runs beside N >= 8 Gauss (Gauss-Patterson) nodes: the interpolant's mean is the
    # design's own, so only the tail of the coefficients beyond its degree can tell the mean's
    # error (the double well's mean: its closed form, 5.1 % and 4.1 % of the largest std).
    # The tail is extrapolated from the interpolant's coefficients, which an interpolant through
    # a jump damps to about half the truth at its top degrees (docs/diagnostics.md): a factor 2
    # low; Smolyak's 23 points fit degrees 0-22 but its rule is exact to 23, so its tail starts
    # a degree later from coefficients damped once more: a factor 4. High: the larger of the two
    # fitted shapes (geometric, algebraic) overstates an algebraic tail by at most its halving
    # undone, a factor 2; a doubled or dropped tail fails.
    inputs = {"x0": pcmb.Uniform(-0.625, 0.375)}
    times = np.linspace(0.0, 4.0, 201)
    result = _run(well, inputs, times, **settings)
    found = result.diagnostics["x"]
    mean, _ = double_well_moments(times, -0.625, 0.375)
    k = np.searchsorted(times, at)
    true = abs(result.mean("x") - mean)[k] / found.scale
    assert low * true <= found.holdout.mean_error[k] <= 2 * true


def test_the_mean_error_of_a_lognormal_response_is_estimated_within_ten_times_the_truth():
    # exp(z t/2) at order 4 beside 8 placed runs: 13 points interpolate degrees the design's
    # 5-point rule does not integrate, so the interpolant measures the design's mean error itself
    # (its closed form: at most 1.05 % of the largest std, at t = 5). Issue 23 asks every
    # estimate within 10 times the truth either side; the extrapolated tail beyond degree 12
    # added to it once made 89 %.
    times = np.linspace(0.0, 5.0, 51)
    result = _run(lognormal, {"z": pcmb.Normal(0.0, 1.0)}, times, order=4)
    found = result.diagnostics["x"]
    mean, _ = lognormal_moments(0.5 * times)
    true = np.max(abs(result.mean("x") - mean)) / found.scale
    assert true / 10 <= np.max(found.holdout.mean_error) <= 10 * true


def _order_3_elements(cuts, function):
    """``function`` on U(-1, 1) cut at ``cuts``, projected at order 3 on each element's Gauss
    rule: the partition, the piecewise expansion, and the nodes' x, elements and germ."""
    partition = Partition.from_splits([pcmb.Uniform(-1.0, 1.0)], [cuts])
    coefficients, nodes = [], []
    for (conditional,) in partition.inputs:
        grid = TensorGrid((conditional,), (3,))
        basis = conditional.family.evaluate(grid.nodes[:, 0], 3)
        coefficients.append(grid.weights @ (basis * function(grid.params)))
        nodes.append(grid.params[:, 0])
    expansion = PiecewiseExpansion(partition, np.array(coefficients)[..., None], np.c_[:4])
    physical = np.concatenate(nodes)
    where = partition.locate(physical[:, None])
    return partition, expansion, physical, where, partition.distributions[0].to_germ(physical)


def test_an_element_with_fewer_placed_runs_than_the_spare_leaves_out_only_those():
    # Two elements of x³ on (-1, 1) at order 3 (exact in each) and 3 placed runs, 2 and 1: the
    # noise leaves out at most the element's own runs, never its nodes: the interpolant stays.
    partition, expansion, physical, where, germ = _order_3_elements([0.0], lambda x: x**3)
    draws, _ = held_out_placed_elements(partition, germ, where, [1.0, 0.5], 3)
    assert np.bincount(partition.locate(draws.params)).tolist() == [2, 1]
    found = placed_check(expansion, germ, physical[:, None] ** 3, draws.nodes, draws.params**3, 1.0)
    assert found.corrected_mean[0] == pytest.approx(0.0, abs=1e-12)
    assert found.corrected_std[0] == pytest.approx(np.sqrt(1.0 / 7.0), rel=1e-12)
    assert found.corrected_std_se[0] < 1e-12 and found.upper[0] - found.error[0] < 1e-12


def test_an_element_without_placed_runs_extrapolates_no_tail_from_its_own_three_degrees():
    # (x - 1/2)² on (-1, 1) in two elements at order 3 (exact in each: its mean 7/12), both
    # placed runs in the first: the second's only degrees 1-3 (0, c₂, 0) cannot tell how its
    # spectrum decays; a line through their two neighbour averages is flat and once put the
    # 4-point rule's errors on degrees 8-12 into the mean: 0.037, 6 % of its std 0.65 (the MR
    # damper's remedy, issue 23).
    partition, expansion, physical, where, germ = _order_3_elements([0.0], lambda x: (x - 0.5) ** 2)
    draws, _ = held_out_placed_elements(partition, germ, where, [1.0, 0.0], 2)
    assert np.bincount(partition.locate(draws.params), minlength=2).tolist() == [2, 0]
    values, observed = (physical[:, None] - 0.5) ** 2, (draws.params - 0.5) ** 2
    found = placed_check(expansion, germ, values, draws.nodes, observed, 1.0)
    assert found.corrected_mean[0] == pytest.approx(7.0 / 12.0, rel=1e-12)
    assert found.mean_error[0] < 1e-12


def test_an_element_without_placed_runs_leaves_the_check_undecided_not_reliable():
    # |x - 0.3| on (-1, 1) cut at 0, order 3: the first element is linear (exact), the second
    # holds the kink. All 4 placed runs forced into the first: the second is unchecked, and
    # its share once counted as zero error (estimates 2e-16 against true errors of the mean
    # and std of 0.0135 and 0.0204 of the largest std, closed forms). Its share is now noise.
    partition, expansion, physical, where, germ = _order_3_elements([0.0], lambda x: abs(x - 0.3))
    draws, _ = held_out_placed_elements(partition, germ, where, [1.0, 0.0], 4)
    assert np.bincount(partition.locate(draws.params), minlength=2).tolist() == [4, 0]
    scale = float(expansion.std()[0])
    values, observed = abs(physical[:, None] - 0.3), abs(draws.params - 0.3)
    found = placed_check(expansion, germ, values, draws.nodes, observed, scale)
    mean, square = (1.3**2 + 0.7**2) / 4, (1.3**3 + 0.7**3) / 6
    true = max(abs(expansion.mean()[0] - mean), abs(expansion.std()[0] - np.sqrt(square - mean**2)))
    assert true / scale == pytest.approx(0.0204, abs=1e-4)
    # Not called reliable at a tolerance the truth passes (estimate + noise above the true
    # error), not flagged at one it does not (0.05), uncertain by less than 10 times the truth.
    assert found.statistics[0] + found.noise[0] > true / scale
    assert np.isnan(verdict(np.zeros(1), found.statistics, 0.05, found.noise))
    assert found.noise[0] < 10 * true / scale


@pytest.mark.parametrize(("order", "tolerance"), [(2, 1e-4), (3, 1e-3), (5, 1e-3)])
def test_a_kink_in_a_sliver_no_node_reaches_is_never_called_reliable(order, tolerance):
    # exp(x) + 2 max(x - 1/√5, 0) on (-1, 1) with elements: auto, whose own estimate reads
    # 0.03-0.08 times the true error (the kink sits between an element's last node and its
    # edge; docs/multi_element.md): the default placed check, whose Leja points start at the
    # elements' edges, sees it (true errors 15, 4.2 and 8.1 times the tolerance: undecided,
    # flagged, undecided). Truth: exact moments of the two analytic pieces.
    cut = 1 / np.sqrt(5)

    @pcmb.batched(outputs=("y",))
    def kinked(params, times):
        x = np.asarray(params["x"])
        return {"y": np.outer(np.exp(x) + 2 * np.maximum(x - cut, 0.0), np.ones_like(times))}

    mean = (np.e - np.exp(-1) + (1 - cut) ** 2) / 2
    square = (np.e**2 - np.exp(-2)) / 4 + 2 * (np.exp(cut) - cut * np.e) + 2 * (1 - cut) ** 3 / 3
    times = np.zeros(1)
    result = _run(
        kinked,
        {"x": pcmb.Uniform(-1.0, 1.0)},
        times,
        order=order,
        elements="auto",
        diagnostics={"tolerance": tolerance},
    )
    found = result.diagnostics["y"]
    true = _true_error(result, "y", mean, np.sqrt(square - mean**2))
    assert true[0] > tolerance  # elements: auto stopped short of its tolerance
    assert found.estimate[0] + found.noise[0] > tolerance  # flagged or undecided


def test_an_element_whose_top_coefficient_a_parity_zeroes_is_neither_skipped_nor_exact():
    # |x| on (-1, 1) cut at ±0.5, order 3: the outer elements are linear (exact), the middle
    # one holds the kink, and |x| is even there: its top (odd) coefficient is 0 and read it
    # as needing no run (importance 0) and, without runs, as exact (estimate and noise
    # 1e-16 against a true std error of 0.034 of the largest std; closed forms: 1/2, 1/12).
    partition, expansion, physical, where, germ = _order_3_elements([-0.5, 0.5], abs)
    values = abs(physical[:, None])
    importance = element_importance(partition, germ, where, {"y": values})
    assert importance[1] > 1e6 * max(importance[0], importance[2])
    scale = float(expansion.std()[0])
    true = abs(expansion.std()[0] - np.sqrt(1 / 12)) / scale
    assert true == pytest.approx(0.034, abs=1e-3)
    draws, _ = held_out_placed_elements(partition, germ, where, [1.0, 0.0, 1.0], 4)
    found = placed_check(expansion, germ, values, draws.nodes, abs(draws.params), scale)
    assert true < found.statistics[0] + found.noise[0] < 10 * true


def test_the_noise_is_the_spread_times_the_normal_quantile():
    found = HeldOutCheck(*[np.full(1, 0.5)] * 9, count=8, confidence=0.975)
    assert found.noise[0] == pytest.approx(0.5 * 1.959963984540054, rel=1e-12)


@pytest.mark.parametrize("settings", [{"order": 7}, {"order": 3}])
def test_the_corrected_mean_carries_the_noise_the_verdict_weighs(settings):
    # One noise for the mean's estimate: where the mean's error is the larger, the corrected
    # mean's standard error is the verdict's spread plus the unseen mean (a bias, >= 0).
    times = np.linspace(0.0, 4.0, 41)
    found = _run(well, {"x0": pcmb.Uniform(-0.625, 0.375)}, times, **settings).diagnostics["x"]
    mean_larger = found.holdout.mean_error >= found.holdout.std_error
    assert mean_larger.any()
    se = found.holdout.corrected_mean_se / found.scale
    assert np.all(se[mean_larger] >= found.holdout.spread[mean_larger] * (1 - 1e-12))


def test_the_file_says_whether_the_check_was_placed_or_drawn(tmp_path, capsys):
    times = np.linspace(0.0, 1.0, 11)
    one = {"x0": pcmb.Uniform(-0.625, 0.375)}
    two = {**one, "u": pcmb.Uniform(0.0, 1.0)}
    for name, inputs, word in (("one", one, "placed"), ("two", two, "drawn")):
        pcmb.Study(well, inputs, times, order=3, backend="inprocess").run(tmp_path / f"{name}.h5")
        held_out = pcmb.load(tmp_path / f"{name}.h5").held_out
        assert held_out.placed == (word == "placed")
        assert main(["inspect", str(tmp_path / f"{name}.h5")]) == 0
        assert f"({held_out.ok.size} {word} held-out runs)" in capsys.readouterr().out


def test_a_multi_element_design_places_its_check_per_element_and_flags_on_time():
    # exp(z t / 2) at order 4 with elements: auto held to 8 elements (75 runs): its std
    # passes 5 % of the largest std at t = 4.78 (the lognormal moments); drawn runs missed it.
    times = np.linspace(0.0, 5.0, 201)
    inputs = {"z": pcmb.Normal(0.0, 1.0)}
    mean, std = lognormal_moments(0.5 * times)
    for seed in range(5):  # drawn, 19 runs flagged it with 1 seed of these 5
        result = _run(lognormal, inputs, times, order=4, elements="auto", max_elements=8, seed=seed)
        crossing = verdict(times, _true_error(result, "x", mean, std), 0.05)
        assert crossing == pytest.approx(4.78, abs=0.03)
        assert abs(result.diagnostics["x"].failing_from - crossing) <= 0.25, seed
    assert result.held_out.placed and result.held_out.ok.size <= held_out_budget(result.n_nodes)


def test_the_verdict_weighs_the_noise_of_the_larger_estimate():
    # 64 runs of f = sign(s) √(s² + 0.44) about the surrogate s = z ~ N(0, 1) (mean 0, std
    # 1): f² - s² = 0.44 at every run, so the std's error (√1.44 - 1 = 0.2) is known without
    # noise, while the mean's correction Σ (f - s) / K is right (0) but noisy. The verdict
    # judges the std's error, with the std's noise.
    z = np.random.default_rng(3).standard_normal((64, 1))
    found = holdout_error(z, np.sign(z) * np.sqrt(z**2 + 0.44), np.zeros(1), np.ones(1), 1.0)
    assert found.std_error[0] == pytest.approx(0.2, abs=0.01) and found.mean_error[0] < 0.1
    assert found.spread[0] == pytest.approx(found.corrected_std_se[0])


@pytest.mark.parametrize("design_runs", [1, 4, 32, 33, 75, 105, 125, 1000])
def test_the_default_check_makes_at_most_a_quarter_of_the_design_or_eight(design_runs):
    # Issue 23: "at most max(8, 1/4 of the design's runs)"; 105 runs may not get 27.
    assert held_out_budget(design_runs) == max(8, design_runs // 4)


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize("table", ["mean_error_rows", "decay_rows"])
def test_the_calibration_reads_the_truth_at_the_tolerance_the_study_s_verdict_uses(table):
    # The sliver's studies judge at 1e-3 and 1e-4 (diagnostics.tolerance): --mean-error once
    # looked for the truth's crossing of 0.05, never reached (0.15-0.81 % at most), and
    # printed the last time, 1, instead of the crossings docs/diagnostics.md gives; --decay
    # reads the decay against the same crossings.
    rows = CALIBRATION[table]("sliver", None)
    assert [float(row.split()[-5]) for row in rows] == [0.67, 0.07, 0.24, 0.13]


def test_a_switch_the_design_has_not_seen_yet_is_no_false_alarm_where_the_check_sees_it_holds():
    # x' = -x + H(t - τ), τ ~ U[1, 3], order 4: just after t = 1 the 5 Gauss nodes are all
    # still off while the placed run at τ = 1 is on; the true error never reaches 5 % of the
    # largest std (4.7 % at most, at t = 2), the check's estimate at t = 1.05 is 1.5 % ± 0.2 %.
    # It was flagged from 1.05, as the design's runs are all equal there.
    *_, times, exact, _ = CALIBRATION["CASES"]["switch"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)  # sobol-undefined before t = 1
        result = CALIBRATION["_run_case"]("switch", "order 4", None)
    mean, std = exact(times)
    assert 0.04 < _true_error(result, "x", mean, std).max() < TOLERANCE
    assert result.diagnostics["x"].reliable
    assert "chaos-unreliable" not in {w.code for w in result.warnings}
