"""Tests of pcmb.analysis.diagnostics against responses whose true error is known.

The true error is the error of the expansion's mean and std, the larger of the two, relative
to the output's largest std, computed by a Gauss rule far finer than the chaos order (exact
to round-off for these smooth integrands). The held-out estimate from K runs has a standard
error below RMS/√K, RMS being the surrogate's true pointwise error, so the verdict must fall
between the first times where truth + 3 RMS/√K and truth - 3 RMS/√K exceed the tolerance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

import pcmb
from pcmb.analysis.diagnostics import (
    TAIL_BOUND,
    TOLERANCE,
    HeldOut,
    HeldOutCheck,
    chi_square_quantile,
    diagnose,
    held_out_draws,
    holdout_error,
    linear_in_widened,
    out_of_range,
    range_checks,
    spectral_decay,
    statistics_error,
    verdict,
)
from pcmb.analysis.diagnostics.draws import _moment_weights, _plain_share, _tail_width
from pcmb.chaos.basis import tail_terms, tensor_index_set, total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Uniform
from pcmb.chaos.nodes import TensorGrid, random_nodes
from pcmb.chaos.recovery import project_tensor
from pcmb.errors import PcmbWarning
from pcmb.references import double_well

TIMES = np.linspace(0.0, 1.0, 101)
#: Held-out runs of the checks below (a fixed ``method.validation``).
HELD_OUT = 32


def chaos(function, orders, index=None):
    """The collocation expansion of function(ξ (N, n)) -> (N, T) on U[-1, 1] inputs, and
    the values at the nodes."""
    grid = TensorGrid((Uniform(-1.0, 1.0),) * len(orders), orders)
    values = function(grid.nodes)
    index = grid.multi_index if index is None else index
    return ChaosExpansion(project_tensor(grid, values, index), index, grid.distributions), values


def true_error(expansion, function, points=120):
    """(T,) exact RMS error of the surrogate over the largest std (a fine Gauss rule)."""
    grid = TensorGrid(expansion.distributions, (points - 1,) * expansion.n)
    error = expansion.evaluate_germ(grid.nodes) - function(grid.nodes)
    return np.sqrt(grid.weights @ error**2) / expansion.std().max()


def true_statistics_error(expansion, function, points=120):
    """(T,) exact error of the expansion's mean and std (the larger) over the largest std."""
    grid = TensorGrid(expansion.distributions, (points - 1,) * expansion.n)
    values = function(grid.nodes)
    mean = grid.weights @ values
    std = np.sqrt(grid.weights @ (values - mean) ** 2)
    error = np.maximum(abs(expansion.mean() - mean), abs(expansion.std() - std))
    return error / expansion.std().max()


def verdict_window(times, truth, rms):
    """(earliest, latest) times the verdict may take (module docstring): it flags where the
    estimate exceeds the tolerance by more than its noise (1.28 standard errors, the standard
    error about RMS/√K), so no later than where the truth minus 3 + 2 × 1.28 of them does;
    the horizon's end where that never happens."""
    error = rms / np.sqrt(HELD_OUT)
    late = crossing(times, truth - (3 + 2 * 1.28) * error, TOLERANCE)
    return crossing(times, truth + 3 * error, TOLERANCE), times[-1] if np.isnan(late) else late


def assert_flagged_or_undecided(found, times, truth, rms):
    """Wherever the truth exceeds the tolerance by more than 3 RMS/√K, the verdict is flagged
    or undecided, never silently reliable."""
    wrong = truth - 3 * rms / np.sqrt(HELD_OUT) > TOLERANCE
    silent = wrong & ~found.undecided & ~(times >= found.failing_from)
    assert not silent.any(), times[silent]


def held_out(expansion, function, seed=1):
    """Surrogate and model at K held-out inputs, a Latin hypercube as a study draws them."""
    germ = random_nodes(expansion.distributions, HELD_OUT, "lhs", seed).nodes
    return expansion.evaluate_germ(germ), function(germ)


def crossing(times, error, level):
    return verdict(times, error, level)


def smooth(xi):
    return (
        np.outer(np.exp(0.5 * xi[:, 0]), np.sin(3 * TIMES))
        + np.outer(xi[:, 1] ** 2 + 0.3 * xi[:, 0] * xi[:, 1], np.cos(3 * TIMES))
        + 2.0
    )


def steepening(xi):
    """tanh((1 + 80 t)(ξ - 0.3)): smooth at t = 0, nearly a jump at ξ = 0.3 by t = 1."""
    return np.tanh(np.outer(xi[:, 0] - 0.3, 1.0 + 80.0 * TIMES))


