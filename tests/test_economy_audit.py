"""Issue 23's second contract audit: dynamical models the repository does not have (a bouncing
ball, a damped oscillator with a drifting phase, a logistic growth run as an external
program, a MuJoCo slider with uncertain dry friction), written as a user would and driven by
``pcmb run``, ``pcmb inspect`` and ``pcmb report`` only, judged on the result file against
closed forms. ``tests/test_economy_contract.py`` holds the first audit's checks; none is
repeated here.

The true error is the larger error of the mean and std over the file's scale
(``/diagnostics/<output>`` attribute ``scale``), as ``docs/diagnostics.md`` defines it.
"""

from __future__ import annotations

import functools
import html
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import pcmb_here
from economy import inspect, lines, run_study, runs_line_agrees_with_the_file, true_error

pytestmark = pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")

MODELS = """
import numpy as np
import pcmb


@pcmb.batched(outputs=("y",))
def vee(params, times):
    both = np.abs(np.asarray(params["x1"])) + np.abs(np.asarray(params["x2"]))
    return {"y": both[:, None] * np.sin(times)}


@pcmb.batched(outputs=("x",))
def growth(params, times):
    return {"x": np.exp(0.5 * np.asarray(params["z"])[:, None] * times)}


def height(h, times):
    h = np.asarray(h, dtype=float)[:, None]
    t = np.broadcast_to(times, (h.shape[0], times.size))
    y, v, start = h - 4.905 * t * t, np.sqrt(19.62 * h) * 0.8, np.sqrt(h / 4.905)
    for _ in range(40):
        tau = t - start
        inside = (tau >= 0) & (tau < v / 4.905)
        y = np.where(inside, v * tau - 4.905 * tau * tau, y)
        start, v = start + v / 4.905, v * 0.8
    return np.where(t >= start, 0.0, y)


@pcmb.batched(outputs=("y",))
def ball(params, times):
    return {"y": height(params["h"], times)}


def oscillation(w, x0, times):
    w, x0 = np.asarray(w)[:, None], np.asarray(x0)[:, None]
    wd = w * np.sqrt(1 - 0.05 * 0.05)
    decay = x0 * np.exp(-0.05 * w * times)
    x = decay * (np.cos(wd * times) + 0.05 * w / wd * np.sin(wd * times))
    return {"x": x, "v": -decay * (w * w / wd) * np.sin(wd * times)}


@pcmb.batched(outputs=("x", "v"))
def oscillator(params, times):
    x0 = params["x0"] if "x0" in params else np.ones_like(params["w"])
    return oscillation(params["w"], x0, times)
"""

LOGISTIC = """\
import json
import math

setup = json.load(open("params.json"))
r, y0 = setup["params"]["r"], setup["params"]["y0"]
with open("output.csv", "w") as out:
    out.write("time,y\\n")
    for t in setup["times"]:
        out.write(f"{t!r},{1.0 / (1.0 + (1.0 / y0 - 1.0) * math.exp(-r * t))!r}\\n")
"""

SLIDER = """\
<mujoco model="slider">
  <option timestep="0.001" integrator="RK4" gravity="0 0 0"/>
  <worldbody>
    <body name="box">
      <joint name="s" type="slide" axis="1 0 0" frictionloss="1.0"/>
      <geom type="box" size="0.1 0.1 0.1" mass="1.0" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""

BALL = "model: {kind: python, entry: fresh.py:ball, params: {h: 1.0}, outputs: [y]}"
DRIFT = "model: {kind: python, entry: fresh.py:oscillator, params: {w: 2.0}, outputs: [x]}"
#: The drifting oscillator of two inputs: x and v, w ~ U[1.8, 2.2] and x(0) = x0 ~ N(1, 0.1²).
OSCILLATOR = (
    "model: {kind: python, entry: fresh.py:oscillator, params: {w: 2.0, x0: 1.0}, outputs: [x, v]}"
)
OSCILLATOR_INPUTS = (
    "{w: {dist: uniform, low: 1.8, high: 2.2}, x0: {dist: normal, mean: 1.0, std: 0.1}}"
)


def _run(folder: Path, model: str, inputs: str, method: str, time: str, *extra: str) -> Path:
    """Write the files a user would, ``pcmb run`` the config; the result file's path."""
    config = f"name: audit\n{model}\ntime: {time}\ninputs: {inputs}\nmethod: {method}\n"
    config += "execution: {backend: inprocess}\noutput: out.h5\n" + "".join(f"{x}\n" for x in extra)
    return run_study(folder, MODELS, config)


