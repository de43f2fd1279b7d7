"""Issue 23's third contract audit: fresh instances of the issue's five families (a
heavy-tailed Hermite response, a jump in an initial condition run as an external program, a
discontinuous contact, a phase drift in a normal frequency, a smooth 4-input response) and
smooth and non-smooth functions under ``kind: adaptive``, none of them in the repository's
scripts or the two audits before (``tests/test_economy_contract.py``,
``tests/test_economy_audit.py``), written as a user would and driven by ``pcmb run``,
``validate``, ``inspect`` and ``report`` only, judged on the result file against closed
forms or fine Gauss rules of the model itself.

The true error is the larger error of the mean and std over the file's scale
(``/diagnostics/<output>`` attribute ``scale``); for ``kind: adaptive`` (responses constant in
time) that scale is the std, the quantity ``method.tolerance`` names.
"""

from __future__ import annotations

import functools
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import pcmb_here
from economy import (
    inspect,
    lines,
    report_text,
    run_study,
    runs_line_agrees_with_the_file,
    silent_times,
    true_error,
)

pytestmark = pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")

MODELS = """
import numpy as np
import pcmb


@pcmb.batched(outputs=("y",))
def tails(params, times):
    z = np.asarray(params["z"])[:, None]
    return {"y": np.exp(0.45 * z * times) + 0.3 * z}


def settle(x0, k, times):
    x0, k = np.asarray(x0)[:, None], np.asarray(k)[:, None]
    decay = np.exp(-k * times)
    return np.where(x0 > 0.3, 1.0, 0.0) * (1 - decay) + x0 * decay


@pcmb.batched(outputs=("y",))
def switch(params, times):
    return {"y": settle(params["x0"], params["k"], times)}


def contact(v0, e, times):
    v0, e = np.asarray(v0)[:, None], np.asarray(e)[:, None]
    before = times < 1 / v0
    return np.where(before, v0, -e * v0)


@pcmb.batched(outputs=("v",))
def wall(params, times):
    return {"v": contact(params["v0"], params["e"], times)}


@pcmb.batched(outputs=("y",))
def phase(params, times):
    return {"y": np.cos(np.asarray(params["w"])[:, None] * times)}


def drift4(a, b, c, d, times):
    a, b, c, d = (np.asarray(v)[:, None] for v in (a, b, c, d))
    return np.exp(-a * times) * np.cos(b * times) + c * times / (1 + times) + d * np.sin(times)


@pcmb.batched(outputs=("y",))
def smooth4(params, times):
    return {"y": drift4(*(params[name] for name in "abcd"), times)}


@pcmb.batched(outputs=("y",))
def tails2(params, times):
    z1, z2 = (np.asarray(params[name])[:, None] for name in ("z1", "z2"))
    return {"y": np.exp(0.35 * z1 * times) * (1 + 0.2 * z2)}


@pcmb.batched(outputs=("y",))
def square(params, times):
    z1, z2 = (np.asarray(params[name])[:, None] for name in ("z1", "z2"))
    return {"y": (z1 * z1 + 0.5 * z2 * z2) * np.sin(times)}


def blind(x):
    return np.exp(np.sin(0.5 * np.pi * x[0]) + 0.5 * x[1] * x[2])


def shifted(x):
    return np.exp(np.sin(0.5 * np.pi * x[0]) + 0.5 * (x[1] + 0.5) * (x[2] + 0.5))


def ratio(x):
    return 1 / (3 + x[0] + 0.5 * (x[1] + 0.4) * (x[2] + 0.6) + 0.3 * x[3])


def bend(x):
    return np.arctan(2 * x[0] + x[1]) + x[2] * np.exp(0.5 * x[3])


def step(x):
    return np.where(x[0] > 0.3, 1.0, 0.0) + 0.5 * x[1] + np.cos(x[2])


def constant_in_time(function):
    @pcmb.batched(outputs=("y",))
    def model(params, times):
        x = [np.asarray(params[f"x{k}"], dtype=float) for k in range(1, len(params) + 1)]
        return {"y": function(x)[:, None] * np.ones_like(times)}

    return model


adaptive_blind, adaptive_shifted, adaptive_ratio, adaptive_bend, adaptive_step = map(
    constant_in_time, (blind, shifted, ratio, bend, step)
)
"""

SWITCH = """\
import json
import math

setup = json.load(open("params.json"))
x0, k = setup["params"]["x0"], setup["params"]["k"]
with open("output.csv", "w") as out:
    out.write("time,y\\n")
    for t in setup["times"]:
        decay = math.exp(-k * t)
        out.write(f"{t!r},{(1.0 if x0 > 0.3 else 0.0) * (1 - decay) + x0 * decay!r}\\n")
"""

NORMAL = "{dist: normal, mean: 0.0, std: 1.0}"
UNIT = "{dist: uniform, low: -1.0, high: 1.0}"
SWITCH_INPUTS = (
    "{x0: {dist: uniform, low: 0.0, high: 1.0}, k: {dist: uniform, low: 1.0, high: 3.0}}"
)
WALL_INPUTS = "{v0: {dist: uniform, low: 0.5, high: 1.5}, e: {dist: uniform, low: 0.3, high: 0.7}}"
SMOOTH4_INPUTS = (
    "{a: {dist: uniform, low: 0.02, high: 0.06}, b: {dist: uniform, low: 0.8, high: 1.2}, "
    "c: {dist: uniform, low: -0.1, high: 0.1}, d: {dist: uniform, low: -0.2, high: 0.2}}"
)
#: Records the verdict rules over: never a warning beside "reliable at every time".
INDICATORS = ("element-decay", "regression-loo", "adaptive-nonsmooth", "order-budget")


def _model(entry: str, params: dict[str, float], outputs: str = "[y]") -> str:
    """The config's model line for the python ``entry`` of the audit's model file."""
    nominal = ", ".join(f"{name}: {value}" for name, value in params.items())
    entry = f"kind: python, entry: fresh.py:{entry}"
    return f"model: {{{entry}, params: {{{nominal}}}, outputs: {outputs}}}"


def _run(folder: Path, model: str, inputs: str, method: str, time: str, *extra: str) -> Path:
    """Write the files a user would, ``pcmb run`` the config; the result file's path."""
    config = f"name: audit3\n{model}\ntime: {time}\ninputs: {inputs}\nmethod: {method}\n"
    config += "execution: {backend: inprocess}\noutput: out.h5\n" + "".join(f"{x}\n" for x in extra)
    return run_study(folder, MODELS, config)


