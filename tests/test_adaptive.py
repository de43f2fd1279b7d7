"""Dimension-adaptive sparse grids (method kind adaptive) against closed forms: an anisotropic
exponential where few inputs matter, and Ishigami; the budget; a YAML study resumed."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.special import sici
from test_resume import (
    PYTHON_CONFIG,
    PYTHON_MODEL,
    assert_same_runs,
    inspected,
    resume_and_rerun,
    run_and_kill,
)

import pcmb
from pcmb.chaos.nodes import NodeSet, join_nodes
from pcmb.chaos.sparse import SparseGrid, project_sparse
from pcmb.config.schema import load_config
from pcmb.designs import MethodSettings, make_design, method_section
from pcmb.designs.adaptive import GUARDED, LAST_LEVEL_REMEDY, estimated_error
from pcmb.errors import ConfigError, UsageError
from pcmb.references import (
    ishigami,
    ishigami_moments,
    piston,
    piston_bounds,
    piston_moments,
    wing_weight,
    wing_weight_bounds,
    wing_weight_moments,
)
from pcmb.study import Study

#: exp(Σ a_k x_k), x_k uniform on [0, 1]: input k matters as a_k; the last not at all.
RATES = np.array([1.0, 0.5, 0.2, 0.05, 0.01, 0.0])
EXPONENTIAL = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(RATES.size)}
ISHIGAMI = {name: pcmb.Uniform(-np.pi, np.pi) for name in ("x1", "x2", "x3")}
TIMES = np.array([0.0, 1.0])
PISTON = {name: pcmb.Uniform(*bounds) for name, bounds in piston_bounds().items()}
WING = {name: pcmb.Uniform(*bounds) for name, bounds in wing_weight_bounds().items()}


def _exponential(x):
    return np.exp(x @ RATES)


def _moments(rates):
    """E[e^{a x}] per input, x uniform on [0, 1] (1 for a = 0)."""
    safe = np.where(rates > 0, rates, 1.0)
    return np.where(rates > 0, np.expm1(rates) / safe, 1.0)


EXACT_MEAN = float(np.prod(_moments(RATES)))
EXACT_VARIANCE = float(np.prod(_moments(2 * RATES)) - EXACT_MEAN**2)


def _model(function, inputs):
    @pcmb.batched(outputs=("y",))
    def model(params, times):
        x = np.stack([params[name] for name in inputs], axis=1)
        return {"y": np.repeat(function(x)[:, None], times.size, axis=1)}

    return model


def _adaptive(function, inputs, **method) -> pcmb.StudyResult:
    study = Study(_model(function, inputs), inputs, TIMES, backend="inprocess", **method)
    return study.run()


def _statistics_error(result: pcmb.StudyResult, mean: float, std: float) -> float:
    """The error of a scalar output's mean and std against the true ones, over the std."""
    return max(abs(result.mean("y")[0] - mean), abs(result.std("y")[0] - std)) / std


def _smolyak_runs(function, inputs, error: float, exact: float) -> int:
    """Runs of the smallest isotropic Smolyak grid (rule auto) whose variance is as accurate."""
    for level in range(1, 8):
        grid = SparseGrid.smolyak(tuple(inputs.values()), level)
        variance = project_sparse(grid, function(grid.params)).variance()
        if abs(variance / exact - 1) <= error:
            return grid.size
    raise AssertionError("no Smolyak grid of level <= 7 is as accurate")


@pytest.mark.parametrize("tolerance", [1e-2, 1e-4])
def test_anisotropic_function_refines_the_inputs_that_matter(tolerance):
    result = _adaptive(_exponential, EXPONENTIAL, method="adaptive", tolerance=tolerance)
    fit = result.adaptive
    assert result.design.label == f"adaptive sparse grid to {tolerance:g}, {result.n_nodes} runs"
    assert fit.estimate <= tolerance and fit.history[-1, 0] == result.n_nodes
    assert not [w for w in result.warnings if w.code == "adaptive-budget"]
    # Honest: the estimate is never 10x over-confident (so, as it meets the tolerance, the
    # error is at most 10x above it), and the error is not 100x below what was asked.
    std = np.sqrt(EXACT_VARIANCE)
    true = max(abs(result.mean("y")[0] - EXACT_MEAN), abs(result.std("y")[0] - std)) / std
    assert tolerance / 100 <= true <= 10 * fit.estimate
    error = abs(result.std("y")[0] ** 2 / EXACT_VARIANCE - 1)
    # The important input is refined most and matters most; the one with rate 0 matters not
    # at all (its axis is probed, as a vanishing surplus may hide interactions: its level
    # says nothing, its importance does).
    assert fit.levels[0] == fit.levels.max() > fit.levels.min()
    assert np.argmax(fit.importance) == 0 and fit.importance[-1] < 1e-12
    # Fewer runs than the isotropic grid of equal accuracy.
    assert result.n_nodes < _smolyak_runs(_exponential, EXPONENTIAL, error, EXACT_VARIANCE)
    # The weights in run order: the sparse quadrature of the mean.
    np.testing.assert_allclose(result.weights @ result.values["y"][:, 0], result.mean("y")[0])


