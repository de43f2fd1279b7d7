"""Heavy tails of several normal inputs: along a direction, the drawn check's estimate may not
call a time reliable where its draws missed the tails that carry the variance
(``docs/diagnostics.md``, 'Heavy tails along a direction'); along one input, the held-out runs
are placed along it ('A tail along one input: placed along it')."""

from __future__ import annotations

import re

import numpy as np
import pytest

import pcmb
from pcmb.analysis.diagnostics import HELD_OUT_SEED, diagnose, held_out_draws
from pcmb.analysis.diagnostics.draws import coverage_error

pytestmark = pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")

TIMES = np.linspace(0.0, 4.0, 81)
NORMAL = pcmb.Normal(0.0, 1.0)


@pcmb.batched(outputs=("y",))
def _diagonal(params, times):
    """exp(0.4 (z1 + z2) t): lognormal along (1, 1)/√2, its variance at u = (z1 + z2)/√2 ≈ 4."""
    return {"y": np.exp(0.4 * np.outer(np.asarray(params["x1"]) + params["x2"], times))}


def test_draws_that_miss_the_tails_along_a_direction_leave_the_time_undecided():
    """Tensor order 4 (25 runs) and the default drawn check of 8 (the budget: no second
    batch), method seeds 0-19: the std's error passes 5 % of the largest std at t = 3.5
    (lognormal moments). A time past it is called reliable in at most 4 seeds: the binomial
    96 % bound (P(<= 4 of 20) = 0.957) of the 10 % the one-sided 90 % confidence allows;
    measured, 2 of seeds 0-39 (14 and 30), 5 %. Before, 8 seeds of 20 did, their estimates
    0.3-1.3 % ± 0.5-1.9 % at t = 3.5 where the truth is 5.3 %: their 8 draws recovered
    4-30 % of the surrogate's own variance (or twice it), which the check now weighs
    (coverage_error)."""
    inputs = {"x1": NORMAL, "x2": NORMAL}
    study = pcmb.Study(_diagonal, inputs, TIMES, backend="inprocess", order=4, validation=0)
    result = study.run(progress=False)
    expansion = result.expansions["y"]
    mean = np.exp(0.16 * TIMES**2)
    std = np.sqrt(np.exp(0.64 * TIMES**2) - np.exp(0.32 * TIMES**2))
    true = np.fmax(abs(expansion.mean() - mean), abs(expansion.std() - std))
    error = true / np.max(expansion.std())
    assert TIMES[np.argmax(error > 0.05)] == 3.5
    silent = []
    for seed in range(20):
        draws, weights = held_out_draws(tuple(inputs.values()), 8, seed + HELD_OUT_SEED)
        observed = _diagonal(dict(zip(inputs, draws.params.T, strict=True)), TIMES)["y"]
        found = diagnose(
            "y",
            expansion,
            result.values["y"],
            TIMES,
            (expansion.evaluate_germ(draws.nodes), observed),
            node_germ=result.germ,
            holdout_germ=draws.nodes,
            weights=weights,
        )
        judged = found.undecided | (found.failing_from <= TIMES)
        if np.any((error > 0.05) & ~judged):
            silent.append(seed)
    assert len(silent) <= 4, silent


def test_the_coverage_error_is_the_missed_share_of_the_variance_times_the_outer_energy():
    # s = ψ1 + ψ4 of one normal input at order 4: σ² = 2, its outer layers (degrees 3 and 4)
    # hold E = 1. Draws where s = μ recover none of σ²: (1 - 0) E / σ = 1/√2; draws that
    # recover it all (or more), or where the model equals s, nothing.
    expansion = pcmb.ChaosExpansion(
        [[0.0], [1.0], [0.0], [0.0], [1.0]], [[p] for p in range(5)], (NORMAL,)
    )
    model = np.ones((4, 1))
    blind = coverage_error(expansion, np.zeros((4, 1)), model, np.ones(4), 1.0)
    assert blind == pytest.approx([2**-0.5])
    seeing = coverage_error(expansion, np.full((4, 1), 2.0), model, np.ones(4), 1.0)
    assert seeing == pytest.approx([0.0])
    assert coverage_error(expansion, np.zeros((4, 1)), np.zeros((4, 1)), None, 1.0) == [0.0]