def even(xi):
    """cos(14 t ξ): even in a symmetric input, so every odd coefficient is zero."""
    return np.cos(np.outer(xi[:, 0], 14.0 * TIMES))


def spreading(xi):
    """cos(12 t (ξ1 + ξ2)): an error that grows with time and involves both inputs alike."""
    return np.cos(np.outer(xi[:, 0] + xi[:, 1], 12.0 * TIMES))


# -- the index-set tail ------------------------------------------------------------------------


def test_the_held_out_check_is_named_apart_from_the_held_out_runs():
    # HeldOut holds the runs, HeldOutCheck the surrogate checked against them.
    check = holdout_error(np.zeros((3, 2)), np.ones((3, 2)), np.zeros(2), np.ones(2), 1.0)
    assert isinstance(check, HeldOutCheck) and check.count == 3
    assert HeldOutCheck is not HeldOut


def test_the_tail_is_the_outer_two_layers_above_degree_one():
    total = total_index_set(2, 4)
    assert np.array_equal(tail_terms(total), total.sum(axis=1) >= 3)
    tensor = tensor_index_set((4, 2))
    expected = ((tensor[:, 0] >= 3) | (tensor[:, 1] >= 1)) & (tensor.sum(axis=1) >= 2)
    assert np.array_equal(tail_terms(tensor), expected)
    # Order 2: only the degree-2 layer; a linear response has an empty tail at any order.
    assert np.array_equal(tail_terms(total_index_set(3, 2)), total_index_set(3, 2).sum(1) == 2)
    linear, _ = chaos(lambda xi: np.outer(xi[:, 0] - 2 * xi[:, 1], TIMES), (3, 3))
    assert spectral_decay(linear, 1.0).max() < 1e-25


# -- both ways: silent where the chaos is right, flagged where it is not -----------------------


def test_a_smooth_response_raises_nothing():
    expansion, values = chaos(smooth, (6, 6))
    # Its exact error is that of exp(ξ/2) at degree 7: 0.5⁷/7! ≈ 2e-6 of the std.
    assert true_error(expansion, smooth).max() < 1e-4
    found = diagnose("y", expansion, values, TIMES, held_out(expansion, smooth))
    assert np.isnan(found.failing_from) and found.reliable and found.warnings == ()
    assert found.decay.max() < 1e-6 and found.holdout.upper.max() < 1e-3


def test_a_steepening_response_is_flagged_when_its_true_error_crosses_the_tolerance():
    expansion, values = chaos(steepening, (5,))
    truth = true_statistics_error(expansion, steepening)
    assert truth.max() > 2 * TOLERANCE
    rms = true_error(expansion, steepening)
    early, late = verdict_window(TIMES, truth, rms)
    for seed in range(1, 9):
        found = diagnose("y", expansion, values, TIMES, held_out(expansion, steepening, seed))
        assert early <= found.failing_from <= late
        assert_flagged_or_undecided(found, TIMES, truth, rms)
    (record,) = [w for w in found.warnings if w.code == "chaos-unreliable"]
    assert record.output == "y" and record.time_range == (found.failing_from, 1.0)
    assert record.message.startswith(f"polynomial chaos unreliable from t = {found.failing_from}")
    assert "held-out runs" in record.message and "surrogate error" in record.message
    assert "method.elements" in record.message and "x0" in record.message


def test_an_even_response_defeats_the_top_shell_but_not_the_decay():
    expansion, values = chaos(even, (7,))
    top_shell = expansion.coefficients[tail_terms(expansion.multi_index, depth=1)]
    assert np.abs(top_shell).max() < 1e-12  # degree 7 is odd: exactly zero by symmetry
    truth = true_statistics_error(expansion, even)
    assert truth.max() > 2 * TOLERANCE
    # With the decay alone (no held-out runs) the failure is still found, and no later
    # than the true error's crossing of twice the tolerance.
    alone = diagnose("y", expansion, values, TIMES)
    assert alone.holdout is None
    assert alone.failing_from <= crossing(TIMES, truth, 2 * TOLERANCE)
    assert alone.decay.max() > TOLERANCE
    rms = true_error(expansion, even)
    early, late = verdict_window(TIMES, truth, rms)
    for seed in range(1, 9):
        found = diagnose("y", expansion, values, TIMES, held_out(expansion, even, seed))
        assert early <= found.failing_from <= late
        assert_flagged_or_undecided(found, TIMES, truth, rms)