#: A product of exponentials not used to calibrate the estimate (scripts/calibrate_adaptive.py
#: chose it on exp8 and genz_oscillatory): weights rising, in 4 inputs.
VALIDATION_RATES = np.array([0.3, 0.7, 1.1, 1.6])
VALIDATION = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(VALIDATION_RATES.size)}


@pytest.mark.parametrize("tolerance", [1e-3, 1e-5])
def test_the_estimate_is_within_ten_times_the_true_error_of_mean_and_std(tolerance):
    result = _adaptive(
        lambda x: np.exp(x @ VALIDATION_RATES), VALIDATION, method="adaptive", tolerance=tolerance
    )
    mean = float(np.prod(_moments(VALIDATION_RATES)))
    std = np.sqrt(float(np.prod(_moments(2 * VALIDATION_RATES))) - mean**2)
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert estimate == result.adaptive.history[-1, 1] <= tolerance
    assert error / 10 <= estimate <= 10 * error
    # So the error is at most 10x the tolerance; and it is not 100x below what was asked.
    assert tolerance / 100 <= error
    assert not [w for w in result.warnings if w.code == "adaptive-nonsmooth"]


#: exp(Σ c_k x_k) in 8 uniform inputs (scripts/calibrate_adaptive.py's exp8).
EXP8_RATES = np.array([1.0, 0.8, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1])
EXP8 = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(EXP8_RATES.size)}


def _exp8(x):
    return np.exp(x @ EXP8_RATES)


def _exp8_moments():
    mean = float(np.prod(_moments(EXP8_RATES)))
    return mean, np.sqrt(float(np.prod(_moments(2 * EXP8_RATES))) - mean**2)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize(
    ("function", "inputs", "moments", "tolerance"),
    [
        (_exp8, EXP8, _exp8_moments(), 1e-5),
        (wing_weight, WING, wing_weight_moments(), 1e-3),  # ended at ε/130
        (wing_weight, WING, wing_weight_moments(), 1e-4),  # ended at ε/104
    ],
)
def test_the_tolerance_is_the_error_delivered(function, inputs, moments, tolerance):
    """The calibration's rule (scripts/calibrate_adaptive.py, docs/methods.md): the true error
    ends between ε/100 and 10 ε, within 10x of the estimate either way (exp8 at 1e-5 was 12x
    careful while the guard held the largest raw change of the last three)."""
    (mean, std), max_runs = moments, 6000
    result = _adaptive(function, inputs, method="adaptive", tolerance=tolerance, max_runs=max_runs)
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert tolerance / 100 <= error <= 10 * tolerance, error
    assert error / 10 <= estimate <= 10 * error, (estimate, error)


#: Genz's corner peak (1 + Σ a_k x_k)^-6 in 5 uniform inputs: no rule was chosen on it.
CORNER_RATES = np.array([1.0, 0.8, 0.6, 0.4, 0.2])
CORNER = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(CORNER_RATES.size)}


def _corner_integral(power: int) -> float:
    """∫ (1 + a·x)^-power over the unit cube, in closed form: an alternating sum over its
    corners v of (1 + a·v)^(n - power)."""
    n = CORNER_RATES.size
    corners = np.array(list(itertools.product((0, 1), repeat=n)))
    terms = (-1.0) ** corners.sum(axis=1) * (1 + corners @ CORNER_RATES) ** (n - power)
    return math.fsum(terms) / (math.prod(range(power - n, power)) * np.prod(CORNER_RATES))


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_slowly_falling_changes_are_summed_not_believed_to_be_the_error():
    """The corner peak's many small rounds each change the mean and std by a small part of
    what is left: taking the largest of the last three changes, ρ² below, as the error
    stopped at 1 719 runs with an estimate of 1e-4 for a true error of 1.3e-3 (13 ε). The
    error left is the sum of the changes to come, a geometric tail of 1 / (1 - ρ)."""
    mean, second = _corner_integral(6), _corner_integral(12)
    std = np.sqrt(second - mean**2)
    result = _adaptive(
        lambda x: (1 + x @ CORNER_RATES) ** -6.0,
        CORNER,
        method="adaptive",
        tolerance=1e-4,
        max_runs=6000,
    )
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert estimate <= 1e-4
    assert 1e-6 <= error <= 1e-3, error
    assert error / 10 <= estimate <= 10 * error, (estimate, error)