def test_the_outer_energy_is_weighted_by_how_slowly_the_spectrum_falls():
    # s = ψ1 + ψ2/2 + ψ3/4 + ψ4/8 of one normal input: energies 1, 1/4, 1/16, 1/64, so
    # σ² = 85/64, the outer layers hold E = 5/64 and fall at r = (1/64 + 1/16) / (1/16 + 1/4)
    # = 1/4, weighted r / (1 - r) = 1/3: draws that recover none of σ² miss
    # (5/64) (1/3) / (√85 / 8) = 5 / (24 √85).
    expansion = pcmb.ChaosExpansion(
        [[0.0], [1.0], [0.5], [0.25], [0.125]], [[p] for p in range(5)], (NORMAL,)
    )
    blind = coverage_error(expansion, np.zeros((4, 1)), np.ones((4, 1)), np.ones(4), 1.0)
    assert blind == pytest.approx([5.0 / (24.0 * np.sqrt(85.0))])


def test_no_coverage_error_where_the_surrogate_is_linear_in_the_normal_inputs_or_has_none():
    # Linear along the normal input (a damped oscillator in its initial displacement), or no
    # normal input: the widened draws have no tail to miss.
    uniform = pcmb.Uniform(-1.0, 1.0)
    index = [[0, 0], [1, 0], [0, 1], [2, 0], [0, 2], [3, 0], [0, 3]]
    coefficients = np.array([[1.0], [0.5], [1.0], [0.3], [0.0], [0.1], [0.0]])
    linear = pcmb.ChaosExpansion(coefficients, index, (uniform, NORMAL))
    plain = pcmb.ChaosExpansion(coefficients, index, (uniform, uniform))
    for expansion in (linear, plain):
        found = coverage_error(expansion, np.ones((4, 1)), np.zeros((4, 1)), np.ones(4), 1.0)
        assert found == pytest.approx([0.0])


@pytest.mark.parametrize("offset", [0.0, 1e5, 1e8])
def test_an_exact_polynomial_on_a_large_baseline_is_vouched_for(offset):
    # y = c + a t + b², a, b ~ N(0, 1), at order 3: the surrogate is exact, its residuals
    # round-off of the output's size, not of its std's. Before, at c = 1e5 the residual's
    # 4e-11 of the std passed for an error: the coverage error widened the noise to 0.18
    # and every time was undecided.
    @pcmb.batched(outputs=("y",))
    def baseline(params, times):
        a, b = np.asarray(params["a"]), np.asarray(params["b"])
        return {"y": offset + np.outer(a, times) + (b**2)[:, None]}

    inputs = {"a": NORMAL, "b": NORMAL}
    study = pcmb.Study(baseline, inputs, TIMES[:21], backend="inprocess", order=3, validation=8)
    found = study.run(progress=False).diagnostics["y"]
    assert found.vouched
    assert np.max(found.noise) < 1e-6


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_an_undecided_check_far_from_deciding_names_what_makes_its_noise_smaller():
    """exp(0.4 (z1 + z2) t) at order 4 (25 runs, 8 drawn): at t = 4 the estimate is 98 % ±
    124 % of the scale, and about 1,149 more held-out runs would decide, 140 times those made.
    The record says so, and that the noise is the surrogate's own error's spread, which a
    finer design makes smaller (before: only the count)."""
    times = np.linspace(0.0, 4.0, 81)
    inputs = {"x1": pcmb.Normal(0.0, 1.0), "x2": pcmb.Normal(0.0, 1.0)}
    result = pcmb.Study(_diagonal, inputs, times, order=4, seed=0, backend="inprocess").run()
    (record,) = [w for w in result.warnings if w.code == "chaos-undecided"]
    more = int(re.search(r"about (\d+) more held-out runs", record.message).group(1))
    assert more > 10 * result.diagnostics["y"].holdout.count
    assert "a finer design (a higher order, or elements) makes smaller" in record.message


@pcmb.batched(outputs=("y",))
def _along_one(params, times):
    """exp(0.3 z1 t) (1 + 0.3 z2²): a lognormal tail along z1, scaled by an even factor of z2."""
    z1, z2 = np.asarray(params["x1"]), np.asarray(params["x2"])
    return {"y": np.exp(0.3 * np.outer(z1, times)) * (1 + 0.3 * z2**2)[:, None]}


