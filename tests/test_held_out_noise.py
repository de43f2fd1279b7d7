"""The noise of the held-out check's estimate: its standard error (the ``spread``) against the
scatter of the estimate over many Latin-hypercube draws, where the truth is known (issue 23,
item 4: flag only where the estimate passes the tolerance by more than its noise).

References: y = (1 + 0.3 b) / (1.05 - a), a ~ U[0, 1], b ~ U[-1, 1], has mean ln(1.05 / 0.05)
and second moment (1 / 0.05 - 1 / 1.05)(1 + 0.09 / 3) in closed form; |a - 0.3| + b by a
Gauss-Legendre rule split at the kink.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

import pcmb
from pcmb.analysis.diagnostics import (
    CONFIDENCE,
    HELD_OUT_SEED,
    diagnose,
    held_out_draws,
    holdout_error,
    more_runs,
)
from pcmb.analysis.diagnostics.check import STANDARD_NORMAL
from pcmb.analysis.diagnostics.draws import unseen_region_error
from pcmb.analysis.diagnostics.verdict import flag_margin
from pcmb.chaos.nodes import TensorGrid, random_nodes
from pcmb.held_out import HeldOutPlan

#: The held-out runs the pole case's sequential check ends with at tolerance 1e-3.
POLE_RUNS = 56
SEEDS = 200


def _pole(a, b):
    return (1 + 0.3 * b) / (1.05 - a)


def _smooth(a, b):
    return np.exp(a + b / 2)


def _kink(a, b):
    return np.abs(a - 0.3) + b


def _study(response, method, tolerance, path):
    @pcmb.batched(outputs=("y",))
    def model(params, times):
        return {"y": response(params["a"], params["b"])[:, None]}

    inputs = {"a": pcmb.Uniform(0, 1), "b": pcmb.Uniform(-1, 1)}
    study = pcmb.Study(
        model,
        inputs,
        np.zeros(1),
        method=method,
        execution={"backend": "inprocess"},
        diagnostics={"tolerance": tolerance},
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return study.run(path)


def _pole_moments():
    mean = math.log(1.05 / 0.05)
    second = (1 / 0.05 - 1 / 1.05) * (1 + 0.09 / 3)
    return mean, math.sqrt(second - mean * mean)


def _flag_share(result, response, count, tolerance):
    """The share of SEEDS held-out checks of ``count`` runs that flag at ``tolerance``, each
    judged as the study judges its own (the held-out values stand in for the design's, which
    only the range checks read)."""
    expansion = result.expansions["y"]
    flags = []
    for seed in range(SEEDS):
        nodes, weights = held_out_draws(expansion.distributions, count, seed)
        observed = response(nodes.params[:, 0], nodes.params[:, 1])[:, None]
        predicted = expansion.evaluate_germ(nodes.nodes)
        found = diagnose(
            "y",
            expansion,
            observed,
            [0.0],
            (predicted, observed),
            tolerance,
            holdout_germ=nodes.nodes,
            weights=weights,
        )
        flags.append(not found.reliable)
    return float(np.mean(flags))


@pytest.fixture(scope="module")
def pole(tmp_path_factory):
    path = tmp_path_factory.mktemp("pole") / "pole.h5"
    return _study(_pole, {"kind": "collocation", "order": "auto"}, 1e-3, path)


def test_pole_within_tolerance_is_not_flagged(pole):
    """The spike of the residual near a = 1 made the std's paired standard error 3 times too
    small (0.076 % against a scatter of 0.22 %): "std off by an estimated 0.31 %" was flagged
    at tolerance 1e-3 with a true error of 2.9e-5."""
    mean, std = _pole_moments()
    assert abs(pole.std("y")[0] - std) / std < 1e-4  # the truth is far below the tolerance
    assert abs(pole.mean("y")[0] - mean) / std < 1e-4
    assert "chaos-unreliable" not in [record.code for record in pole.warnings]


def test_pole_false_alarms_at_most_the_confidence(pole):
    """Over 200 Latin hypercubes of 56 runs a true error 30 times below the tolerance is
    flagged at most as often as the one-sided confidence allows (10 %; 18 % before). The rate
    is 5.25 % over 2,000 (6.5 % here): the ceiling lies 3.0 of the 200 draws' binomial
    standard errors above it."""
    assert _flag_share(pole, _pole, POLE_RUNS, 1e-3) <= 1 - CONFIDENCE


def test_kink_mean_keeps_its_paired_standard_error(tmp_path):
    """The residual of |a - 0.3| + b at order 4 depends on a alone and its neighbouring pairs
    along a share it evenly: their standard error of the mean stands (6 times below sd/√K at
    K = 56), so a mean error 3 times the tolerance is flagged in most draws."""
    result = _study(
        _kink, {"kind": "collocation", "order": 4, "validation": 0}, 0.05, tmp_path / "kink.h5"
    )
    rule, weights = np.polynomial.legendre.leggauss(200)
    a = np.concatenate([0.15 * (rule + 1), 0.3 + 0.35 * (rule + 1)])
    w = np.concatenate([0.15 * weights, 0.35 * weights])
    true_mean = float(w @ np.abs(a - 0.3))
    std = float(result.std("y")[0])
    error = abs(result.mean("y")[0] - true_mean) / std
    assert error > 3e-3
    assert _flag_share(result, _kink, POLE_RUNS, error / 3) >= 0.5


def test_error_far_below_noise_flags_at_most_the_confidence(tmp_path):
    """exp(a + b/2) at order 4 is off by 2.4e-9 of its std, far below a tolerance of 1e-7
    that is itself far below the noise of 16 runs (9e-6): |estimate| passes the tolerance by
    1.28 standard errors on either side of the truth, twice as often as the one-sided
    confidence allows (19.5 % of 200 checks), unless the margin is that of the sign-free
    estimate (7 %). The code is at its limit here: over 2,000 checks the rate is 8.8 %
    (± 0.6 %), the margin being exact only for a known standard error (16 runs estimate it),
    so other sets of 200 draws pass 10 % about one time in four."""
    result = _study(
        _smooth, {"kind": "collocation", "order": 4, "validation": 0}, 0.05, tmp_path / "s.h5"
    )
    assert _flag_share(result, _smooth, 16, 1e-7) <= 1 - CONFIDENCE


@pytest.mark.xfail(
    strict=True,
    reason="the margin takes the standard error as known (the normal's 1.28-1.64 of it), where "
    "one read from the same 10 runs makes (estimate - truth) / standard error Student's t of 9 "
    "degrees of freedom: 11.5 % and 11.6 % flagged; its quantiles (1.38-1.83) give 10.1 % and "
    "9.8 %, but flagged later on the drawn families (cosine order 7, oscillator_wide order 3, "
    "largest: a timely flag each of 30 seeds lost): measured and not kept (docs/diagnostics.md)",
)
@pytest.mark.parametrize("noise", [0.2, 1.0])
def test_a_drawn_error_at_the_tolerance_is_flagged_at_most_at_the_confidence(noise):
    """10 independent runs whose residual is N(e, σ²), its mean e the tolerance itself and the
    standard error σ/√10 ``noise`` times it (0.2: the one-sided margin; 1: the sign-free one):
    over 20,000 checks (columns) the flag passes in at most 1 - confidence of them, plus 3
    binomial standard errors (0.64 %)."""
    runs, checks, tolerance = 10, 20_000, 0.05
    rng = np.random.default_rng(0)
    sigma = noise * tolerance * math.sqrt(runs)
    residual = tolerance + sigma * rng.standard_normal((runs, checks))
    found = holdout_error(
        np.zeros((runs, checks)), residual, np.zeros(checks), np.ones(checks), 1.0
    )
    flagged = found.statistics - flag_margin(found, tolerance) > tolerance
    binomial = math.sqrt(CONFIDENCE * (1 - CONFIDENCE) / checks)
    assert flagged.mean() <= 1 - CONFIDENCE + 3 * binomial, flagged.mean()


def test_two_batches_of_draws_are_not_paired_as_one_latin_hypercube(tmp_path):
    """A second batch of held-out draws joins the first: each is a Latin hypercube, their union
    is not, and pairing neighbours across it understated the noise (|x1| |x2| (1 + t), order 7,
    tolerance 0.02: 3 flags of 10 seeds 5-35 % of the horizon early, none with one batch of 16;
    tests/test_economy_contract.py). The joined runs say how many batches they hold, the file
    keeps it, and their noise is that of independent draws."""
    from pcmb.analysis.diagnostics import HeldOut, holdout_error
    from pcmb.chaos.expansion import ChaosExpansion
    from pcmb.chaos.nodes import TensorGrid
    from pcmb.chaos.recovery import project_tensor

    inputs = (pcmb.Uniform(-1.0, 1.0), pcmb.Uniform(-1.0, 1.0))
    grid = TensorGrid(inputs, (4, 4))
    times = np.linspace(0.0, 1.0, 3)

    def response(germ):
        return np.abs(germ[:, :1]) * np.abs(germ[:, 1:]) * (1 + times)

    expansion = ChaosExpansion(
        project_tensor(grid, response(grid.nodes), grid.multi_index), grid.multi_index, inputs
    )
    batches = []
    for seed in (1, 2):
        draws, weights = held_out_draws(inputs, 8, seed)
        values = {"y": response(draws.nodes)}
        batches.append(HeldOut(seed, draws.nodes, draws.params, values, np.ones(8, bool), weights))
    joined = batches[0].joined(batches[1])
    assert joined.batches == 2
    found = diagnose(
        "y",
        expansion,
        response(grid.nodes),
        times,
        (expansion.evaluate_germ(joined.germ), joined.values["y"]),
        holdout_germ=joined.germ,
        weights=joined.weights,
        stratified=joined.batches == 1,
    )
    plain = holdout_error(
        expansion.evaluate_germ(joined.germ),
        joined.values["y"],
        expansion.mean(),
        expansion.std(),
        found.scale,
        weights=joined.weights,
    )
    np.testing.assert_allclose(found.noise, plain.noise)


@pcmb.batched(outputs=("y",))
def _kinks(params, times):
    """|x1| |x2| (1 + t)."""
    x1, x2 = (np.asarray(params[name])[:, None] for name in ("x1", "x2"))
    return {"y": np.abs(x1) * np.abs(x2) * (1 + times)}


def _kinks_plan(inputs, seed):
    """The held-out plan of :func:`_kinks` at tensor order 7 (64 runs) and its design's germ
    points: a first batch of 8 draws and at most 16 in all."""
    study = pcmb.Study(_kinks, inputs, np.zeros(1), method={"kind": "collocation", "order": 7})
    grid = TensorGrid(tuple(study.inputs.values()), (7, 7))
    return HeldOutPlan(study.design, study.inputs, seed, None), grid.nodes


@pytest.mark.parametrize("seed", [0, 7, 26])
def test_a_second_batch_of_uniform_draws_completes_one_latin_hypercube(seed):
    """The sequential check's second batch fills the slices of a Latin hypercube of 16 that its
    first 8 draws leave empty, so that the 16 runs stratify every input as one Latin hypercube
    does (two independent hypercubes of 8 left slices empty and doubled others: the mean of
    |x1| |x2|'s residual varied 1.25 times as much, docs/diagnostics.md)."""
    inputs = {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)}
    plan, design = _kinks_plan(inputs, seed)
    assert plan.runs(design.shape[0]) == (8, 16)
    union = np.concatenate([plan.draws(8, design, batch=b).nodes.params for b in (0, 1)])
    slices = np.floor((union + 1.0) / 2.0 * 16).astype(int)
    for column in slices.T:
        assert sorted(column) == list(range(16))