@functools.cache
def _fresh() -> dict:
    """The namespace of the audit's model file, whose closed forms give the truth."""
    namespace: dict = {}
    exec(compile(MODELS, "fresh.py", "exec"), namespace)
    return namespace


def _legendre(low: float, high: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre for a uniform input on [low, high]."""
    points, weights = np.polynomial.legendre.leggauss(count)
    return low + (points + 1) * (high - low) / 2, weights / 2


def _product(*rules: tuple[np.ndarray, np.ndarray]) -> tuple[list[np.ndarray], np.ndarray]:
    """The tensor product of 1-D rules: the points per input (flat) and their weights."""
    points = [grid.ravel() for grid in np.meshgrid(*(rule[0] for rule in rules), indexing="ij")]
    weights = [grid.ravel() for grid in np.meshgrid(*(rule[1] for rule in rules), indexing="ij")]
    return points, np.prod(weights, axis=0)


def _split(low: float, cut: float, high: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre on each side of a jump at ``cut`` for a uniform input on [low, high]."""
    parts = [_legendre(a, b, count) for a, b in ((low, cut), (cut, high))]
    shares = [(cut - low) / (high - low), (high - cut) / (high - low)]
    return np.concatenate([p for p, _ in parts]), np.concatenate(
        [w * s for (_, w), s in zip(parts, shares, strict=True)]
    )


def _one_signal(shown: str) -> None:
    """Item 5 and Done when: no output called reliable at every time beside a warning of an
    indicator the verdict rules over, and nothing says "not converged"."""
    assert "not converged" not in shown
    for checked in lines(shown, "checked"):
        output = checked.split()[1].rstrip(":")
        if "reliable at every time" in checked:
            for code in INDICATORS:
                assert not [
                    line
                    for line in lines(shown, "warning")
                    if f"[{code}]" in line and line.startswith(f"warning  {output}:")
                ], shown


def _flag_near_crossing(times, error, verdict, tolerance=0.05) -> tuple[float, float]:
    """(true crossing, flag) where the truth passes ``tolerance``."""
    return times[np.argmax(error > tolerance)], verdict["failing_from"]


# -- Done when, line 1: the five families, fresh ---------------------------------------------


def _tails(folder: Path):
    """y = exp(0.45 z t) + 0.3 z, z ~ N(0, 1), order 4 (5 runs) to t = 5: :func:`true_error`
    with mean e^{a²/2} and E y² = e^{2a²} + 0.6 a e^{a²/2} + 0.09 (a = 0.45 t), the closed
    form, and the result file's path."""
    path = _run(
        folder,
        _model("tails", {"z": 0.0}),
        f"{{z: {NORMAL}}}",
        "{kind: collocation, order: 4}",
        "{start: 0.0, stop: 5.0, points: 101}",
    )

    def moments(t):  # two equally likely values with the closed form's mean and std
        a = 0.45 * t
        mean = np.exp(a * a / 2)
        std = np.sqrt(np.exp(2 * a * a) + 0.6 * a * np.exp(a * a / 2) + 0.09 - mean * mean)
        return np.vstack([mean - std, mean + std])

    return *true_error(path, "y", moments, np.array([0.5, 0.5])), path


def test_a_heavy_tailed_hermite_sum_is_flagged_at_its_true_crossing(tmp_path):
    """Item 4: y = exp(0.45 z t) + 0.3 z, z ~ N(0, 1), order 4: the truth passes 5 % at
    t = 3.75; the placed check (8 runs, the budget) flags it within 5 % of the horizon, calls
    no failing time reliable, and inspect states the runs the file holds."""
    times, error, verdict, path = _tails(tmp_path)
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert 3.6 < crossing < 3.9  # the closed form's
    assert abs(flagged - crossing) <= 0.05 * times[-1]
    assert silent_times(times, error, verdict).size == 0
    assert verdict["holdout_count"] <= 8
    runs_line_agrees_with_the_file(path)
    _one_signal(inspect(path))


def test_the_corrected_std_of_a_heavy_tailed_sum_is_within_its_standard_errors(tmp_path):
    """Item 3: the corrected std the placed check stores beside the expansion's is within 3 of
    its standard errors (or 0.5 % of the scale) of the closed form at 95 % of the times."""
    times, _, verdict, _ = _tails(tmp_path)
    off = np.abs(verdict["corrected_std"] - verdict["true_std"])
    beyond = off > np.fmax(3 * verdict["corrected_std_se"], 0.005 * verdict["scale"])
    assert np.mean(beyond) <= 0.05, times[beyond]


def test_a_heavy_tailed_response_of_two_normal_inputs_is_flagged_at_its_true_crossing(tmp_path):
    """Item 4 and Done when, line 1: y = exp(0.35 z1 t) (1 + 0.2 z2), z ~ N(0, 1)², tensor
    order 4 (25 runs), to t = 6, seed 4: mean e^{a²/2} and E y² = 1.04 e^{2a²} (a = 0.35 t)
    in closed form; the truth passes 5 % at t = 4.65; the flag is within 5 % of the horizon."""
    path = _run(
        tmp_path,
        _model("tails2", {"z1": 0.0, "z2": 0.0}),
        f"{{z1: {NORMAL}, z2: {NORMAL}}}",
        "{kind: collocation, order: 4, seed: 4}",
        "{start: 0.0, stop: 6.0, points: 121}",
    )

    def moments(t):
        a = 0.35 * t
        mean = np.exp(a * a / 2)
        std = np.sqrt(1.04 * np.exp(2 * a * a) - mean * mean)
        return np.vstack([mean - std, mean + std])

    times, error, verdict = true_error(path, "y", moments, np.array([0.5, 0.5]))
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert 4.5 < crossing < 4.8  # the closed form's
    assert abs(flagged - crossing) <= 0.05 * times[-1], flagged


def test_a_phase_drift_in_a_normal_frequency_is_flagged_and_told_to_raise_the_order(tmp_path):
    """Items 4 and 5: y = cos(w t), w ~ N(1, 0.03²), to t = 100, order 6 (7 runs): mean
    cos t e^{−σ²t²/2} and E y² = (1 + cos 2t e^{−2σ²t²}) / 2 in closed form; the truth passes
    5 % at t = 59.6. The flag is within 5 % of the horizon, and the remedy of an entire
    response is a higher order, not elements."""
    path = _run(
        tmp_path,
        _model("phase", {"w": 1.0}),
        "{w: {dist: normal, mean: 1.0, std: 0.03}}",
        "{kind: collocation, order: 6}",
        "{start: 0.0, stop: 100.0, points: 501}",
    )

    def moments(t):
        mean = np.cos(t) * np.exp(-0.00045 * t * t)
        std = np.sqrt(np.maximum(0.5 * (1 + np.cos(2 * t) * np.exp(-0.0018 * t * t)) - mean**2, 0))
        return np.vstack([mean - std, mean + std])

    times, error, verdict = true_error(path, "y", moments, np.array([0.5, 0.5]))
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert 59 < crossing < 60.5  # the closed form's
    assert abs(flagged - crossing) <= 0.05 * times[-1]
    assert silent_times(times, error, verdict).size == 0
    shown = inspect(path)
    (flag,) = [line for line in lines(shown, "warning") if "[chaos-unreliable]" in line]
    assert "consider raising the order of w (method.order)" in flag, flag
    assert "method.elements" not in flag
    _one_signal(shown)


def _switch_error(path: Path):
    """:func:`true_error` of the switch: Gauss–Legendre on each side of x0 = 0.3 times
    Gauss–Legendre in k."""
    (x0, k), weights = _product(_split(0.0, 0.3, 1.0, 100), _legendre(1.0, 3.0, 60))
    settle = _fresh()["settle"]
    return true_error(path, "y", lambda t: settle(x0, k, t), weights)


def _switch(tmp_path: Path, method: str) -> tuple[Path, float, float]:
    """The switch's Python twin at tensor order 4 with the ``method`` keys besides, to t = 3:
    its file, true crossing and flag (:func:`_flag_near_crossing`)."""
    path = _run(
        tmp_path,
        _model("switch", {"x0": 0.5, "k": 2.0}),
        SWITCH_INPUTS,
        f"{{kind: collocation, order: 4{method}}}",
        "{start: 0.0, stop: 3.0, points: 61}",
    )
    return path, *_flag_near_crossing(*_switch_error(path))


@pytest.mark.slow
def test_a_jump_in_an_initial_condition_run_as_a_program_is_never_called_reliable(tmp_path):
    """Items 3, 4 and 6 through ``kind: command``: y relaxes at rate k ~ U[1, 3] from x0 ~
    U[0, 1] to 1 if x0 > 0.3, else to 0 (a jump in the initial condition), written by an
    external program; tensor order 4 (25 runs). The truth passes 5 % at t = 0.3 and reaches
    12 %: no failing time is called reliable, the drawn check stays within max(8, 25 // 4),
    inspect and the report state the file's runs, the surrogate's caution (its held-out error
    passes the tolerance) is in the file, inspect and the report, and the PDF at t = 2, with
    mass outside [0, 1] where y cannot go, is noted (``pdf-outside-runs``)."""
    (tmp_path / "switch.py").write_text(SWITCH)
    model = (
        "model: {kind: command, command: [python3, switch.py], files: [switch.py], "
        "params: {x0: 0.5, k: 2.0}, outputs: [y], output: {file: output.csv}}"
    )
    method = "{kind: collocation, order: 4}"
    path = _run(
        tmp_path,
        model,
        SWITCH_INPUTS,
        method,
        "{start: 0.0, stop: 3.0, points: 61}",
        "analysis: {pdf_times: [2.0]}",
    )
    times, error, verdict = _switch_error(path)
    assert 0.25 <= times[np.argmax(error > 0.05)] <= 0.35 and error.max() > 0.1  # the truth's
    assert silent_times(times, error, verdict).size == 0
    assert 0 < verdict["holdout_count"] <= 8
    runs_line_agrees_with_the_file(path)
    assert '"surrogate-inaccurate"' in verdict["warnings"]
    shown = inspect(path)
    assert [line for line in lines(shown, "note") if "[surrogate-inaccurate]" in line]
    with h5py.File(path) as file:  # y stays in [0, 1]: mass beyond is where no run can go
        value, density = file["outputs/y/pdf/value"][0], file["outputs/y/pdf/density"][0]
    assert np.sum((density * np.gradient(value))[(value < 0) | (value > 1)]) > 0.1
    (outside,) = [line for line in lines(shown, "note") if "[pdf-outside-runs]" in line]
    assert "the PDF at t = 2 " in outside, outside
    _one_signal(shown)
    text = report_text(path)
    assert "25 design nodes (25 ok, 0 failed, 0 pending); 8 held-out (8 ok); nominal run" in text
    assert "Caution on the PDFs, quantile bands and Sobol' indices" in text


@pytest.mark.xfail(
    strict=True,
    reason="a miss by the issue's measure: the drawn check of 8 runs (the budget, max(8, 25 // "
    "4)) calls the switch undecided at 56-60 of 61 times for seeds 0-2 (estimate 20 % ± 25 % "
    "against a truth of 12 %) and never flags it: no second batch fits the budget "
    "(pcmb/analysis/diagnostics/draws.py, held_out_budget); the chaos-undecided record asks "
    "for 819 more",
)
def test_a_jump_in_an_initial_condition_is_flagged_at_its_true_crossing(tmp_path):
    """Done when, line 1: the switch above (its Python twin, the same response) is flagged
    within 5 % of the horizon of its true crossing (t = 0.3)."""
    _, crossing, flagged = _switch(tmp_path, "")
    assert abs(flagged - crossing) <= 0.05 * 3.0, flagged


def test_the_held_out_runs_an_undecided_record_asks_for_decide_it(tmp_path):
    """Item 4: the switch's ``chaos-undecided`` record says "about 819 more held-out runs would
    decide (method.validation: 827)"; with ``validation: 827`` the verdict flags it within 5 %
    of the horizon of the true crossing (t = 0.3), calls no failing time reliable, and sends
    the jump in x0 to multi-element chaos along it."""
    path, crossing, flagged = _switch(tmp_path, ", validation: 827")
    assert abs(flagged - crossing) <= 0.05 * 3.0, flagged
    assert silent_times(*_switch_error(path)).size == 0
    runs_line_agrees_with_the_file(path)
    (flag,) = [line for line in lines(inspect(path), "warning") if "[chaos-unreliable]" in line]
    assert "consider multi-element chaos along x0 (method.elements)" in flag, flag


def test_a_discontinuous_contact_is_sent_to_elements(tmp_path):
    """Item 5: the wall below (seed 1, its flag at t = 1.15) is told multi-element chaos along
    v0, the input its velocity jumps in, with the coefficients' algebraic decay as evidence."""
    path = _run(
        tmp_path,
        _model("wall", {"v0": 1.0, "e": 0.5}, "[v]"),
        WALL_INPUTS,
        "{kind: collocation, order: 5, seed: 1}",
        "{start: 0.0, stop: 4.0, points: 81}",
    )
    (flag,) = [line for line in lines(inspect(path), "warning") if "[chaos-unreliable]" in line]
    assert "consider multi-element chaos along v0 (method.elements)" in flag, flag
    assert "fall algebraically" in flag, flag


def _contact(folder: Path, seed: int):
    """The discontinuous contact, tensor order 5 (36 runs) drawn with ``seed``: a mass at v0 ~
    U[0.5, 1.5] hits a wall at distance 1 and rebounds with restitution e ~ U[0.3, 0.7]; its
    velocity jumps in v0 at v0 = 1/t while t is in [2/3, 2]. :func:`true_error` by a fine
    midpoint rule in v0 (the jump) and Gauss-Legendre in e (linear)."""
    (v0, e), weights = _product(
        ((0.5 + (np.arange(20000) + 0.5) / 20000), np.full(20000, 1 / 20000)),
        _legendre(0.3, 0.7, 4),
    )
    contact = _fresh()["contact"]
    folder.mkdir()
    path = _run(
        folder,
        _model("wall", {"v0": 1.0, "e": 0.5}, "[v]"),
        WALL_INPUTS,
        f"{{kind: collocation, order: 5, seed: {seed}}}",
        "{start: 0.0, stop: 4.0, points: 81}",
    )
    return true_error(path, "v", lambda t: contact(v0, e, t), weights)


@pytest.mark.slow
def test_a_discontinuous_contact_is_never_called_reliable_where_it_fails_on_three_seeds(
    tmp_path,
):
    """Done when, line 1: over seeds 0-2 of the contact no failing time is called reliable,
    within 9 held-out runs. Before, seed 0 called t = 1.6-1.9 reliable where the truth is
    6-8 %: the draws saw the jump before, not there ("0 ± 0" at t = 1.9)."""
    for seed in range(3):
        times, error, verdict = _contact(tmp_path / str(seed), seed)
        assert verdict["holdout_count"] <= 9
        assert silent_times(times, error, verdict).size == 0, (
            seed,
            silent_times(times, error, verdict),
        )


@pytest.mark.xfail(
    strict=True,
    reason="the budget's 9 draws: seed 0 never flags (undecided from t = 0.7 to 4.0: its "
    "estimate passes 5 % by less than its noise, and after t = 1.6 the draws may have missed "
    "the jump), seeds 1 and 2 flag at 1.15 against a true crossing at 0.75 (10 % of the "
    "horizon late, undecided in between)",
)
def test_a_discontinuous_contact_is_flagged_at_its_true_crossing_on_three_seeds(tmp_path):
    """Done when, line 1: over seeds 0-2 of the contact every flag is within 5 % of the
    horizon of the truth's crossing (t = 0.75)."""
    for seed in range(3):
        times, error, verdict = _contact(tmp_path / str(seed), seed)
        crossing, flagged = _flag_near_crossing(times, error, verdict)
        assert abs(flagged - crossing) <= 0.05 * times[-1], (seed, flagged, crossing)


def _smooth4(folder: Path, method: str) -> Path:
    """exp(−a t) cos(b t) + c t / (1 + t) + d sin t to t = 30, a ~ U[0.02, 0.06], b ~
    U[0.8, 1.2], c ~ U[−0.1, 0.1], d ~ U[−0.2, 0.2], run with ``method``."""
    params = {"a": 0.04, "b": 1.0, "c": 0.0, "d": 0.0}
    time = "{start: 0.0, stop: 30.0, points: 301}"
    return _run(folder, _model("smooth4", params), SMOOTH4_INPUTS, method, time)


def _smooth4_error(path: Path):
    """:func:`true_error` of the smooth 4-input case: Gauss–Legendre in a and b; c and d
    enter linearly, so two points each are exact."""
    (a, b, c, d), weights = _product(
        _legendre(0.02, 0.06, 30),
        _legendre(0.8, 1.2, 60),
        _legendre(-0.1, 0.1, 2),
        _legendre(-0.2, 0.2, 2),
    )
    drift4 = _fresh()["drift4"]
    return true_error(path, "y", lambda t: drift4(a, b, c, d, t), weights)


def test_a_smooth_four_input_drift_is_never_called_reliable_where_it_fails(tmp_path):
    """Items 2 and 4: the smooth 4-input case, tensor order 2 (81 runs): its truth passes 5 %
    at t = 11.1; the check stays within max(8, 81 // 4) = 20 runs, calls no failing time
    reliable, and its runs line is the file's."""
    path = _smooth4(tmp_path, "{kind: collocation, order: 2}")
    times, error, verdict = _smooth4_error(path)
    assert 10.5 < times[np.argmax(error > 0.05)] < 11.5  # the truth's
    assert silent_times(times, error, verdict).size == 0
    assert verdict["holdout_count"] <= 20
    runs_line_agrees_with_the_file(path)
    _one_signal(inspect(path))


@pytest.mark.xfail(
    strict=True,
    reason="undecided from t = 7.8 to 15.6 (estimate 13 % ± 9 % at t = 12.6 where the truth is "
    "10 %), flagged at 15.7 (seed 0; 13.9 and 15.5 for seeds 1 and 2) against a true "
    "crossing at 11.1: 9-15 % of the horizon late; the 20-run check (the budget) is spent",
)
def test_a_smooth_four_input_drift_is_flagged_at_its_true_crossing(tmp_path):
    """Done when, line 1: the smooth 4-input case is flagged within 5 % of the horizon of the
    truth's crossing (t = 11.1)."""
    path = _smooth4(tmp_path, "{kind: collocation, order: 2}")
    times, error, verdict = _smooth4_error(path)
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert abs(flagged - crossing) <= 0.05 * times[-1], flagged


PENDULUM = """\
<mujoco model="pendulum">
  <option timestep="0.002" integrator="RK4"/>
  <worldbody>
    <body name="arm">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom type="sphere" pos="0 0 -1" size="0.05" mass="1.0" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""


def _pendulum(folder: Path, order: int) -> Path:
    """A MuJoCo pendulum (1 m, 1 kg) released from rest at a ~ U[0.6, 1.4] rad, to t = 20 s:
    its period grows with the amplitude, so its phase drifts across the range (about 2 s over
    ten swings); tensor order ``order``."""
    (folder / "pendulum.xml").write_text(PENDULUM)
    model = (
        "model: {kind: mujoco, xml: pendulum.xml, bind: {a: [{qpos0: hinge}]}, "
        "outputs: {theta: {qpos: hinge}}}"
    )
    inputs = "{a: {dist: uniform, low: 0.6, high: 1.4}}"
    method = f"{{kind: collocation, order: {order}}}"
    return _run(folder, model, inputs, method, "{start: 0.0, stop: 20.0, points: 201}")


def _pendulum_angles(release: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(releases, times) the hinge angle of the same scene stepped by MuJoCo itself (16
    Gauss–Legendre releases agree with 40 to 5e-8 rad)."""
    mujoco = pytest.importorskip("mujoco")
    scene = mujoco.MjModel.from_xml_string(PENDULUM)
    data = mujoco.MjData(scene)
    steps = np.rint(times / scene.opt.timestep).astype(int)
    angles = np.empty((release.size, times.size))
    for row, angle in enumerate(release):
        mujoco.mj_resetData(scene, data)
        data.qpos[0] = angle
        for column, count in enumerate(np.diff(steps, prepend=0)):
            for _ in range(count):
                mujoco.mj_step(scene, data)
            angles[row, column] = data.qpos[0]
    return angles


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory) -> Path:
    """The pendulum at order 3 (4 runs, 8 placed held-out runs), run once for its tests."""
    pytest.importorskip("mujoco")
    return _pendulum(tmp_path_factory.mktemp("pendulum"), 3)