def _along_one_error(result: pcmb.StudyResult, times: np.ndarray) -> np.ndarray:
    """The true error of mean and std over the largest std: mean 1.3 e^{a²/2} and
    E y² = E(1 + 0.3 z²)² e^{2a²} = 1.87 e^{2a²}, a = 0.3 t."""
    a = 0.3 * times
    mean = 1.3 * np.exp(a * a / 2)
    std = np.sqrt(1.87 * np.exp(2 * a * a) - mean**2)
    found = result.diagnostics["y"]
    return np.fmax(abs(result.mean("y") - mean), abs(result.std("y") - std)) / found.scale


@pytest.mark.parametrize("order", [4, 6])
def test_a_tail_along_one_of_two_normal_inputs_is_flagged_where_the_truth_crosses(order):
    """Tensor orders 4 and 6 (25 and 49 runs) to t = 7 (closed form): the std's error passes 5 %
    at t = 5.4 and 6.3. The check's 8 runs (the budget, max(8, ¼ of the design) for 25; 12 for
    49, the line check's first batch 8) are placed along z1, which carries the tail (the
    expansion's outer energy lies in z1's own terms: 90 % at order 4), and the flag comes
    within 5 % of the horizon of the crossing, no time past it called reliable. Before, 8
    drawn runs reached z1 ≈ 2.7-4 once or not at all, and seeds 0-2 at order 4 never flagged
    (undecided from t = 4.5-5.15)."""
    times = np.linspace(0.0, 7.0, 141)
    inputs = {"x1": NORMAL, "x2": NORMAL}
    method = {"kind": "collocation", "order": order}
    result = pcmb.Study(_along_one, inputs, times, method=method, backend="inprocess").run()
    error = _along_one_error(result, times)
    crossing = times[np.argmax(error > 0.05)]
    assert crossing == pytest.approx({4: 5.4, 6: 6.3}[order])
    found = result.diagnostics["y"]
    assert result.held_out.ok.size == 8
    assert abs(found.failing_from - crossing) <= 0.05 * times[-1], found.failing_from
    holding = found.undecided | (times >= found.failing_from)
    assert not np.any((error > 0.05) & ~holding)


def test_the_line_check_corrects_the_std_of_a_tail_along_one_input():
    """exp(0.3 z1 t) (1 + 0.3 z2²) at tensor order 4: where the expansion's std errs by more
    than 5 % of the largest std (t = 5.4-7: up to 92 %), the corrected std is within a tenth of
    that error of the closed form: the interpolant of the line z2 = 0 through the 5 nodes and 8
    runs resolves exp(0.3 z1 t) to degree 12, and the z2 profile of the expansion's top layers
    along z1, 1 + 0.3 z2², carries it to z2 exactly (measured: 0.3-2.6 % of the error left).
    Before, 8 drawn runs (seed 0) left up to 87 % of it."""
    times = np.linspace(0.0, 7.0, 141)
    inputs = {"x1": NORMAL, "x2": NORMAL}
    result = pcmb.Study(_along_one, inputs, times, order=4, backend="inprocess").run()
    a = 0.3 * times
    std = np.sqrt(1.87 * np.exp(2 * a * a) - 1.69 * np.exp(a * a))
    failing = _along_one_error(result, times) > 0.05
    corrected = result.diagnostics["y"].holdout.corrected_std
    off = abs(corrected - std)[failing]
    assert np.all(off <= 0.1 * abs(result.std("y") - std)[failing])


@pcmb.batched(outputs=("y",))
def _odd_factor(params, times):
    """exp(0.4 z1 t) z2: zero on the line z2 = 0, where a check along z1 would see nothing."""
    z1, z2 = np.asarray(params["x1"]), np.asarray(params["x2"])
    return {"y": np.exp(0.4 * np.outer(z1, times)) * z2[:, None]}


@pytest.mark.parametrize("model", [_odd_factor, _diagonal])
def test_a_tail_not_along_one_input_keeps_the_drawn_check(model):
    """exp(0.4 z1 t) z2 (its tail in the terms of both inputs: a line through the centre sees
    y = 0) and exp(0.4 (z1 + z2) t) (along a direction), order 4: the expansion's outer energy
    does not lie in one input's own terms (0 and 5 %), so the held-out runs are drawn as
    before, not placed along a line that would read an error of 0 or a few % of the truth."""
    inputs = {"x1": NORMAL, "x2": NORMAL}
    result = pcmb.Study(model, inputs, TIMES, order=4, backend="inprocess").run()
    assert not result.held_out.placed
    assert result.diagnostics["y"].estimated_by == "held-out"