def test_a_kink_is_reported_as_a_response_the_estimate_cannot_see():
    """|a - 0.3| + e^b: the surpluses along a fall like a power of the degree, not
    geometrically, so the estimate (which assumes a smooth response) is not to be trusted.
    It is the grid's own indicator: a note where the held-out check vouches for the output
    (``tests/test_verdicts.py``), as it does here."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)}
    result = _adaptive(
        lambda x: np.abs(x[:, 0] - 0.3) + np.exp(x[:, 1]),
        inputs,
        method="adaptive",
        tolerance=1e-3,
    )
    (record,) = [w for w in result.warnings if w.code == "adaptive-nonsmooth"]
    assert "along a " in record.message and "assumes a smooth, resolved response" in record.message
    assert all(found.vouched for found in result.diagnostics.values()) and result.is_note(record)


#: Sobol's G-function Π (|4 x_k - 2| + a_k) / (1 + a_k): mean 1, a kink at every centre.
G_WEIGHTS = np.array([0.0, 1.0, 4.5, 9.0])


def _g_function(x):
    return np.prod((np.abs(4 * x - 2) + G_WEIGHTS) / (1 + G_WEIGHTS), axis=1)


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize("tolerance", [1e-2, 1e-3])
def test_the_g_function_does_not_stop_while_its_error_is_ten_times_the_tolerance(tolerance):
    """|4 x0 - 2| vanishes on the centre plane of x0, so every index at level 0 in x0 is blind
    and hides the interactions behind it: the grid must probe them rather than stop with an
    estimate below the tolerance and a true error 10x above it (it did: 8.9e-3 and 0.21)."""
    inputs = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(G_WEIGHTS.size)}
    std = np.sqrt(np.prod(1 + 1 / (3 * (1 + G_WEIGHTS) ** 2)) - 1)
    result = _adaptive(_g_function, inputs, method="adaptive", tolerance=tolerance, max_runs=2000)
    error = _statistics_error(result, 1.0, std)
    estimate = result.adaptive.estimate
    assert not (estimate <= tolerance and error > 10 * tolerance), (estimate, error)
    assert error / 10 <= estimate <= 10 * error
    # Its kink is named: the x0 axis surpluses fall like p^-1.5.
    assert [w for w in result.warnings if w.code == "adaptive-nonsmooth" and " x0 " in w.message]


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize("rule", ["clenshaw-curtis", "leja"])
def test_a_first_round_with_no_spread_but_a_changed_mean_does_not_stop_the_grid(rule):
    """Both rules' level 1 is the centre and the ends of the box, whose projection reaches
    degree 1 only: the G-function, symmetric about every centre, has a std of 0 on the first
    round's 9 runs while its mean changed (0 at the centre, not at the x0 axis's ends). That
    change relative to a std of 0 was read as none: the grid stopped with an estimate of 0 for
    a true error of 1.1 (8 inputs: 17 runs; docs/methods.md, which nested rule)."""
    inputs = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(G_WEIGHTS.size)}
    std = np.sqrt(np.prod(1 + 1 / (3 * (1 + G_WEIGHTS) ** 2)) - 1)
    result = _adaptive(
        _g_function, inputs, method="adaptive", tolerance=1e-2, max_runs=300, rule=rule
    )
    error = _statistics_error(result, 1.0, std)
    estimate = result.adaptive.estimate
    assert not (estimate <= 1e-2 and error > 0.1), (result.n_nodes, estimate, error)


@pytest.mark.parametrize(("function", "inputs"), [(piston, PISTON), (wing_weight, WING)])
def test_smooth_functions_are_not_called_nonsmooth(function, inputs):
    """Piston and Wing weight are analytic on their boxes: their axis surpluses, not yet in
    their geometric regime, may fall steadily like a power of the degree over three levels,
    but a steep one (p^-3.9 and steeper), not a kink's or a jump's."""
    result = _adaptive(function, inputs, method="adaptive", tolerance=1e-4, max_runs=3000)
    assert not [w for w in result.warnings if w.code == "adaptive-nonsmooth"]


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_the_error_left_beyond_a_rules_last_level_is_not_ignored():
    """|a - 0.3| + e^b: a reaches Gauss–Patterson's last level (degree 23) with its kink
    unresolved, and the terms with b add nothing, so the changes vanish: the grid stopped at
    97 runs with an estimate of 2e-15 for a true error of 2.9e-4, 29 times the tolerance. The
    mean change a's last level made (the quadrature error of the level before) stays in the
    estimate, which more runs cannot lower."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)}
    mean = (0.3**2 + 0.7**2) / 2 + math.expm1(1.0)
    variance = (0.3**3 + 0.7**3) / 3 - ((0.3**2 + 0.7**2) / 2) ** 2
    std = np.sqrt(variance + math.expm1(2.0) / 2 - math.expm1(1.0) ** 2)
    result = _adaptive(
        lambda x: np.abs(x[:, 0] - 0.3) + np.exp(x[:, 1]),
        inputs,
        method="adaptive",
        tolerance=1e-5,
        validation=0,
    )
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert error > 10 * 1e-5 and estimate > 1e-5, (estimate, error)
    assert error / 10 <= estimate <= 10 * error, (estimate, error)
    (stopped,) = [w for w in result.warnings if w.code == "adaptive-budget"]
    assert "last level" in stopped.message


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_no_run_is_spent_once_only_the_error_beyond_the_last_levels_is_left():
    """1{a <= 0.6} e^(b + c/2): a's jump reaches Gauss–Patterson's last level with 4.8e-2 of
    the std left, which no refinement lowers, so the estimate cannot meet 1e-4; the grid ran
    on to 375 runs (143 at 1e-2) for the same error, 2.9e-2. It stops once the error it can
    lower is below the error left."""
    inputs = {name: pcmb.Uniform(0.0, 1.0) for name in ("a", "b", "c")}
    mean = 0.6 * math.expm1(1.0) * 2 * math.expm1(0.5)
    std = math.sqrt(0.6 * math.expm1(2.0) / 2 * math.expm1(1.0) - mean**2)
    runs = []
    for tolerance in (1e-2, 1e-4):
        result = _adaptive(
            lambda x: np.where(x[:, 0] <= 0.6, np.exp(x[:, 1] + 0.5 * x[:, 2]), 0.0),
            inputs,
            method="adaptive",
            tolerance=tolerance,
            max_runs=2000,
            validation=0,
        )
        error, estimate = _statistics_error(result, mean, std), result.adaptive.estimate
        assert error / 10 <= estimate <= 10 * error and estimate > tolerance, (estimate, error)
        (stopped,) = [w for w in result.warnings if w.code == "adaptive-budget"]
        assert "a reached the last level" in stopped.message
        assert LAST_LEVEL_REMEDY in stopped.message
        assert "method.max_runs" not in stopped.message  # the rule stopped it, not the budget
        runs.append(result.n_nodes)
    assert runs[1] == runs[0], runs