@pytest.mark.slow
def test_a_mujoco_pendulums_phase_drift_is_flagged_at_its_true_crossing(pendulum):
    """Done when, line 1, on a MuJoCo scene: the pendulum at order 3 (4 runs, 8 placed
    held-out runs); the truth, from MuJoCo itself at 16 Gauss–Legendre releases, passes 5 %
    at t = 17.4: the flag is within 5 % of the horizon, no failing time is called reliable, and
    inspect's runs line is the file's."""
    path = pendulum
    release, weights = _legendre(0.6, 1.4, 16)
    times, error, verdict = true_error(
        path, "theta", lambda t: _pendulum_angles(release, t), weights
    )
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert 17 <= crossing <= 18  # MuJoCo's own
    assert abs(flagged - crossing) <= 0.05 * times[-1]
    assert silent_times(times, error, verdict).size == 0
    assert verdict["holdout_count"] <= 8
    runs_line_agrees_with_the_file(path)


@pytest.mark.slow
def test_a_mujoco_pendulums_phase_drift_is_told_to_raise_the_order(pendulum):
    """Item 5: the pendulum's angle is analytic in its release angle; the remedy of its flag
    at order 3 is a higher order (order 4, 5 runs, holds it within 2.2 % to t = 20), not
    elements."""
    (flag,) = [line for line in lines(inspect(pendulum), "warning") if "[chaos-unreliable]" in line]
    assert "raising the order of a (method.order)" in flag, flag