def test_an_error_spread_over_the_inputs_and_growing_points_to_sampling():
    expansion, values = chaos(spreading, (5, 5))
    found = diagnose("y", expansion, values, TIMES, held_out(expansion, spreading))
    truth = true_statistics_error(expansion, spreading)
    early, late = verdict_window(TIMES, truth, true_error(expansion, spreading))
    assert early <= found.failing_from <= late
    assert "sampling" in found.warnings[0].message


def test_the_double_well_is_flagged_where_its_exact_error_crosses_the_tolerance():
    from pcmb import Study

    model = pytest.importorskip("model_loading").model_class("double_well", "DoubleWell")
    times = np.linspace(0.0, 4.0, 201)
    study = Study(model, {"x0": Uniform(-0.625, 0.375)}, times, order=7, jobs=1)
    # Its own check (8 runs placed to extend its 8 nodes, held_out_placed) flags it, after
    # times it cannot tell.
    flagged = r"x: t in \[.*(polynomial chaos unreliable from|cannot tell whether mean)"
    with pytest.warns(PcmbWarning, match=flagged):
        result = study.run(progress=False)
    assert result.held_out.germ.shape[0] == 8
    expansion = result.expansions["x"]
    draws, weights = held_out_draws(expansion.distributions, 64, 7)
    observed = double_well(times, draws.params[:, 0])
    found = diagnose(
        "x",
        expansion,
        result.values["x"],
        times,
        (expansion.evaluate_germ(draws.nodes), observed),
        weights=weights,
        holdout_germ=draws.nodes,
    )
    fine = TensorGrid(expansion.distributions, (399,))
    exact = double_well(times, fine.params[:, 0])
    mean = fine.weights @ exact
    std = np.sqrt(fine.weights @ (exact - mean) ** 2)
    scale = expansion.std().max()
    truth = np.maximum(abs(expansion.mean() - mean), abs(expansion.std() - std)) / scale
    rms = np.sqrt(fine.weights @ (expansion.evaluate_germ(fine.nodes) - exact) ** 2) / scale
    # The statistics are wrong from about t = 3 (the pointwise surrogate from about 2.1).
    assert 2.9 < crossing(times, truth, TOLERANCE) < 3.3
    early, _ = verdict_window(times, truth, rms)
    # Its truth peaks at 0.097, below twice the tolerance: with 64 runs the standard
    # applies (within a tenth of the horizon of the truth).
    assert early <= found.failing_from
    assert abs(found.failing_from - crossing(times, truth, TOLERANCE)) <= 0.1 * times[-1]
    assert_flagged_or_undecided(result.diagnostics["x"], times, truth, rms)
    # The placed check, within 5 % of the horizon (issue 23).
    own = result.diagnostics["x"].failing_from
    assert abs(own - crossing(times, truth, TOLERANCE)) <= 0.05 * times[-1]


def test_moment_weights_give_every_cubic_in_the_widened_germs_its_standard_normal_mean():
    # Two normal germs drawn as held_out_draws draws them (N(0, λ²) within ±TAIL_BOUND, the
    # rest N(0, 1)) beside a uniform: Gauss–Legendre rules of that density on each side of
    # the bound (exact to round-off for these smooth pieces) give E ω g = E_N(0,1) g for
    # every g of degree 3 or less in each normal germ.
    inputs = (pcmb.Normal(0.0, 1.0), Uniform(0.0, 1.0), pcmb.Normal(2.0, 3.0))
    x, w = np.polynomial.legendre.leggauss(100)

    def drawn(width):
        pieces = [(-14.0, -TAIL_BOUND), (-TAIL_BOUND, TAIL_BOUND), (TAIL_BOUND, 14.0)]
        z = np.concatenate([a + (x + 1) * (b - a) / 2 for a, b in pieces])
        inside = np.repeat([False, True, False], x.size)
        plain = _plain_share(width)
        density = plain * norm.pdf(z) + inside * norm.pdf(z / width) / width
        return z, np.concatenate([w * (b - a) / 2 for a, b in pieces]) * density

    z, rule = drawn(_tail_width(2))
    a, b = (g.ravel() for g in np.meshgrid(z, z, indexing="ij"))
    rule = np.outer(rule, rule).ravel()
    germ = np.column_stack([a, np.full(a.size, 0.3), b])
    omega = _moment_weights(inputs, germ)
    z1, z2 = germ[:, 0], germ[:, 2]
    for g, exact in ((1, 1), (z1, 0), (z1**2, 1), (z1**3, 0), (z1**2 * z2**2, 1), (z1 * z2**3, 0)):
        assert rule @ (omega * g) == pytest.approx(exact, abs=1e-10)
    # One normal germ: a second moment of 1.55 where the importance weights' is 1.99.
    z, rule = drawn(_tail_width(1))
    omega = _moment_weights((pcmb.Normal(0.0, 1.0),), z[:, None])
    assert rule @ omega**2 == pytest.approx(1.55, abs=0.01)