def test_a_response_near_a_singularity_is_not_called_nonsmooth():
    """sqrt(a + 0.002) e^b is analytic on the box, its branch point just outside: the norms of
    its surpluses along a fall like a kink's (p^-2.3) to degree 23, but the changes of the mean
    they make fall geometrically, as a quadrature's error does on an analytic response (they
    fell like a power on the G-function's and a jump's, too): it was flagged, at 129 runs."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)}
    delta = 0.002
    root = 2 / 3 * ((1 + delta) ** 1.5 - delta**1.5)  # E sqrt(a + δ)
    mean = root * math.expm1(1.0)
    std = np.sqrt((0.5 + delta) * math.expm1(2.0) / 2 - mean**2)
    result = _adaptive(
        lambda x: np.sqrt(x[:, 0] + delta) * np.exp(x[:, 1]),
        inputs,
        method="adaptive",
        tolerance=1e-4,
        validation=0,
    )
    assert not [w for w in result.warnings if w.code == "adaptive-nonsmooth"]
    error = _statistics_error(result, mean, std)
    assert error / 10 <= result.adaptive.estimate <= 10 * error, (result.adaptive.estimate, error)


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize(
    ("validation", "code"), [(None, "chaos-unreliable"), (0, "runs-all-equal")]
)
def test_a_degenerate_design_on_the_g_function_is_flagged(tmp_path, validation, code):
    """Tensor order 1 puts both Gauss points of every input symmetric about the kink: all 16
    runs are equal, std 0, NaN Sobol' indices. The held-out check says the chaos is unreliable;
    without one, the runs' equality is flagged; both in the file and in inspect."""
    inputs = {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(G_WEIGHTS.size)}
    method = {"method": "collocation", "order": 1}
    if validation is not None:
        method["validation"] = validation
    study = Study(_model(_g_function, inputs), inputs, TIMES, backend="inprocess", **method)
    result = study.run(tmp_path / "out.h5")
    assert np.all(result.std("y") == 0) and np.all(result.values["y"] == result.values["y"][0])
    assert [w for w in result.warnings if w.code == code]
    assert code in inspected(tmp_path / "out.h5")


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_one_lucky_small_change_does_not_stop_the_grid():
    """Piston's changes per round fall unevenly (1e-4, 1e-4, then 3e-6): believing the small
    one stopped the grid at 1 167 runs 13x over-confident (7.3e-6 against 9.6e-5); starting
    from the largest of the last three changes keeps it within 10x. Mean and std: a tensor
    Gauss–Legendre rule of 12^7 points."""
    mean, std = piston_moments()
    result = _adaptive(piston, PISTON, method="adaptive", tolerance=1e-5, max_runs=3000)
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert estimate <= 1e-5 and error <= 1e-4
    assert error / 10 <= estimate <= 10 * error


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_two_lucky_small_changes_in_a_row_do_not_stop_the_grid():
    """Issue 23's band at Piston, ε = 1e-6: past 2 000 runs its changes per round zig-zag
    (9.5e-6, then 6.7e-7 and 1.5e-6), the median of the last three believed the two small ones
    and stopped at 3 599 runs 28x over-confident (2.4e-7 against 6.7e-6). The true error stays
    within 10 ε and within 10x of the estimate either way."""
    mean, std = piston_moments()
    result = _adaptive(piston, PISTON, method="adaptive", tolerance=1e-6, max_runs=6000)
    error = _statistics_error(result, mean, std)
    estimate = result.adaptive.estimate
    assert error <= 1e-5
    assert error / 10 <= estimate <= 10 * error, (estimate, error)