def _fmu_oscillator(folder: Path, fmu_dir: Path, inputs: str, method: str) -> Path:
    """The repository's FMU oscillator x'' + c x' + k x = 0, x(0) = 1 at rest (built by the
    suite's ``fmu_dir``), to t = 40 (the phase drifts with k), with ``inputs`` and
    ``method``."""
    (folder / "DampedOscillator.fmu").symlink_to(fmu_dir / "DampedOscillator.fmu")
    fixed = "{x0: 1.0, v0: 0.0}" if "c:" in inputs else "{x0: 1.0, v0: 0.0, c: 0.1}"
    model = f"model: {{kind: fmu, fmu: DampedOscillator.fmu, params: {fixed}, outputs: [x]}}"
    return _run(folder, model, inputs, method, "{start: 0.0, stop: 40.0, points: 401}")


def _fmu_error(path: Path, c_rule: tuple[np.ndarray, np.ndarray]):
    """:func:`true_error` of the oscillator's x in closed form, e^{−ct/2} (cos ω t +
    c / (2ω) sin ω t), ω = √(k − c²/4), over k ~ U[3, 5] and ``c_rule``."""
    (k, c), weights = _product(_legendre(3.0, 5.0, 200), c_rule)
    k, c = k[:, None], c[:, None]
    omega = np.sqrt(k - c * c / 4)

    def response(t):
        return np.exp(-c * t / 2) * (np.cos(omega * t) + c / (2 * omega) * np.sin(omega * t))

    return true_error(path, "x", response, weights)