def test_the_first_batch_is_the_latin_hypercube_it_was():
    """The held-out draws' first batch is ``random_nodes``' hypercube of the same seed (both
    ``latin_hypercube``): every calibrated first batch stays the same."""
    inputs = (pcmb.Uniform(-1.0, 1.0), pcmb.Uniform(0.0, 2.0), pcmb.Uniform(0.0, 1.0))
    for seed in range(5):
        draws, _ = held_out_draws(inputs, 8, seed)
        np.testing.assert_array_equal(draws.nodes, random_nodes(inputs, 8, "lhs", seed).nodes)


def test_a_second_batch_with_a_widened_input_is_drawn_apart():
    """Where an input is widened (a normal one, weighted back), the second batch is its own
    Latin hypercube, seed + 1, as before: measured on the wide damped oscillator, completing
    the first batch's hypercube there did not change how often a time past the crossing is
    called reliable and cost a third of the timely flags (docs/diagnostics.md)."""
    inputs = {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Normal(0.0, 1.0)}
    plan, design = _kinks_plan(inputs, 4)
    second = plan.draws(8, design, batch=1)
    apart, _ = held_out_draws(tuple(inputs.values()), 8, 4 + HELD_OUT_SEED + 1)
    np.testing.assert_array_equal(second.nodes.nodes, apart.nodes)