def test_ishigami_finds_the_interaction_its_axes_hide():
    """0.1 x3⁴ sin x1 vanishes on the x3 axis through the centre: only probing that axis
    finds it. At tolerance 1e-3 the variance and Sobol' indices are the closed form's."""
    exact = ishigami_moments()
    result = _adaptive(ishigami, ISHIGAMI, method="adaptive", tolerance=1e-3)
    error = abs(result.std("y")[0] ** 2 / exact.variance - 1)
    assert error <= 1e-3 and result.adaptive.estimate <= 1e-3
    np.testing.assert_allclose(result.mean("y"), exact.mean, atol=1e-12)
    np.testing.assert_allclose(result.sobol_total("y")[:, 0], exact.total, atol=1e-3)
    assert result.adaptive.levels[2] >= 2  # x3⁴ needs degree 4: Gauss–Patterson level 2
    # Exact to round-off, as the isotropic grid of level 5 (1 023 runs): compare at 1e-14.
    assert result.n_nodes < _smolyak_runs(ishigami, ISHIGAMI, max(error, 1e-14), exact.variance)


def _hidden_triple(x):
    return np.exp(x[:, 0]) * (1 + x[:, 1] * x[:, 2])


def test_an_interaction_behind_blind_mixed_indices_is_found():
    """e^{x1} (1 + x2 x3) on U[−1, 1]³: x2 x3 vanishes on the planes of (1, 1, 0), (2, 1, 0),
    ... and (1, 0, 1), ..., so their surpluses are zero and e^{x1} x2 x3 shows only behind
    them; before, the grid stopped at 287 runs at every ε with an estimate of 8e-16 for a
    true error of 2e-4. Closed form: mean sinh 1, second moment (sinh 2 / 2)(1 + 1/9)."""
    inputs = {name: pcmb.Uniform(-1.0, 1.0) for name in ("x1", "x2", "x3")}
    mean = math.sinh(1.0)
    std = math.sqrt(math.sinh(2.0) / 2 * 10 / 9 - mean**2)
    result = _adaptive(_hidden_triple, inputs, method="adaptive", tolerance=1e-5)
    assert _statistics_error(result, mean, std) <= 1e-4
    # Only the hidden input's neighbours are raised behind blind indices, not the blind ones.
    assert result.n_nodes <= 400


def _bilinear_sine(x):
    return np.sin(x[:, 0] + x[:, 1] * x[:, 2])


def test_an_interaction_a_lower_face_shows_is_found_behind_a_blind_index():
    """sin(x0 + x1 x2) on U[−1, 1]³: x1 x2 vanishes where x1 or x2 is at the centre, so (1, 0, 2)
    is blind and alone hides (1, 1, 2), whose face (0, 1, 2), the same step without x0, holds
    x1 x2's content at x2's second level. Before, the grid stopped at 783 runs at 1e-6 with an
    estimate of 3.5e-15 for a true error of 1e-4 (100 ε). Closed form: mean 0 (odd in x0 and
    x1 x2 together), E sin² = 1/2 − sin 2 Si(2) / 8."""
    inputs = {f"x{k}": pcmb.Uniform(-1.0, 1.0) for k in range(3)}
    std = math.sqrt(0.5 - math.sin(2.0) * sici(2.0)[0] / 8)
    result = _adaptive(_bilinear_sine, inputs, method="adaptive", tolerance=1e-6, max_runs=2000)
    error = _statistics_error(result, 0.0, std)
    assert error <= 1e-5, error
    assert result.adaptive.estimate >= error / 10, (result.adaptive.estimate, error)


def _late_bend(x):
    return np.arctan(1.5 * x[:, 0] - x[:, 1]) + x[:, 2] * np.exp(x[:, 3] / 2)


def test_a_change_found_late_keeps_its_tail():
    """arctan(1.5 x0 − x1) + x2 e^{x3/2} on U[−1, 1]⁴: x3 is blind on its axis (x2 = 0 there), so
    x2 e^{x3/2}'s higher terms are found once the estimate meets ε, their change (6.1e-6) 100
    times the one before it (5.7e-8) but far below the arctan's three rounds back. The rate read
    across that find discounted the found change's tail: at 1e-5 the grid ended at 257 runs with
    an estimate of 2.1e-8 for a true error of 9e-7 (0.023x). Truth: mean 0 (both terms odd);
    variance E arctan²(1.5 x0 − x1), by a 120-point Gauss–Legendre product (200 points agree to
    1e-14), plus E x2² E e^{x3} = sinh(1) / 3."""
    inputs = {f"x{k}": pcmb.Uniform(-1.0, 1.0) for k in range(4)}
    germ, weight = np.polynomial.legendre.leggauss(120)
    first, second = np.meshgrid(germ, germ)
    square = np.sum(np.outer(weight, weight) / 4 * np.arctan(1.5 * first - second) ** 2)
    std = math.sqrt(square + math.sinh(1.0) / 3)
    result = _adaptive(_late_bend, inputs, method="adaptive", tolerance=1e-5)
    error = _statistics_error(result, 0.0, std)
    assert 1e-7 <= error <= 1e-4, error
    assert error / 10 <= result.adaptive.estimate <= 10 * error, (result.adaptive.estimate, error)