@pytest.mark.slow
def test_an_fmu_oscillators_phase_drift_is_flagged_and_told_to_raise_the_order(tmp_path, fmu_dir):
    """Items 4 and 5 through ``kind: fmu``: the oscillator with stiffness k ~ U[3, 5]
    (damping 0.1), order 5 (6 runs): the truth passes 5 % at t = 21.9; the placed check flags
    it within 5 % of the horizon, calls no failing time reliable, and its remedy is a higher
    order."""
    inputs = "{k: {dist: uniform, low: 3.0, high: 5.0}}"
    path = _fmu_oscillator(tmp_path, fmu_dir, inputs, "{kind: collocation, order: 5}")
    times, error, verdict = _fmu_error(path, (np.array([0.1]), np.array([1.0])))
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert 21.5 <= crossing <= 22.5  # the closed form's
    assert abs(flagged - crossing) <= 0.05 * times[-1]
    assert silent_times(times, error, verdict).size == 0
    shown = inspect(path)
    (flag,) = [line for line in lines(shown, "warning") if "[chaos-unreliable]" in line]
    assert "consider raising the order of k (method.order)" in flag, flag
    runs_line_agrees_with_the_file(path)


@pytest.fixture(scope="module")
def two_input_oscillator(tmp_path_factory, fmu_dir) -> Path:
    """The oscillator with k ~ U[3, 5] and c ~ U[0.05, 0.15], tensor order 4 (25 runs), seed 0,
    run once for its tests."""
    inputs = "{k: {dist: uniform, low: 3.0, high: 5.0}, c: {dist: uniform, low: 0.05, high: 0.15}}"
    folder = tmp_path_factory.mktemp("oscillator")
    return _fmu_oscillator(folder, fmu_dir, inputs, "{kind: collocation, order: 4}")


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="the drawn check of 8 runs (the budget for 25) flags at t = 22.0 against a true "
    "crossing at 17.2 (12 % of the horizon late, undecided in between); seeds 1 and 2 flag at "
    "18.9 and 31.4",
)
def test_an_fmu_oscillator_of_two_inputs_is_flagged_at_its_true_crossing(two_input_oscillator):
    """Done when, line 1: the oscillator of two inputs, seed 0: the flag is within 5 % of the
    horizon of the truth's crossing (t = 17.2)."""
    path = two_input_oscillator
    times, error, verdict = _fmu_error(path, _legendre(0.05, 0.15, 12))
    assert silent_times(times, error, verdict).size == 0
    crossing, flagged = _flag_near_crossing(times, error, verdict)
    assert abs(flagged - crossing) <= 0.05 * times[-1], (flagged, crossing)