@pytest.mark.slow
def test_the_sequential_check_of_two_kinks_misses_at_most_at_its_confidence():
    """|x1| |x2| (1 + t) on U[-1, 1]², tensor order 7 (64 runs), tolerance 0.02: its true error
    (8-point Gauss on |x|, in closed form) passes 2 % at t = 0.9. Over seeds 0-99 of the
    default sequential check (8 draws, then 8 more where undecided), a time past the crossing
    is called reliable in at most 15 studies: the binomial 96 % bound of the 10 % the one-sided
    90 % confidence allows (16 with two independent hypercubes of 8)."""
    times = np.linspace(0.0, 2.0, 41)
    inputs = {"x1": pcmb.Uniform(-1.0, 1.0), "x2": pcmb.Uniform(-1.0, 1.0)}
    # The design, and so the true error, does not depend on the seed.
    design = pcmb.Study(_kinks, inputs, times, backend="inprocess", order=7, validation=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expansion = design.run(progress=False).expansions["y"]
    mean, std = 0.25 * (1 + times), math.sqrt(1 / 9 - 1 / 16) * (1 + times)
    true = np.fmax(abs(expansion.mean() - mean), abs(expansion.std() - std))
    error = true / np.max(expansion.std())
    assert times[np.argmax(error > 0.02)] == pytest.approx(0.9)
    misses = 0
    for seed in range(100):
        study = pcmb.Study(
            _kinks,
            inputs,
            times,
            method={"kind": "collocation", "order": 7, "seed": seed},
            execution={"backend": "inprocess"},
            diagnostics={"tolerance": 0.02},
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = study.run()
        found = result.diagnostics["y"]
        misses += bool(np.any((error > 0.02) & ~(found.undecided | (times >= found.failing_from))))
    assert misses <= 15, misses


def test_the_unseen_region_error_is_the_rule_of_three_times_the_largest_residual_so_far():
    """K draws all miss a region of mass m with probability (1 - m)^K: at 90 % one of mass
    -ln(0.1) / K may hold none. The error it may hide there is that mass times the largest
    |residual| seen at this time or before, against the largest spread of the runs seen so
    far, times their spread now, where every residual now is below it; round-off of a large
    baseline (1e5 here) counts as none."""
    spread = np.array([1.0, 1.0, 1.0, 0.25, 1.0])  # the runs' values 1e5 + spread x u
    observed = 1e5 + np.linspace(-1.0, 1.0, 9)[:, None] * spread
    predicted = observed.copy()
    predicted[4] -= [5e-8, 0.2, 0.0, 0.02, 0.02]  # round-off of 1e5 (1e-12 of it), then errors
    found = unseen_region_error(predicted, observed, None, 0.5, 0.9)
    # 0.4 of the scale seen at the full spread; at t3 the runs vary by a quarter of it, and
    # 0.04 is more than 2.3 / 9 of a quarter of 0.4 (settled with the output): no floor.
    floor = math.log(10) / 9 * 0.4
    np.testing.assert_allclose(found, [0.0, 0.0, floor, 0.0, floor])


def test_draws_that_all_miss_a_moving_jump_leave_the_time_undecided():
    """A mass at v0 ~ U[0.5, 1.5] meets a wall at t = 1 / v0 and rebounds at -e v0, e ~
    U[0.3, 0.7]; tensor order 5, seed 7, 9 drawn runs. At t = 1.9 the jump sits at v0 =
    0.53, below every node and draw: each residual is 0 (the velocity is linear in v0 and e
    on each side) while the truth's error is 8 % of the scale. Before, "0 ± 0": reliable.
    The draws saw residuals up to 1.3 of the scale before; the jump may hide in the 2.3 / 9
    of the mass they may miss, as large against the runs' spread there as the largest
    residual against the largest spread before: undecided."""

    @pcmb.batched(outputs=("v",))
    def wall(params, times):
        v0, e = (np.asarray(params[name])[:, None] for name in ("v0", "e"))
        return {"v": np.where(times < 1 / v0, v0, -e * v0)}

    inputs = {"v0": pcmb.Uniform(0.5, 1.5), "e": pcmb.Uniform(0.3, 0.7)}
    times = np.linspace(0.0, 4.0, 81)
    method = {"kind": "collocation", "order": 5, "seed": 7}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = pcmb.Study(wall, inputs, times, method=method, backend="inprocess").run()
    found, at = result.diagnostics["v"], 38  # t = 1.9
    assert result.held_out.ok.sum() == 9
    predicted = result.expansions["v"].evaluate_germ(result.held_out.germ)
    residual = np.abs(result.held_out.values["v"] - predicted) / found.scale
    assert np.max(residual[:, at]) < 1e-9 < 1.0 < np.max(residual[:, :at])
    assert found.reliable and found.undecided[at]
    spread = np.std(result.held_out.values["v"], axis=0) / found.scale
    seen = np.max(residual[:, :at]) / np.max(spread[: at + 1])
    assert found.noise[at] == pytest.approx(math.log(10) / 9 * seen * spread[at], rel=1e-6)


@pcmb.batched(outputs=("y",))
def _settling(params, times):
    a, b = (np.asarray(params[name])[:, None] for name in ("a", "b"))
    return {"y": (1 / (1 + 25 * a * a) + b) * np.exp(-times)}


def _settled(seed):
    """The diagnostics of y = (1 / (1 + 25 a²) + b) e^(-t), a, b ~ U[-1, 1], t in [0, 5] (51
    points), tensor order 7, drawn with ``seed``."""
    inputs = {"a": pcmb.Uniform(-1, 1), "b": pcmb.Uniform(-1, 1)}
    method = {"kind": "collocation", "order": 7, "seed": seed}
    study = pcmb.Study(_settling, inputs, np.linspace(0, 5, 51), method=method, backend="inprocess")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return study.run().diagnostics["y"]


@pytest.mark.parametrize("seed", range(4))
def test_a_response_that_settles_is_not_floored_by_the_rule_of_three(seed):
    """The response above: every residual and the runs' spread are the same functions of
    (a, b) times e^(-t), so the draws see the error at every time as large against what the
    output varies by there as before; nothing settled out of their sight, and the noise is
    the sampling noise alone. Before, the residuals fell below 2.3 / K of the largest so far
    against the fixed scale: 36-46 of the 51 times undecided on seeds 0-3 (5-15 on the
    sampling noise)."""
    found = _settled(seed)
    np.testing.assert_array_equal(found.noise, found.holdout.noise)


def test_more_runs_lets_the_sampling_noise_fall_as_one_over_root_k_and_the_floor_as_one_over_k():
    """16 runs, an estimate of 3 % against a 5 % tolerance (margin 2 %): a sampling noise of
    1 % falls below the margin at 16 (1 / 2)² = 4 runs, a rule-of-three floor of 4 % at
    16 x 4 / 2 = 32 (its mass is 2.3 / K): 16 more. Before, the floor was squared as if it
    were sampling noise: 16 x 2² = 64, 48 more."""
    found = _settled(0)
    times = np.ones(found.estimate.shape)
    confidence = found.holdout.confidence
    spread = 0.01 / STANDARD_NORMAL.inv_cdf(confidence) * times
    found = dataclasses.replace(
        found,
        holdout=dataclasses.replace(found.holdout, spread=spread, count=16),
        estimate=0.03 * times,
        noise=0.04 * times,  # the floor: above the sampling noise of 1 %
        undecided=times > 0,
        tolerance=0.05,
    )
    assert more_runs(found) == 16