@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.timeout(60)
def test_a_probe_past_the_budget_ends_the_rounds():
    """The blind-mixed probe of e^{x1} (1 + x2 x3) at 1e-3 comes at 151 runs and costs 8 more:
    with ``max_runs`` 156 it does not fit, and the rounds end there with ``adaptive-budget`` (the
    design once looped for ever, the probe neither added nor refused)."""
    inputs = {name: pcmb.Uniform(-1.0, 1.0) for name in ("x1", "x2", "x3")}
    method = {"kind": "adaptive", "tolerance": 1e-3, "max_runs": 156, "validation": 0}
    study = Study(
        _model(_hidden_triple, inputs), inputs, np.zeros(1), method=method,
        execution={"backend": "inprocess"},
    )  # fmt: skip
    result = study.run()
    (record,) = [w for w in result.warnings if w.code == "adaptive-budget"]
    assert result.n_nodes == 151 and "probing blind indices" in record.message


@pytest.mark.filterwarnings("ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning")
@pytest.mark.filterwarnings("ignore:.*chaos-undecided:pcmb.errors.PcmbWarning")
def test_a_budget_that_ends_before_the_tolerance_is_reported():
    with pytest.warns(pcmb.PcmbWarning, match="adaptive-budget"):
        result = _adaptive(ishigami, ISHIGAMI, method="adaptive", tolerance=1e-8, max_runs=40)
    assert result.n_nodes <= 40 and result.adaptive.estimate > 1e-8
    (record,) = [w for w in result.warnings if w.code == "adaptive-budget"]
    assert f"after {result.n_nodes} of 40 runs (method.max_runs;" in record.message


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        ({"tolerance": 0.0}, "method.tolerance"),  # refused by its section
        ({}, "method.tolerance"),
        ({"tolerance": 1e-3, "max_runs": 6}, "method.max_runs"),  # one step is 7 runs
        ({"tolerance": 1e-3, "level": 2}, "method.level"),  # a key of collocation
    ],
)
def test_unusable_settings_name_their_key(settings, key):
    with pytest.raises(UsageError, match=rf"^Study: {key}:"):
        model = pcmb.pointwise(lambda params, times: {"y": times}, outputs=("y",))
        pcmb.Study(model, ISHIGAMI, [0.0], method={"kind": "adaptive", **settings})


def _write_config(folder, method: str):
    text = PYTHON_CONFIG.replace("method: {kind: collocation, order: 3}", f"method: {method}")
    # y = 1/(1 + a t + b²): analytic, not polynomial, so the grid refines in rounds.
    folder.joinpath("model.py").write_text(
        PYTHON_MODEL.replace(
            '{"y": params["a"] * times + params["b"] ** 2}',
            '{"y": 1.0 / (1.0 + params["a"] * times + params["b"] ** 2)}',
        )
    )
    (folder / "study.yaml").write_text(text)
    return folder / "study.yaml"


def test_config_errors_name_the_budget(tmp_path):
    path = _write_config(tmp_path, "{kind: adaptive, tolerance: 1e-3, max_runs: 4}")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert [p.path for p in caught.value.problems] == ["method.max_runs"]


@pytest.mark.slow
def test_a_run_killed_between_rounds_resumes_to_the_same_result(tmp_path):
    """Round 0 (5 runs: the level-0 index and its neighbours) journaled, killed at round 1;
    the resumed run writes what an uninterrupted one does, and inspect shows the refinement."""
    _write_config(tmp_path, "{kind: adaptive, tolerance: 1e-4, max_runs: 400}")
    run_and_kill(tmp_path, after=5, nominal_first=True)
    journal = tmp_path / "out.h5.journal"
    assert len(list(journal.glob("record-*.npz"))) == 5
    first, second = resume_and_rerun(tmp_path)
    assert first.n_nodes == second.n_nodes > 5 and first.design == second.design
    assert first.adaptive.history.shape[0] > 2
    for field in ("index_set", "indicators", "active", "history", "orders"):
        np.testing.assert_array_equal(
            getattr(first.adaptive, field), getattr(second.adaptive, field)
        )
    assert_same_runs(tmp_path, first, second)
    shown = inspected(tmp_path / "out.h5")
    assert first.design.label in shown
    assert f"adaptive {first.adaptive.index_set.shape[0]} level indices" in shown
    assert "a level " in shown and "b level " in shown


# -- the anisotropic tensor grid (basis tensor) --------------------------------------------

#: Three inputs of the exponential: 3^3 = 27 runs at level 1 in each.
THREE = {name: EXPONENTIAL[name] for name in ("x0", "x1", "x2")}


def _exponential3(x):
    return np.exp(x @ RATES[:3])