def test_a_surrogate_is_linear_in_its_normal_inputs_only_without_their_higher_degrees():
    inputs = (pcmb.Normal(0.0, 1.0), Uniform(0.0, 1.0))
    index = [[0, 0], [1, 0], [0, 2], [1, 2], [2, 0]]
    # Time 0: z times a quadratic in u (linear in z); time 1: z² too (curved).
    coefficients = np.array([[1.0, 1.0], [0.5, 0.5], [0.3, 0.3], [0.2, 0.2], [0.0, 0.1]])
    expansion = ChaosExpansion(coefficients, index, inputs)
    assert linear_in_widened(expansion, 1.0).tolist() == [True, False]
    uniform = ChaosExpansion(coefficients[:, :1], [[0], [1], [2], [3], [4]], inputs[1:])
    assert linear_in_widened(uniform, 1.0).tolist() == [False]


# -- the held-out bound ------------------------------------------------------------------------


def test_the_held_out_bound_is_the_chi_square_bound_and_covers_at_its_level():
    rng = np.random.default_rng(3)
    observed = rng.normal(size=(10, 2000))
    zeros = np.zeros_like(observed)
    found = holdout_error(zeros, observed, zeros[0], zeros[0], scale=2.0)
    rms = np.sqrt(np.mean(observed**2, axis=0)) / 2.0
    # χ²₁₀ has its 10 % quantile at 4.8652 (tables): the bound is √(10/4.8652) × the RMS.
    assert found.upper == pytest.approx(rms * np.sqrt(10 / 4.8652), rel=1e-4)
    assert found.error == pytest.approx(rms) and found.count == 10
    # Each column is one experiment with true RMS error 1/2: the bound covers it in 90 %
    # of them, within 3 binomial standard deviations (0.0067) of 2000 experiments.
    assert np.mean(found.upper >= 0.5) == pytest.approx(0.9, abs=0.02)


@pytest.mark.parametrize("dof", [*range(1, 41), 99, 100, 1001, 5000])
def test_the_chi_square_quantile_is_scipys(dof):
    """Against scipy.stats.chi2, an independent implementation, where the check uses it."""
    from scipy.stats import chi2

    for probability in (0.01, 0.1, 0.5, 0.9, 0.99):
        expected = chi2.ppf(probability, dof)
        assert chi_square_quantile(dof, probability) == pytest.approx(expected, rel=1e-11)


def test_the_statistics_errors_are_estimated_without_bias_and_with_a_fair_standard_error():
    # Model f ~ N(1, 1) and surrogate s = 0.9 (f - 1) + 1.05: the surrogate's mean is 0.05
    # high, its std 0.1 low; 4000 experiments of K runs each (one per column).
    rng = np.random.default_rng(5)
    observed = rng.normal(1.0, 1.0, size=(HELD_OUT, 4000))
    predicted = 0.9 * (observed - 1.0) + 1.05
    mean_error, std_error, spread = statistics_error(
        predicted, observed, np.full(4000, 1.05), np.full(4000, 0.9), scale=1.0
    )
    # The residual r = 0.1 (f - 1) - 0.05 has sd 0.1: its mean has standard error 0.1/√K.
    assert np.std(mean_error) == pytest.approx(0.1 / np.sqrt(HELD_OUT), rel=0.1)
    # Unbiased: the mean error's average over 4000 experiments is within 3 of its standard
    # errors; the std's is biased by the square root and the sample variance, -Var(V̂)/8 -
    # Var(r)/(2K) ≈ -1e-3, within 3e-3 with its own sampling error (4e-4).
    assert mean_error.mean() == pytest.approx(0.05, abs=3 * 0.1 / np.sqrt(HELD_OUT * 4000))
    assert std_error.mean() == pytest.approx(0.1, abs=3e-3)
    # Fair: the reported standard error (here the std's, the larger) is the spread of the
    # std's estimates over the experiments, to the delta method's O(1/K).
    assert np.median(spread) == pytest.approx(np.std(std_error), rel=0.1)


def test_failed_held_out_runs_are_left_out():
    observed = np.array([[1.0, 2.0], [np.nan, 0.0], [3.0, 4.0]])
    found = holdout_error(np.zeros((3, 2)), observed, np.zeros(2), np.zeros(2), scale=1.0)
    assert found.count == 2
    assert found.error == pytest.approx(np.sqrt([5.0, 10.0]))


# -- range checks ------------------------------------------------------------------------------