@pytest.mark.slow
def test_an_fmu_oscillator_of_two_inputs_is_told_to_raise_the_order(two_input_oscillator):
    """Item 5: the oscillator of two inputs, analytic in k, seed 0: the remedy of its flag is a
    higher order of k (8 drawn runs once put the error "inside the range of k" and sent it to
    elements, where seeds 1-2 said order)."""
    (flag,) = [
        line
        for line in lines(inspect(two_input_oscillator), "warning")
        if "[chaos-unreliable]" in line
    ]
    assert "consider raising the order of k (method.order)" in flag, flag


# -- Done when, lines 3-4: a degenerate design; a non-smooth function under adaptive --------


@pytest.mark.parametrize("validation", ["", ", validation: 0"])
def test_a_degenerate_hermite_design_is_flagged_with_or_without_the_check(tmp_path, validation):
    """Done when, a degenerate design is flagged: (z1² + 0.5 z2²) sin t, z ~ N(0, 1)², tensor
    order 1 puts both Gauss–Hermite points at ±1, where z² = 1: all 4 runs are equal and the
    std is 0 while the response varies; ``--strict`` exits 4 with the file written, and the
    verdict is UNRELIABLE, not reliable."""
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        f"name: square\n{_model('square', {'z1': 0.0, 'z2': 0.0})}\n"
        "time: {start: 0.0, stop: 3.0, points: 31}\n"
        f"inputs: {{z1: {NORMAL}, z2: {NORMAL}}}\n"
        f"method: {{kind: collocation, order: 1{validation}}}\n"
        "execution: {backend: inprocess}\noutput: out.h5\n"
    )
    done = pcmb_here("run", "study.yaml", "--quiet", "--strict", cwd=tmp_path)
    assert done.returncode == 4, done.stderr
    with h5py.File(tmp_path / "out.h5") as file:
        assert np.all(file["outputs/y/std"][:] == 0)
    shown = inspect(tmp_path / "out.h5")
    (checked,) = lines(shown, "checked")
    assert "UNRELIABLE from t = " in checked and "reliable at every" not in checked, checked
    _one_signal(shown)


def _adaptive(folder: Path, function: str, inputs: int, method: str) -> Path:
    """``function`` of the model file on U[−1, 1]^inputs, constant in time, run with
    ``method``."""
    names = {f"x{k}": 0.0 for k in range(1, inputs + 1)}
    square = "{" + ", ".join(f"{name}: {UNIT}" for name in names) + "}"
    time = "{start: 0.0, stop: 1.0, points: 2}"
    return _run(folder, _model(f"adaptive_{function}", names), square, method, time)


#: Function -> (inputs, the points per input of its Gauss–Legendre truth, a jump's place).
ADAPTIVE = {
    "blind": (3, 40),
    "shifted": (3, 40),
    "ratio": (4, 24),
    "bend": (4, 24),
    "step": (3, 40),
}


def _adaptive_error(path: Path, function: str) -> float:
    """The true error of the mean and std over the std of ``function`` in the file at
    ``path`` (a Gauss–Legendre product; the step's input x1 split at its jump)."""
    inputs, count = ADAPTIVE[function]
    first = _split(-1.0, 0.3, 1.0, count) if function == "step" else _legendre(-1.0, 1.0, count)
    points, weights = _product(first, *[_legendre(-1.0, 1.0, count)] * (inputs - 1))
    values = _fresh()[function](points)
    return float(true_error(path, "y", lambda t: np.outer(values, np.ones_like(t)), weights)[1][0])