@pytest.mark.parametrize("tolerance", [1e-2, 1e-4])
def test_a_tensor_grid_raised_one_input_at_a_time_meets_the_tolerance(tolerance):
    rates = RATES[:3]
    result = _adaptive(
        _exponential3,
        THREE,
        method="adaptive",
        basis="tensor",
        tolerance=tolerance,
        max_runs=5000,
    )
    fit = result.adaptive
    index = fit.index_set
    levels = index.max(axis=0)
    # A box: every level multi-index up to the levels reached, so a tensor grid.
    assert index.shape[0] == np.prod(levels + 1)
    assert np.all(levels >= 1) and list(levels) == sorted(levels, reverse=True)
    assert fit.estimate <= tolerance
    mean, variance = np.prod(_moments(rates)), np.prod(_moments(2 * rates))
    variance -= mean**2
    # Honest: the estimate is within 10x of the true error of the mean and std (it was 1e9
    # times careful: the top faces' change is the error of the box one level lower in all).
    std = np.sqrt(variance)
    error = _statistics_error(result, mean, std)
    assert error / 10 <= fit.estimate <= 10 * error, (fit.estimate, error)
    assert result.design.basis == "tensor"
    # One input per round: each round adds one level of one input.
    steps = np.diff(fit.history[:, 0])
    assert steps.size == levels.sum() - 3 and np.all(steps > 0)


def test_a_tensor_grid_stops_at_its_budget_and_says_so():
    with pytest.warns(pcmb.PcmbWarning, match=r"of 60 runs \(method.max_runs"):
        result = _adaptive(
            _exponential3, THREE, method="adaptive", basis="tensor", tolerance=1e-12, max_runs=60
        )
    assert result.n_nodes <= 60
    with pytest.raises(pcmb.UsageError, match=r"level 1 in every input\) needs 27 runs"):
        Study(
            _model(_exponential3, THREE),
            THREE,
            TIMES,
            method="adaptive",
            basis="tensor",
            tolerance=1e-3,
            max_runs=20,
        )


def test_kind_adaptive_refuses_another_basis():
    with pytest.raises(ValidationError, match=r"adaptive\.basis"):  # its section declares it
        method_section({"kind": "adaptive", "tolerance": 1e-3, "basis": "total"})


@pytest.mark.filterwarnings("ignore:.*square-overflow:pcmb.errors.PcmbWarning")
def test_the_estimate_does_not_depend_on_the_outputs_scale():
    """The same response in units 1e300 times larger refines alike (the surpluses' squares
    overflowed)."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(-1.0, 1.0)}
    found = [
        _adaptive(
            lambda x, scale=scale: scale / (1.2 + x[:, 0] + 0.6 * x[:, 1]),
            inputs,
            method="adaptive",
            tolerance=1e-4,
            validation=0,
        ).adaptive
        for scale in (1.0, 1e300)
    ]
    np.testing.assert_array_equal(found[0].history[:, 0], found[1].history[:, 0])
    np.testing.assert_allclose(found[0].indicators, found[1].indicators, rtol=1e-9)


def test_each_round_is_a_public_record_the_history_is_made_of():
    """``design.rounds``: one record per round, whose runs and estimates are the result's
    history, each estimate the tail of the changes so far (at least the error beyond the
    rules' last levels); a kink's input is named where it is measured."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)}
    design = make_design(inputs, MethodSettings("adaptive", tolerance=1e-5, max_runs=400))
    first = design.nodes()
    germ, params = first.nodes, first.params
    while True:
        values = {"y": (np.abs(params[:, 0] - 0.3) + np.exp(params[:, 1]))[:, None]}
        nodes, ok = NodeSet(first.distributions, germ, params), np.ones(len(germ), bool)
        more = design.more(nodes, values, ok)
        if more is None:
            break
        germ, params = np.vstack([germ, more.nodes]), np.vstack([params, more.params])
    rounds = design.rounds
    history = design.recover(nodes, values, ok, np.zeros(1)).adaptive.history
    np.testing.assert_array_equal(history, [(r.runs, r.estimate) for r in rounds])
    assert [r.runs for r in rounds] == sorted({r.runs for r in rounds})
    # The first change is the whole std: the grid of index 0 alone is one node, with none.
    assert rounds[0].change == pytest.approx(1.0, rel=1e-12)
    for k, record in enumerate(rounds):
        changes = [r.change for r in rounds[: k + 1]]
        guarded = min(GUARDED, len(inputs))
        assert record.reducible == estimated_error(
            changes, geometric=not record.nonsmooth, guarded=guarded
        )
        assert record.estimate == max(record.reducible, record.left)
    assert [name for name, _ in rounds[-1].nonsmooth] == ["a"]


def test_a_tensor_grid_does_not_raise_a_resolved_input_past_another_at_its_last_level():
    """log(a + 0.005) + b: a reaches Gauss–Patterson's last level (31 points) with its error
    above 1e-6; b, linear, reads exact at level 2 (its top two degrees at round-off). Raising
    b further cannot lower the estimate, yet the grid raised it to the last level too:
    31 x 31 = 961 runs where 31 x 7 = 217 say as much."""
    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(-1.0, 1.0)}
    design = make_design(inputs, MethodSettings("adaptive", tolerance=1e-6, basis="tensor"))
    nodes = design.nodes()

    def values(batch):
        a, b = batch.params[:, :1], batch.params[:, 1:]
        return np.log(a + 0.005) + b + 0 * TIMES

    found, ok = {"y": values(nodes)}, np.ones(nodes.size, dtype=bool)
    while (batch := design.more(nodes, found, ok)) is not None:
        nodes = join_nodes(nodes, batch)
        found = {"y": np.vstack([found["y"], values(batch)])}
        ok = np.ones(nodes.size, dtype=bool)
    recovery = design.recover(nodes, found, ok, TIMES)
    assert nodes.size == 31 * 7
    (record,) = [w for w in recovery.warnings if w.code == "adaptive-budget"]
    assert "a is at its rule's last level" in record.message
    assert LAST_LEVEL_REMEDY in record.message  # the sparse grid's words ('use rule leja')