def test_a_basis_that_misses_the_variation_has_a_nonpositive_variance():
    # ξ1 ξ2 is orthogonal to every term of total degree <= 1.
    expansion, values = chaos(
        lambda xi: np.outer(xi[:, 0] * xi[:, 1], 1.0 + TIMES), (1, 1), total_index_set(2, 1)
    )
    records = range_checks("y", expansion, values, TIMES)
    assert [r.code for r in records] == ["variance-nonpositive"]
    assert records[0].time_range == (0.0, 1.0)


def test_a_surrogate_far_outside_the_runs_is_reported():
    # A surrogate 10 ξ checked against runs ξ: most draws lie beyond the runs' range.
    expansion = ChaosExpansion(
        np.array([[0.0] * TIMES.size, [10.0 / np.sqrt(3)] * TIMES.size]),
        [[0], [1]],
        (Uniform(-1.0, 1.0),),
    )
    runs = np.outer(np.array([-1.0, 0.0, 1.0]), np.ones(TIMES.size))
    share = out_of_range(expansion, runs)
    assert share == pytest.approx(np.full(TIMES.size, 1 - 1.5 / 10), abs=0.03)
    (record,) = range_checks("y", expansion, runs, TIMES)
    assert record.code == "surrogate-out-of-range" and record.time_range == (0.0, 1.0)


def test_the_verdict_is_the_first_time_above_the_tolerance():
    assert verdict([0.0, 1.0, 2.0, 3.0], [0.0, 0.06, 0.01, 0.2], 0.05) == 1.0
    assert np.isnan(verdict([0.0, 1.0], [0.05, 0.0], 0.05))


@pytest.mark.slow
def test_diagnostics_outputs_leaves_a_round_off_residual_unjudged(tmp_path, capsys):
    from pcmb.cli import main

    config = tmp_path / "pendulum.yaml"
    source = Path(__file__).parent.parent / "configs" / "pendulum_dae.yaml"
    text = source.read_text(encoding="utf-8").replace(
        "../models", str(source.parent.parent / "models")
    )
    config.write_text(text.replace("[x, y, theta]}", "[x, y, theta, q]}"), encoding="utf-8")
    assert main(["validate", str(config)]) == 2
    assert "diagnostics.outputs[3]: 'q' is not an output" in capsys.readouterr().err
    config.write_text(text, encoding="utf-8")
    out = tmp_path / "out.h5"
    assert main(["run", str(config), "-o", str(out), "--quiet", "--strict"]) == 0
    result = pcmb.load(out)
    assert set(result.diagnostics) == {"x", "y", "theta"}  # the constraint is not judged
    assert all(found.reliable for found in result.diagnostics.values())


def test_the_surrogate_error_is_that_of_the_inputs_distribution_not_of_the_widened_draws():
    """K ~ N(1, 0.1) in logistic growth K / (1 + (K/x0 - 1) e^(-r t)): the held-out draws of
    K, widened into its tails (λ = 4.2), reach z = -14 (K = -0.4), where the degree-7
    surrogate is far off, with an importance weight of e^-90. Unweighted, that one draw made
    the surrogate's RMS error 1204 % of the std and a surrogate-inaccurate caution on a result
    true to 2.4e-5; weighted, it counts as the inputs' distribution makes it."""
    inputs = (pcmb.Normal(0.0, 1.0), Uniform(0.0, 1.0))
    grid = TensorGrid(inputs, (7, 3))

    def response(germ):
        z, u = germ[:, :1], germ[:, 1:]
        return np.exp(0.3 * z) * (1.0 + u) * np.ones(TIMES.size)

    coefficients = project_tensor(grid, response(grid.nodes), grid.multi_index)
    expansion = ChaosExpansion(coefficients, grid.multi_index, inputs)
    draws, weights = held_out_draws(inputs, 16, 3)
    germ = draws.nodes.copy()
    germ[0, 0], weights = -14.0, weights.copy()
    width = _tail_width(1)
    weights[0] = float(np.exp(np.log(width) - 14.0**2 * (1 - 1 / width**2) / 2))
    found = holdout_error(
        expansion.evaluate_germ(germ),
        response(germ),
        expansion.mean(),
        expansion.std(),
        float(expansion.std().max()),
        weights=weights,
        germ=germ,
    )
    # The surrogate's true L2 error under N(0, 1) x U(0, 1), on a fine rule.
    fine = TensorGrid(inputs, (60, 8))
    miss = expansion.evaluate_germ(fine.nodes) - response(fine.nodes)
    true = np.sqrt(fine.weights @ miss**2).max() / expansion.std().max()
    assert found.error.max() <= 30 * true, (found.error.max(), true)