def _chaospy_runs(function: str, error: float) -> int:
    """The runs of the smallest chaospy Smolyak grid (nested Clenshaw–Curtis) whose mean and
    std are within ``error`` of the std (the same truth)."""
    chaospy = pytest.importorskip("chaospy")
    inputs, count = ADAPTIVE[function]
    points, weights = _product(*[_legendre(-1.0, 1.0, count)] * inputs)
    truth = _fresh()[function](points)
    mean = weights @ truth
    std = np.sqrt(weights @ truth**2 - mean * mean)
    law = chaospy.J(*[chaospy.Uniform(-1, 1) for _ in range(inputs)])
    for level in range(12):
        nodes, rule = chaospy.generate_quadrature(level, law, rule="clenshaw_curtis", sparse=True)
        values = _fresh()[function](nodes)
        grid_mean = rule @ values
        grid_std = np.sqrt(max(rule @ values**2 - grid_mean**2, 0.0))
        if max(abs(grid_mean - mean), abs(grid_std - std)) <= error * std:
            return nodes.shape[1]
    raise AssertionError("no chaospy grid of level 11 or less reaches the error")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("function", "tolerance"),
    [
        ("shifted", 1e-2),
        ("shifted", 1e-4),
        ("ratio", 1e-3),
        ("ratio", 1e-4),
        ("ratio", 1e-5),
        ("bend", 1e-5),
        pytest.param(
            "ratio",
            1e-2,
            marks=pytest.mark.xfail(
                strict=True,
                reason="in band (true error 5.3e-3, estimate 5.2e-3) but 57 runs where "
                "chaospy's level-2 Clenshaw-Curtis Smolyak grid (41 runs) is within 4.9e-3: "
                "the refinement's path, not the stop (errors 9e-2, 8.8e-2, 4.4e-2, 1.8e-2 at 9, "
                "13, 33, 49 runs; docs/methods.md, issue 23's remaining misses)",
            ),
        ),
        pytest.param(
            "shifted",
            1e-5,
            marks=pytest.mark.xfail(
                strict=True,
                reason="stops at 127 runs (as at 1e-4) with an estimate of 9.2e-6 for a true "
                "error of 1.4e-4: 14 ε, the estimate 15x over-confident; the error is in the "
                "x2-x3 interaction's second level, inadmissible behind (0,2,0) and (0,0,2), "
                "whose surpluses (4e-4) bulk marking leaves while the changes see x1 converge "
                "(docs/methods.md, issue 23's remaining misses: the rules tried)",
            ),
        ),
        pytest.param(
            "bend",
            1e-3,
            marks=pytest.mark.xfail(
                strict=True,
                reason="too careful: 225 runs, true error 8.6e-7 = ε/1161 (and ε/116 at "
                "1e-4, where the blind-axis check at 193 runs, error 4.5e-6, finds x3 x4's "
                "terms), below the band's ε/100; runs are still fewer than chaospy's 7537",
            ),
        ),
        pytest.param(
            "blind",
            1e-3,
            marks=pytest.mark.xfail(
                strict=True,
                reason="exp(sin(πx1/2) + x2 x3/2): too careful now, 351 runs, true error 6.1e-6 "
                "= ε/164 (estimate 7.1e-9; chaospy needs 2561 for it); the x1-x2-x3 interaction "
                "behind the blind (1,1,0) and (1,0,1) is probed and found at 87 runs (error "
                "3.8e-2 to 5.6e-4 to 8.1e-6 in two rounds), but the guard holds the estimate at "
                "0.3 for three rounds (pcmb/designs/adaptive.py, estimated_error); before, it "
                "stopped at 87-167 runs, estimate down to 1.4e-10, true error 3.8e-2",
            ),
        ),
    ],
)
def test_adaptive_ends_within_its_band_in_no_more_runs_than_smolyak(tmp_path, function, tolerance):
    """Done when, line 2: ``{kind: adaptive, tolerance: ε}`` (no held-out check) on smooth
    functions no script or test has (exp(sin(πx1/2) + (x2 + ½)(x3 + ½)/2) and exp(sin(πx1/2)
    + x2 x3/2) in 3 inputs; 1/(3 + x1 + (x2 + 0.4)(x3 + 0.6)/2 + 0.3 x4) and
    arctan(2 x1 + x2) + x3 e^{x4/2} in 4, all on U[−1, 1]) ends with a true error in
    [ε/100, 10 ε], in no more runs than chaospy's Smolyak grid needs for that error."""
    inputs = ADAPTIVE[function][0]
    path = _adaptive(
        tmp_path, function, inputs, f"{{kind: adaptive, tolerance: {tolerance}, validation: 0}}"
    )
    error = _adaptive_error(path, function)
    assert tolerance / 100 <= error <= 10 * tolerance, error
    with h5py.File(path) as file:
        runs = file["nodes/params"].shape[0]
    assert runs <= _chaospy_runs(function, error), runs


@pytest.mark.slow
@pytest.mark.parametrize("tolerance", [1e-2, 1e-3])
def test_adaptive_on_a_step_never_ends_below_its_tolerance_while_the_truth_is_ten_times_above(
    tmp_path, tolerance
):
    """Done when, line 4: 1(x1 > 0.3) + x2/2 + cos x3 on U[−1, 1]³ (a jump off the centre):
    the adaptive grid may not end with an estimate below ε while its true error is 10 ε or
    more; the jump is named (``adaptive-nonsmooth`` on x1), and the budget record names the
    limit it hit (x1's last level, not method.max_runs)."""
    method = f"{{kind: adaptive, tolerance: {tolerance}, max_runs: 3000, validation: 0}}"
    path = _adaptive(tmp_path, "step", 3, method)
    error = _adaptive_error(path, "step")
    with h5py.File(path) as file:
        estimate = file["adaptive/history"][-1, 1]
    assert not (estimate < tolerance and error >= 10 * tolerance), (estimate, error)
    shown = inspect(path)
    (nonsmooth,) = [line for line in shown.splitlines() if "[adaptive-nonsmooth]" in line]
    assert "surpluses along x1" in nonsmooth
    (budget,) = [line for line in shown.splitlines() if "[adaptive-budget]" in line]
    assert "x1 reached the last level of its rule" in budget and "max_runs" not in budget
    _one_signal(shown)


@pytest.mark.slow
def test_the_adaptive_budget_record_reads_cleanly_where_a_rule_ran_out(tmp_path):
    """The ``adaptive-budget`` record of the step (x1 at its rule's last level) is well formed."""
    path = _adaptive(tmp_path, "step", 3, "{kind: adaptive, tolerance: 0.01, validation: 0}")
    (budget,) = [line for line in inspect(path).splitlines() if "[adaptive-budget]" in line]
    assert "( " not in budget, budget


REGRESSION = "{kind: regression, samples: 40, order: 8, tolerance: 0.01, max_samples: 1500, seed: 1"


@pytest.mark.slow
def test_regression_to_a_tolerance_is_judged_reliable_by_its_check(tmp_path):
    """Item 1 for ``kind: regression`` with ``tolerance``: the shifted exp-sin function to
    1e-2 (128 runs) ends with a true error of 6.2e-3 of the std; the default check (8 drawn
    runs) calls it reliable, its estimate within 10x of the truth."""
    path = _adaptive(tmp_path, "shifted", 3, REGRESSION + "}")
    error = _adaptive_error(path, "shifted")
    assert error <= 0.01
    with h5py.File(path) as file:
        estimate = file["diagnostics/y/estimate"][0]
        assert np.isnan(file["diagnostics/y"].attrs["failing_from"])
    assert error / 10 <= estimate <= 10 * error, (estimate, error)
    _one_signal(inspect(path))


@pytest.mark.slow
def test_regression_to_a_tolerance_without_a_check_is_not_a_false_alarm(tmp_path):
    """Item 1 and Done when, no false alarm: the same fit with ``validation: 0`` is judged by
    the design's own estimate, which met the tolerance; the verdict may not flag it."""
    path = _adaptive(tmp_path, "shifted", 3, REGRESSION + ", validation: 0}")
    assert _adaptive_error(path, "shifted") <= 0.01  # the premise: 0.62 % of the std
    (checked,) = lines(inspect(path), "checked")
    assert "UNRELIABLE" not in checked, checked