def _rosenbrock(x):
    return np.sum(100 * (x[:, 1:] - x[:, :-1] ** 2) ** 2 + (1 - x[:, :-1]) ** 2, axis=1)


def test_without_held_out_runs_a_grid_exact_to_round_off_is_not_called_unreliable():
    """Rosenbrock in 3 inputs, a polynomial the grid resolves exactly (its estimate 1e-16):
    with validation 0 the verdict read the spectral decay alone, 21 % of the std in the
    sparse set's edge terms, real ones, and flagged the exact result (chaos-unreliable, with
    multi-element chaos as the remedy). At tolerance 1e-2: at 1e-4 the grid now also refines
    blind indices whose lower faces predict terms, and its larger set has no edge terms left."""
    inputs = {f"x{k}": pcmb.Uniform(-2.0, 2.0) for k in range(3)}
    study = Study(
        _model(_rosenbrock, inputs),
        inputs,
        TIMES,
        method={"kind": "adaptive", "tolerance": 1e-2, "validation": 0},
        execution={"backend": "inprocess"},
    )
    result = study.run()
    assert result.adaptive.estimate < 1e-12
    found = result.diagnostics["y"]
    assert np.nanmax(found.decay) > found.tolerance  # what the decay alone reads
    assert found.reliable and "chaos-unreliable" not in {w.code for w in result.warnings}
    assert np.nanmax(found.estimate) < 1e-12


def _drift(params, times):
    """x(t) of x'' + 0.1 w x' + w² x = 0, x(0) = 1, x'(0) = 0: the phase drifts with w."""
    w = np.asarray(params["w"])[:, None]
    damped = w * np.sqrt(1 - 0.05**2)
    decay = np.exp(-0.05 * w * times)
    return {"x": decay * (np.cos(damped * times) + 0.05 * w / damped * np.sin(damped * times))}


def test_one_input_stops_once_its_levels_fall_not_at_the_rules_last_level():
    """On one input a round refines the only direction there is, so its change is no
    direction's luck: the phase drift of w ~ U[1.8, 2.2] over 40 s, whose changes of the mean
    and std fall 0.25, 0.024 per Gauss–Patterson level (true errors 1.75e-2 with 7 runs, 5e-8
    with 15), stops at 15 runs within the tolerance 0.01, not at the rule's last level (31
    runs, estimate 0.10 and an adaptive-budget record naming method.max_runs)."""
    times = np.linspace(0.0, 40.0, 401)
    study = Study(
        pcmb.batched(outputs=("x",))(_drift),
        {"w": pcmb.Uniform(1.8, 2.2)},
        times,
        method={"kind": "adaptive", "tolerance": 0.01, "validation": 0},
        backend="inprocess",
    )
    result = study.run()
    w, weights = np.polynomial.legendre.leggauss(200)
    values = _drift({"w": 2.0 + 0.2 * w}, times)["x"]
    mean = weights @ values / 2
    std = np.sqrt(weights @ (values - mean) ** 2 / 2)
    error = max(np.abs(result.mean("x") - mean).max(), np.abs(result.std("x") - std).max())
    assert result.n_nodes == 15 and error / std.max() <= 0.01
    assert result.adaptive.estimate <= 0.01
    assert not [w for w in result.warnings if w.code == "adaptive-budget"]


def test_without_held_out_runs_an_estimate_within_its_calibration_leaves_the_time_undecided():
    """Welch et al.'s 20 inputs (scripts/calibrate_adaptive.py) to 1e-2 in 229 runs,
    ``validation: 0``: the grid's estimate, 4.6e-3, meets the tolerance 1e-2 while the decay
    says 0.41 and the true error is 0.081. Vouched for by the estimate at face value before;
    now undecided, as the estimate fell to 0.14 of the truth in its calibration
    (docs/methods.md)."""
    import runpy
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "scripts" / "calibrate_adaptive.py"
    inputs, function, mean, std = runpy.run_path(str(script))["FUNCTIONS"]["welch20"]()
    study = Study(
        _model(function, inputs),
        inputs,
        TIMES,
        method={"kind": "adaptive", "tolerance": 1e-2, "max_runs": 229, "validation": 0},
        execution={"backend": "inprocess"},
        diagnostics={"tolerance": 1e-2},
    )
    with pytest.warns(pcmb.PcmbWarning):
        result = study.run()
    own = result.report.statistics_error(result, "y")
    assert own <= 1e-2 < _statistics_error(result, mean, std)  # the premise
    found = result.diagnostics["y"]
    assert not found.vouched and found.undecided.all() and np.isnan(found.failing_from)