def _midpoints(low: float, high: float, count: int = 40000) -> tuple[np.ndarray, np.ndarray]:
    """The midpoint rule on [low, high] for a uniform input (a response with kinks in it)."""
    return low + (high - low) * (np.arange(count) + 0.5) / count, np.full(count, 1 / count)


def _legendre(low: float, high: float, count: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre for a uniform input on [low, high] (a smooth response)."""
    points, weights = np.polynomial.legendre.leggauss(count)
    return low + (points + 1) * (high - low) / 2, weights / 2


def _oscillator_error(path: Path, name: str):
    """:func:`true_error` of the oscillator's output ``name``: Gauss–Legendre in w ~ U[1.8, 2.2]
    times Gauss–Hermite in x0 ~ N(1, 0.1²) (its response is linear in x0)."""
    w, w_weights = _legendre(1.8, 2.2, 150)
    z, z_weights = np.polynomial.hermite_e.hermegauss(40)
    w, x0 = (grid.ravel() for grid in np.meshgrid(w, 1 + 0.1 * z, indexing="ij"))
    weights = np.outer(w_weights, z_weights / z_weights.sum()).ravel()
    oscillation = _fresh()["oscillation"]
    return true_error(path, name, lambda t: oscillation(w, x0, t)[name], weights)


@functools.cache
def _fresh() -> dict:
    """The namespace of the audit's model file, whose closed forms give the truth."""
    namespace: dict = {}
    exec(compile(MODELS, "fresh.py", "exec"), namespace)
    return namespace


def _ball(folder: Path, method: str) -> Path:
    """The bouncing ball to t = 4, h ~ U[0.5, 1.5], run with ``method``."""
    inputs = "{h: {dist: uniform, low: 0.5, high: 1.5}}"
    return _run(folder, BALL, inputs, method, "{start: 0.0, stop: 4.0, points: 201}")


@pytest.mark.slow
def test_a_bouncing_ball_is_flagged_at_its_first_true_crossing_and_sent_to_elements(tmp_path):
    """Items 4 and 5: a ball dropped from h ~ U[0.5, 1.5] onto a floor (restitution 0.8),
    order 5 (6 runs), the default placed check (8 runs): the contact puts a kink in h, the
    truth's error passes 5 % at t = 1.1; the flag is within 5 % of the horizon of it, no time
    past it is called reliable, and the remedy is elements, with the coefficients' algebraic
    decay as its evidence."""
    path = _ball(tmp_path, "{kind: collocation, order: 5}")
    h, weights = _midpoints(0.5, 1.5)
    height = _fresh()["height"]
    times, error, verdict = true_error(path, "y", lambda t: height(h, t), weights)
    crossing = times[np.argmax(error > 0.05)]
    assert 1.0 <= crossing <= 1.2  # the closed form's, not the code's
    assert abs(verdict["failing_from"] - crossing) <= 0.05 * times[-1]
    judged = verdict["undecided"] | (times >= verdict["failing_from"])
    assert not np.any((error > 0.05) & ~judged)
    assert verdict["holdout_count"] <= 8
    (flag,) = [line for line in lines(inspect(path), "warning") if "[chaos-unreliable]" in line]
    assert "multi-element chaos along h" in flag and "fall algebraically" in flag, flag
    runs_line_agrees_with_the_file(path)


def test_order_auto_on_an_oscillator_keeps_every_run_and_its_estimate_is_calibrated(tmp_path):
    """Items 1, 2 and 3: x'' + 0.1 w x' + w² x = 0, w ~ U[1.8, 2.2], x(0) = x0 ~ N(1, 0.1²), to
    t = 20 (the phase drifts), ``order: auto``: every run of its first round is a node of its
    last (nested rules: the design is the last round's runs), the check stays within
    max(8, ¼ of the design), inspect's runs line is the file's, and the last round's indicator
    lies within 10× of the true error on either side, which is below the tolerance."""
    time = "{start: 0.0, stop: 20.0, points: 201}"
    path = _run(tmp_path, OSCILLATOR, OSCILLATOR_INPUTS, "{kind: collocation, order: auto}", time)
    with h5py.File(path) as file:
        runs, indicator = file["refinement/runs"][:], file["refinement/indicator"][:]
        nodes, held = file["nodes/params"].shape[0], file["validation/params"].shape[0]
    assert len(runs) >= 2 and nodes == runs[-1]  # no round's runs discarded
    assert 0 < held <= max(8, nodes // 4)
    runs_line_agrees_with_the_file(path)
    worst = max(_oscillator_error(path, name)[1].max() for name in ("x", "v"))
    assert worst < 0.05
    assert worst / 10 <= indicator[-1] <= 10 * worst, (indicator[-1], worst)


@pytest.mark.slow
def test_elements_auto_out_of_elements_names_its_limit_and_never_contradicts_the_verdict(
    tmp_path,
):
    """Item 5: the bouncing ball with ``elements: auto`` held to 2 elements: the budget record
    names the limit it hit (2 of 2 elements, method.max_elements); the verdict is not
    "reliable" while the elements' indicator says the error is above the tolerance, and that
    indicator is worded as one; no time past the true crossing is called reliable."""
    path = _ball(tmp_path, "{kind: collocation, order: 3, elements: auto, max_elements: 2}")
    shown = inspect(path)
    (budget,) = [line for line in shown.splitlines() if line.endswith("[element-budget]")]
    assert "stopped at 2 of 2 elements (method.max_elements)" in budget, budget
    (checked,) = lines(shown, "checked")
    (decay,) = [line for line in shown.splitlines() if line.endswith("[element-decay]")]
    assert "reliable at every time" not in checked
    assert decay.startswith("warning") and "an indicator, not a verdict" in decay
    h, weights = _midpoints(0.5, 1.5)
    height = _fresh()["height"]
    times, error, verdict = true_error(path, "y", lambda t: height(h, t), weights)
    judged = verdict["undecided"] | (times >= verdict["failing_from"])
    assert not np.any((error > 0.05) & ~judged)
    runs_line_agrees_with_the_file(path)


def _report_text(path: Path) -> str:
    """``pcmb report``'s index page as text (tags, styles and images dropped)."""
    done = pcmb_here("report", str(path), "-o", str(path.parent / "report"))
    assert done.returncode == 0, done.stderr
    page = (path.parent / "report" / "index.html").read_text()
    page = re.sub(r"<(style|script)\b.*?</\1>", " ", page, flags=re.S)
    return html.unescape(re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", page)))


@pytest.mark.slow
def test_a_command_program_over_time_is_judged_honestly_and_reported_as_the_file_says(tmp_path):
    """Items 3 and 4 through ``kind: command``: logistic growth y = 1 / (1 + (1/y0 − 1) e^{−rt}),
    r ~ U[0.5, 1.5], y0 ~ U[0.05, 0.15], written by an external program as output.csv, tensor
    order 2 (9 runs): its held-out runs go through the same program (8, the budget), no time
    whose true error passes the tolerance is called reliable, and ``pcmb report`` states the
    runs made and the largest std the file holds."""
    (tmp_path / "logistic.py").write_text(LOGISTIC)
    model = (
        "model: {kind: command, command: [python3, logistic.py], files: [logistic.py], "
        "params: {r: 1.0, y0: 0.1}, outputs: [y], output: {file: output.csv}}"
    )
    inputs = "{r: {dist: uniform, low: 0.5, high: 1.5}, y0: {dist: uniform, low: 0.05, high: 0.15}}"
    time = "{start: 0.0, stop: 10.0, points: 101}"
    path = _run(tmp_path, model, inputs, "{kind: collocation, order: 2}", time)
    r, r_weights = _legendre(0.5, 1.5, 150)
    y0, y0_weights = _legendre(0.05, 0.15, 150)
    r, y0 = (grid.ravel()[:, None] for grid in np.meshgrid(r, y0, indexing="ij"))
    weights = np.outer(r_weights, y0_weights).ravel()
    response = lambda t: 1 / (1 + (1 / y0 - 1) * np.exp(-r * t))  # noqa: E731
    times, error, verdict = true_error(path, "y", response, weights)
    judged = verdict["undecided"] | (times >= verdict["failing_from"])
    assert not np.any((error > 0.05) & ~judged)
    assert verdict["holdout_count"] == 8
    runs_line_agrees_with_the_file(path)
    text = _report_text(path)
    assert "9 design nodes (9 ok, 0 failed, 0 pending); 8 held-out (8 ok); nominal run" in text
    with h5py.File(path) as file:
        largest = file["outputs/y/std"][:].max()
    assert re.search(rf"\by +[-0-9.e]+ \.\. [-0-9.e]+ +{largest:.4g}\b", text), text


@pytest.mark.slow
def test_a_mujoco_slider_with_uncertain_dry_friction_is_reliable_where_it_is(tmp_path):
    """A MuJoCo scene: a box launched at 2 m/s on a slide joint whose dry friction f ~
    U[0.6, 1.4] N stops it at t = 2/f, x = 2t − f t²/2 until then (a kink in f at each time
    the box stops); order 5, the default check (8 placed runs). The truth's error stays far
    below the tolerance, the verdict says reliable, and its estimate is within 10× of the
    truth where the truth is above round-off."""
    (tmp_path / "slider.xml").write_text(SLIDER)
    model = (
        "model: {kind: mujoco, xml: slider.xml, bind: {f: [{field: dof_frictionloss, name: s}]}, "
        "init: {qvel: {s: 2.0}}, outputs: {x: {qpos: s}}}"
    )
    inputs = "{f: {dist: uniform, low: 0.6, high: 1.4}}"
    time = "{start: 0.0, stop: 4.0, points: 201}"
    path = _run(tmp_path, model, inputs, "{kind: collocation, order: 5}", time)
    f, weights = _midpoints(0.6, 1.4)
    f = f[:, None]
    response = lambda t: np.where(t < 2 / f, 2 * t - 0.5 * f * t * t, 2 / f)  # noqa: E731
    _, error, verdict = true_error(path, "x", response, weights)
    assert error.max() < 0.005  # MuJoCo's soft friction is within 1e-4 m of the closed form
    assert np.isnan(verdict["failing_from"]) and not verdict["undecided"].any()
    assert error.max() / 10 <= verdict["estimate"].max() <= 10 * error.max()
    runs_line_agrees_with_the_file(path)


@pytest.mark.slow
@pytest.mark.parametrize(
    "method",
    [
        pytest.param(
            "{kind: collocation, order: 5}",
            id="order-5",
            marks=pytest.mark.xfail(
                strict=True,
                reason="the corrected std now holds (beyond 3 standard errors at 5 of 201 "
                "times, was 21: the interpolant's own std error joined its noise), but the "
                "verdict's estimate is not: 35 of 201 times beyond 3 of its standard errors, "
                "mostly the mean's, |interpolant - design| + its own unseen error, which reads "
                "up to twice the truth at the ball's kinks while its leave-two-out moves stay "
                "small (pcmb/analysis/diagnostics/placed.py); widening by the move before "
                "made it 3, but delayed the ball's flag from 1.10 to 1.92, so it was not kept",
            ),
        ),
        pytest.param(
            "{kind: collocation, order: 3, elements: auto}",
            id="elements-auto",
            marks=pytest.mark.xfail(
                strict=True,
                reason="the placed check's noise on the ball's elements "
                "(pcmb/analysis/diagnostics/placed.py): the corrected std is beyond 3 "
                "standard errors at 12 of 201 times (39 before the interpolant's own std "
                "error joined it), the verdict's estimate at 14",
            ),
        ),
    ],
)
def test_the_placed_checks_standard_errors_cover_a_kinked_response(tmp_path, method):
    """Items 3 and 4: the bouncing ball (one input, a kink from the contact), the default
    placed check: the stored corrected std and the verdict's estimate are within 3 of their
    standard errors (or 0.5 % of the scale) of the truth at all but 5 % of the times."""
    path = _ball(tmp_path, method)
    h, weights = _midpoints(0.5, 1.5)
    height = _fresh()["height"]
    times, error, verdict = true_error(path, "y", lambda t: height(h, t), weights)
    scale, confidence_se = verdict["scale"], verdict["noise"] / 1.28  # noise: 1.28 se at 90 %
    std_off = np.abs(verdict["corrected_std"] - verdict["true_std"]) / scale
    std_se = verdict["corrected_std_se"] / scale
    estimate_off = np.abs(verdict["estimate"] - error)
    allowed = 0.05 * times.size
    assert np.sum(std_off > np.fmax(3 * std_se, 0.005)) <= allowed
    assert np.sum(estimate_off > np.fmax(3 * confidence_se, 0.005)) <= allowed


def test_a_phase_drift_is_told_to_raise_the_order(tmp_path):
    """Item 5: x(t) of x'' + 0.1 w x' + w² x = 0, w ~ U[1.8, 2.2], to t = 40, order 4 (5 runs):
    cos(w t) is entire in w, flagged at t = 29.1 where the truth crosses; the remedy is a
    higher order (order 6 holds it within 1.75 % of the largest std), not elements."""
    path = _drift(tmp_path, "{kind: collocation, order: 4}")
    (flag,) = [line for line in lines(inspect(path), "warning") if "[chaos-unreliable]" in line]
    assert "unreliable from t = 29.1" in flag
    assert "raising the order of w (method.order)" in flag, flag


def _drift(folder: Path, method: str) -> Path:
    """x(t) of x'' + 0.1 w x' + w² x = 0, x(0) = 1, w ~ U[1.8, 2.2], to t = 40 (the phase
    drifts by 0.4 × 40 = 16 rad across the range), run with ``method``."""
    inputs = "{w: {dist: uniform, low: 1.8, high: 2.2}}"
    return _run(folder, DRIFT, inputs, method, "{start: 0.0, stop: 40.0, points: 401}")


def _drift_error(path: Path) -> float:
    """The largest true error of the phase drift's mean and std over the file's scale."""
    w, weights = _legendre(1.8, 2.2, 400)
    oscillation = _fresh()["oscillation"]
    response = lambda t: oscillation(w, np.ones_like(w), t)["x"]  # noqa: E731
    return true_error(path, "x", response, weights)[1].max()


def test_an_adaptive_grid_on_a_phase_drift_stops_where_its_tolerance_is_met(tmp_path):
    """Item 1 and Done when, item 5: ``{kind: adaptive, tolerance: 0.01}`` on the phase drift
    (one input) stops at the first Gauss-Patterson level within the tolerance (15 runs: true
    error 4.1e-6; 7 runs: 1.75e-2, above it), not at the rule's last level (31 runs, estimate
    0.101, before), and with no budget record: none of its limits was hit. No level lands in
    [ε/100, 10ε] and within ε both; the band is not asked here."""
    path = _drift(tmp_path, "{kind: adaptive, tolerance: 0.01}")
    shown = inspect(path)
    assert "[adaptive-budget]" not in shown, shown
    with h5py.File(path) as file:
        assert file["nodes/germ"].shape[0] == 15
    assert _drift_error(path) <= 0.01


VEE = "model: {kind: python, entry: fresh.py:vee, params: {x1: 0.0, x2: 0.0}, outputs: [y]}"
SQUARE = "{x1: {dist: uniform, low: -1.0, high: 1.0}, x2: {dist: uniform, low: -1.0, high: 1.0}}"


def _vee_at_order_1(folder: Path, *flags: str):
    """(|x1| + |x2|) sin t on U[-1, 1]², tensor order 1: both Gauss points of each input at
    ±1/√3, so all 4 runs are equal at every time while the response varies; ``pcmb run``
    with ``flags``, its completed process."""
    (folder / "fresh.py").write_text(MODELS)
    (folder / "study.yaml").write_text(
        f"name: vee\n{VEE}\ntime: {{start: 0.0, stop: 3.0, points: 31}}\ninputs: {SQUARE}\n"
        "method: {kind: collocation, order: 1}\nexecution: {backend: inprocess}\noutput: out.h5\n"
    )
    return pcmb_here("run", "study.yaml", "--quiet", *flags, cwd=folder)


def test_a_degenerate_design_over_time_exits_4_under_strict_with_the_file_written(tmp_path):
    """Done when, a degenerate design is flagged; README, exit codes: with ``--strict`` an
    expansion the diagnostics call unreliable exits 4 after writing the file. The flag is at
    the first time the response varies (t = 0.1), where the held-out runs differ."""
    done = _vee_at_order_1(tmp_path, "--strict")
    assert done.returncode == 4, done.stderr
    assert "--strict: the expansion of y is unreliable" in done.stderr
    with h5py.File(tmp_path / "out.h5") as file:
        assert np.all(file["outputs/y/std"][:] == 0)
        assert file["diagnostics/y"].attrs["failing_from"] == pytest.approx(0.1)
    (checked,) = lines(inspect(tmp_path / "out.h5"), "checked")
    assert "UNRELIABLE from t = 0.1" in checked


def test_a_degenerate_design_does_not_say_the_output_does_not_vary_where_it_does(tmp_path):
    """Item 5, one signal: where the design's runs are all equal and the held-out runs vary, no
    record may say that the output does not vary there (it is the expansion that does not)."""
    assert _vee_at_order_1(tmp_path).returncode == 0
    shown = inspect(tmp_path / "out.h5")
    assert "runs are all equal" in shown
    assert "the output does not vary (variance 0 up to round-off) at all 31 times" not in shown


def test_every_missing_key_of_a_method_is_named_at_once(tmp_path):
    """docs/architecture.md, ConfigError: "an invalid config, with file, line and key path of
    every problem", before any run (exit 2): ``{kind: regression, tolerance: 0.01}`` lacks
    ``method.samples`` and ``method.order``; ``pcmb validate`` names both."""
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        f"name: vee\n{VEE}\ntime: {{start: 0.0, stop: 3.0, points: 31}}\ninputs: {SQUARE}\n"
        "method: {kind: regression, tolerance: 0.01}\noutput: out.h5\n"
    )
    done = pcmb_here("validate", "study.yaml", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "method.samples" in done.stderr and "method.order" in done.stderr, done.stderr


@pytest.mark.slow
def test_elements_auto_on_a_heavy_tailed_hermite_response_is_flagged_where_it_fails(tmp_path):
    """Item 4 and the issue's case: x = exp(0.5 z t), z ~ N(0, 1), ``elements: auto`` at order
    4 (it ended 12 % wrong from t = 3.77, unflagged, before). Mean exp(t²/8) and std
    √(e^{t²/2} − e^{t²/4}) in closed form: no time whose true error passes 5 % is called
    reliable, a flag is within 5 % of the horizon of the true crossing, and the check stays
    within max(8, ¼ of the design)."""
    model = "model: {kind: python, entry: fresh.py:growth, params: {z: 0.0}, outputs: [x]}"
    inputs = "{z: {dist: normal, mean: 0.0, std: 1.0}}"
    method = "{kind: collocation, order: 4, elements: auto}"
    path = _run(tmp_path, model, inputs, method, "{start: 0.0, stop: 5.0, points: 101}")

    def moments(t):  # two equally likely values with the closed form's mean and std
        mean, std = np.exp(t * t / 8), np.sqrt(np.exp(t * t / 2) - np.exp(t * t / 4))
        return np.vstack([mean - std, mean + std])

    times, error, verdict = true_error(path, "x", moments, np.array([0.5, 0.5]))
    judged = verdict["undecided"] | (times >= verdict["failing_from"])
    assert np.any(error > 0.05)  # the premise: the design fails before the horizon
    assert not np.any((error > 0.05) & ~judged), times[(error > 0.05) & ~judged]
    crossing = times[np.argmax(error > 0.05)]
    assert abs(verdict["failing_from"] - crossing) <= 0.05 * times[-1]
    with h5py.File(path) as file:
        nodes, held = file["nodes/params"].shape[0], file["validation/params"].shape[0]
    assert held <= max(8, nodes // 4)


@pytest.mark.parametrize(
    ("method", "first_round", "budget", "held_out"),
    [
        ("{kind: collocation, order: auto, max_runs: 200}", 3, 200, "8 to 50"),
        ("{kind: collocation, order: 4, elements: auto}", 5, 155, "8 to 38"),
    ],
)
def test_validate_counts_the_held_out_runs_a_refining_design_may_make(
    tmp_path, method, first_round, budget, held_out
):
    """Item 2 through ``pcmb validate``: a design that refines (``order: auto``,
    ``elements: auto``) may end with up to its budget of runs, whose check is up to max(8, ¼
    of them), not the first round's 8: ``elements: auto`` on exp(0.5 z t) makes 105 runs and
    26 held-out runs where validate said "+ 8"."""
    (tmp_path / "fresh.py").write_text(MODELS)
    (tmp_path / "study.yaml").write_text(
        "name: growth\nmodel: {kind: python, entry: fresh.py:growth, params: {z: 0.0}, "
        "outputs: [x]}\ntime: {start: 0.0, stop: 5.0, points: 101}\n"
        f"inputs: {{z: {{dist: normal, mean: 0.0, std: 1.0}}}}\nmethod: {method}\n"
    )
    done = pcmb_here("validate", "study.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    (runs,) = lines(done.stdout, "runs")
    expected = (
        f"runs     {first_round} model runs in the first round, at most {budget} in all + "
        f"{held_out} held-out runs that check the expansion (abort on failure)"
    )
    assert runs == expected


def test_a_pdf_below_every_run_of_a_positive_output_is_flagged(tmp_path):
    """Item 6: x = exp(0.5 z t) > 0, z ~ N(0, 1), order 3 (4 runs, 8 placed held-out runs),
    PDF at t = 3 (before the flag at 3.2, the closed form's crossing): the stored PDF puts
    more than a fifth of its mass below the smallest run made; a ``pdf-outside-runs`` record
    must say so."""
    model = "model: {kind: python, entry: fresh.py:growth, params: {z: 0.0}, outputs: [x]}"
    inputs = "{z: {dist: normal, mean: 0.0, std: 1.0}}"
    time = "{start: 0.0, stop: 5.0, points: 101}"
    method = "{kind: collocation, order: 3}"
    path = _run(tmp_path, model, inputs, method, time, "analysis: {pdf_times: [3.0]}")
    with h5py.File(path) as file:
        k = int(np.argmin(np.abs(file["time"][:] - 3.0)))
        runs = [file["outputs/x/values"][:, k], file["validation/x/values"][:, k]]
        smallest = min(np.min(values) for values in runs)
        value, density = file["outputs/x/pdf/value"][0], file["outputs/x/pdf/density"][0]
        assert file["diagnostics/x"].attrs["failing_from"] == pytest.approx(3.2)
    below = np.sum((density * np.gradient(value))[value < min(0.0, smallest)])
    assert below > 0.2  # the premise: a fifth of the mass where x cannot be
    outside = [line for line in inspect(path).splitlines() if "[pdf-outside-runs]" in line]
    assert [line for line in outside if "the PDF at t = 3 " in line], outside


@pytest.mark.slow
def test_order_auto_on_a_bouncing_ball_is_not_flagged_early(tmp_path):
    """Done when, no false alarm: the bouncing ball, ``order: auto`` (it stops at order 5 on
    its own estimate, 0.0092), the default placed check: a flag within 5 % of the horizon of
    the truth's first crossing of 5 %."""
    path = _ball(tmp_path, "{kind: collocation, order: auto}")
    h, weights = _midpoints(0.5, 1.5)
    height = _fresh()["height"]
    times, error, verdict = true_error(path, "y", lambda t: height(h, t), weights)
    crossing = times[np.argmax(error > 0.05)]
    assert 1.6 <= crossing <= 1.7  # the closed form's
    assert abs(verdict["failing_from"] - crossing) <= 0.05 * times[-1], verdict["failing_from"]


@pytest.mark.slow
def test_the_drawn_check_of_a_drifting_oscillator_is_within_its_confidence_on_ten_seeds(tmp_path):
    """Item 4: x and v of
    x'' + 0.1 w x' + w² x = 0, w ~ U[1.8, 2.2], x(0) = x0 ~ N(1, 0.1²), to t = 20, tensor
    order 3 (16 runs, a drawn check of 8): the truth's error passes 5 % at t = 18.8. At the
    verdict's 90 % one-sided confidence, at most 3 of 10 seeds may call a time past the
    crossing reliable, and at most 3 may flag 5 % of the horizon early (the binomial bound of a
    10 % rate, 99 %; measured on seeds 0-9: none and one, seed 4 at t = 14.3); at each seed the
    corrected mean is within two of its standard errors of the truth at 95 % of the times."""
    misses, early = set(), set()  # the seeds
    for seed in range(10):
        folder = tmp_path / str(seed)
        folder.mkdir()
        method = f"{{kind: collocation, order: 3, seed: {seed}}}"
        path = _run(
            folder, OSCILLATOR, OSCILLATOR_INPUTS, method, "{start: 0.0, stop: 20.0, points: 201}"
        )
        for name in ("x", "v"):
            times, error, verdict = _oscillator_error(path, name)
            crossing = times[np.argmax(error > 0.05)]
            assert 18.5 <= crossing <= 19.0  # the closed form's
            judged = verdict["undecided"] | (times >= verdict["failing_from"])
            if np.any((error > 0.05) & ~judged):
                misses.add(seed)
            if verdict["failing_from"] < crossing - 0.05 * times[-1]:
                early.add(seed)
            off = np.abs(verdict["corrected_mean"] - verdict["true_mean"])
            assert np.mean(off[1:] > 2 * verdict["corrected_mean_se"][1:]) <= 0.05
    assert len(misses) <= 3 and len(early) <= 3, (misses, early)


@pytest.mark.parametrize(("stop", "batches", "held"), [(20.0, 1, 8), (40.0, 2, 12)])
def test_the_drawn_check_draws_its_second_batch_only_where_undecided(tmp_path, stop, batches, held):
    """Items 2 and 4: the drifting oscillator (w ~ U[1.8, 2.2], x0 ~ N(1, 0.1²)), tensor
    orders 5 × 7 (48 runs; budget max(8, 12) = 12). To t = 20 the first batch of 8 decides
    (reliable everywhere: one batch); to t = 40 it leaves times undecided and the second
    batch spends the rest of the budget, no more. The truth's error stays below 3 % of the
    largest std: no time is flagged; the runs line and the file agree."""
    time = f"{{start: 0.0, stop: {stop}, points: {int(stop * 10) + 1}}}"
    path = _run(
        tmp_path, OSCILLATOR, OSCILLATOR_INPUTS, "{kind: collocation, order: {w: 5, x0: 7}}", time
    )
    with h5py.File(path) as file:
        assert file["validation"].attrs["batches"] == batches
        assert file["validation/params"].shape[0] == held
        assert [np.isnan(file[f"diagnostics/{y}"].attrs["failing_from"]) for y in "xv"] == [1, 1]
    runs_line_agrees_with_the_file(path)
    for name in ("x", "v"):
        assert _oscillator_error(path, name)[1].max() < 0.03