@pytest.mark.slow
def test_a_sweep_of_adaptive_tolerances_measures_the_true_error(tmp_path):
    """``pcmb sweep`` against ``{kind: collocation, order: 24}`` (exact to round-off here): its
    table's runs are each setting's design and its errors of the mean and std are the true
    errors of the independent Gauss–Legendre truth (adaptive on the shifted exp-sin function
    at 1e-2..1e-4: 63, 79 and 127 runs, std errors 5.5e-4, 1.4e-4 and 1.4e-4 of the std)."""
    names = {f"x{k}": 0.0 for k in (1, 2, 3)}
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        f"name: sweep\n{_model('adaptive_shifted', names)}\n"
        "time: {start: 0.0, stop: 1.0, points: 2}\n"
        f"inputs: {{{', '.join(f'{name}: {UNIT}' for name in names)}}}\n"
        "method: {kind: adaptive, tolerance: 1.0e-3}\nexecution: {backend: inprocess}\n"
        "sweep:\n  methods:\n    - {kind: adaptive, tolerance: [1.0e-2, 1.0e-3, 1.0e-4]}\n"
        "  reference: {kind: collocation, order: 24}\n"
    )
    done = pcmb_here("sweep", "study.yaml", "-o", "out", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with h5py.File(tmp_path / "out" / "sweep.h5") as file:
        table = {key: file[f"table/{key}"][:] for key in ("runs", "err_mean", "err_std", "file")}
    assert len(table["runs"]) == 3
    for runs, err_mean, err_std, name in zip(*table.values(), strict=True):
        path = tmp_path / "out" / (name.decode() if isinstance(name, bytes) else str(name))
        with h5py.File(path) as file:
            assert file["nodes/params"].shape[0] == runs
        error = _adaptive_error(path, "shifted")
        assert max(err_mean, err_std) == pytest.approx(error, rel=1e-3, abs=1e-9)


# -- Items 3 and 5 through the contract: budgets, runs, bad keys ------------------------------


@pytest.mark.parametrize(
    ("model", "inputs", "method", "time", "code", "named"),
    [
        (
            _model("adaptive_shifted", {"x1": 0.0, "x2": 0.0, "x3": 0.0}),
            f"{{x1: {UNIT}, x2: {UNIT}, x3: {UNIT}}}",
            "{kind: adaptive, tolerance: 1.0e-6, max_runs: 40}",
            "{start: 0.0, stop: 1.0, points: 2}",
            "adaptive-budget",
            "after 39 of 40 runs (method.max_runs;",
        ),
        (
            _model("tails", {"z": 0.0}),
            f"{{z: {NORMAL}}}",
            "{kind: collocation, order: 3, elements: auto, max_elements: 3}",
            "{start: 0.0, stop: 5.0, points: 101}",
            "element-budget",
            "stopped at 3 of 3 elements (method.max_elements)",
        ),
        (
            _model("smooth4", {"a": 0.04, "b": 1.0, "c": 0.0, "d": 0.0}),
            SMOOTH4_INPUTS,
            "{kind: collocation, order: auto, max_runs: 100}",
            "{start: 0.0, stop: 30.0, points: 301}",
            "order-budget",
            "ended at order 2 after 81 of 100 runs (method.max_runs)",
        ),
    ],
    ids=["adaptive-max-runs", "elements-max-elements", "order-auto-max-runs"],
)
def test_a_budget_record_names_the_limit_it_hit_and_inspect_counts_every_run(
    tmp_path, model, inputs, method, time, code, named
):
    """Items 3 and 5: each refinement held by a limit says which, and ``pcmb inspect``'s runs
    line (design, held-out, nominal) is what the file holds."""
    path = _run(tmp_path, model, inputs, method, time)
    shown = inspect(path)
    (budget,) = [line for line in shown.splitlines() if f"[{code}]" in line]
    assert named in budget, budget
    runs_line_agrees_with_the_file(path)
    _one_signal(shown)


@pytest.mark.parametrize(
    ("method", "named"),
    [
        ("{kind: adaptive, tolerance: 1.0e-3, max_run: 100}", "method.max_run: unknown key"),
        (
            "{kind: collocation, order: 3, elements: auto, max_element: 4}",
            "method.max_element: unknown key",
        ),
        (
            "{kind: regression, samples: 20, order: 3, selction: lars}",
            "method.selction: unknown key",
        ),
        ("{kind: collocation, order: 3, tolerance: 0.01}", "method.tolerance: not a setting of"),
    ],
)
def test_a_bad_key_in_a_methods_settings_is_named_before_any_run(tmp_path, method, named):
    """docs/architecture.md, exit codes: a misspelt or misplaced key of a method's settings is
    an invalid config (exit 2) named with its key path, by ``validate`` and by ``run`` before
    any run: no result file, no journal."""
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        f"name: bad\n{_model('tails', {'z': 0.0})}\ntime: {{start: 0.0, stop: 1.0, points: 3}}\n"
        f"inputs: {{z: {NORMAL}}}\nmethod: {method}\noutput: out.h5\n"
    )
    for command in ("validate", "run"):
        done = pcmb_here(command, "study.yaml", cwd=tmp_path)
        assert done.returncode == 2 and named in done.stderr, done.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["fresh.py", "study.yaml"]


@pytest.mark.parametrize(
    ("method", "expected"),
    [
        (
            "{kind: adaptive, tolerance: 1.0e-3, max_runs: 200}",
            "7 model runs in the first round, at most 200 in all + 8 to 50 held-out runs",
        ),
        ("{kind: collocation, grid: smolyak, level: 3}", "111 model runs + 8 to 27 held-out runs"),
        (
            "{kind: regression, samples: 40, order: 6, tolerance: 1.0e-3, max_samples: 400}",
            "40 model runs in the first round, at most 400 in all + 8 to 100 held-out runs",
        ),
    ],
)
def test_validate_counts_the_held_out_runs_of_nested_and_growing_designs(
    tmp_path, method, expected
):
    """Item 2 through ``pcmb validate``: the check of a Smolyak grid, an adaptive grid and a
    regression grown to a tolerance is at most max(8, ¼ of the most runs the design may make)."""
    names = {f"x{k}": 0.0 for k in (1, 2, 3)}
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        f"name: counts\n{_model('adaptive_shifted', names)}\n"
        "time: {start: 0.0, stop: 1.0, points: 2}\n"
        f"inputs: {{{', '.join(f'{name}: {UNIT}' for name in names)}}}\nmethod: {method}\n"
    )
    done = pcmb_here("validate", "study.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    (runs,) = lines(done.stdout, "runs")
    assert runs == f"runs     {expected} that check the expansion (abort on failure)", runs
