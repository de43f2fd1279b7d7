"""Issue 23 checked through the contract only: models the repository does not have, a model
file and a YAML config written as a user would, driven by ``pcmb run`` and ``pcmb inspect``,
judged on the result file against closed forms or a fine quadrature of the model itself.

The true crossing is the first time the error of the mean or the std passes the tolerance
times the output's largest std, the scale the file stores (``/diagnostics/<output>`` attribute
``scale``), as ``docs/diagnostics.md`` defines it.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import pcmb_here
from economy import inspect, run_study, runs_line_agrees_with_the_file, true_error
from scipy.stats import norm

pytestmark = pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")

MODELS = """
import numpy as np
import pcmb


@pcmb.batched(outputs=("y",))
def kinks(params, times):
    x1, x2 = (np.asarray(params[name])[:, None] for name in ("x1", "x2"))
    return {"y": np.abs(x1) * np.abs(x2) * (1 + times)}


@pcmb.batched(outputs=("y",))
def smooth(params, times):
    x1, x2 = (np.asarray(params[name])[:, None] for name in ("x1", "x2"))
    return {"y": np.exp(0.3 * x1 * times) * np.cos((1 + 0.2 * x2) * times)}


@pcmb.batched(outputs=("y",))
def kink(params, times):
    return {"y": np.abs(np.asarray(params["x1"])[:, None]) * (1 + times)}


@pcmb.batched(outputs=("y",))
def sinh_growth(params, times):
    return {"y": np.sinh(0.6 * np.asarray(params["x1"])[:, None] * times)}


@pcmb.batched(outputs=("y",))
def lognormal2(params, times):
    z = np.asarray(params["x1"]) + np.asarray(params["x2"])
    return {"y": np.exp(0.4 * z[:, None] * times)}


@pcmb.batched(outputs=("y",))
def jump(params, times):
    x0 = np.asarray(params["x1"])[:, None]
    return {"y": np.where(x0 > 0.2, 1.0, -1.0) * (1 - np.exp(-times)) + 0.1 * x0}
"""

UNIFORM = "{dist: uniform, low: -1.0, high: 1.0}"


def _study(tmp_path: Path, entry: str, inputs: int, method: str, stop: float, *extra: str):
    """Write the model file and a config, ``pcmb run`` it; the result file's path."""
    names = [f"x{k}" for k in range(1, inputs + 1)]
    normal = entry in ("sinh_growth", "lognormal2")
    law = "{dist: normal, mean: 0.0, std: 1.0}" if normal else UNIFORM
    config = textwrap.dedent(
        f"""\
        name: {entry}
        model:
          kind: python
          entry: fresh.py:{entry}
          params: {{{", ".join(f"{n}: 0.0" for n in names)}}}
          outputs: [y]
        time: {{start: 0.0, stop: {stop}, points: {int(stop * 20) + 1}}}
        inputs: {{{", ".join(f"{n}: {law}" for n in names)}}}
        method: {method}
        execution: {{backend: inprocess}}
        output: out.h5
        """
    )
    return run_study(tmp_path, MODELS, config + "".join(f"{line}\n" for line in extra))


def _true_error(path: Path, response, *, normal: bool = False, cut: float = 0.0):
    """(times, error of mean or std over the file's scale, the diagnostics group's arrays and
    attributes) with mean and std of one input by Gauss–Legendre on each side of ``cut``."""
    points, weights = np.polynomial.legendre.leggauss(400)
    if normal:  # the normal law on [-12, 12]
        x, w = 12 * points, 12 * weights * norm.pdf(12 * points)
    else:
        pieces = [(-1.0, cut), (cut, 1.0)]
        x = np.concatenate([a + (points + 1) * (b - a) / 2 for a, b in pieces])
        w = np.concatenate([weights * (b - a) / 4 for a, b in pieces])
    return true_error(path, "y", lambda times: response(x[:, None], times[None, :]), w)


@pytest.mark.parametrize(("inputs", "order", "design"), [(1, 3, 4), (2, 2, 9), (2, 9, 100)])
def test_inspect_states_every_run_made_and_the_check_stays_within_its_budget(
    tmp_path, inputs, order, design
):
    """Item 2 and 3: the held-out runs are at most max(8, a quarter of the design), and the
    runs line of ``pcmb inspect`` is what the file holds (design, held-out, nominal)."""
    entry = "kink" if inputs == 1 else "kinks"
    path = _study(tmp_path, entry, inputs, f"{{kind: collocation, order: {order}}}", 2.0)
    with h5py.File(path) as file:
        nodes, held = file["nodes/params"].shape[0], file["validation/params"].shape[0]
    assert nodes == design and 0 < held <= max(8, design // 4)
    runs_line_agrees_with_the_file(path)


def test_a_heavy_tailed_hermite_response_is_flagged_at_its_true_crossing(tmp_path):
    """Item 4: y = sinh(0.6 z t), z ~ N(0, 1), order 4 (5 runs): the std, √((e^{0.72 t²} − 1)/2)
    in closed form, passes 5 % of the largest std at t = 3.45; the default check (8 runs)
    flags it within 5 % of the horizon and calls no time past the crossing reliable."""
    path = _study(tmp_path, "sinh_growth", 1, "{kind: collocation, order: 4}", 5.0)
    times, error, verdict = _true_error(path, lambda z, t: np.sinh(0.6 * z * t), normal=True)
    crossing = times[np.argmax(error > 0.05)]
    assert 3.3 < crossing < 3.6  # the closed form's, not the code's
    assert abs(verdict["failing_from"] - crossing) <= 0.05 * times[-1]
    with h5py.File(path) as file:
        assert file["validation/params"].shape[0] <= 8


def test_a_jump_in_the_initial_condition_is_never_called_reliable_past_its_crossing(tmp_path):
    """Item 4, Done when: sign(x0 − 0.2)(1 − e^{−t}) + 0.1 x0, x0 ~ U[−1, 1], order 5: every
    time whose true error passes 5 % is flagged or undecided, and the flag is within 5 % of the
    horizon of the true crossing (t = 0.30)."""
    path = _study(tmp_path, "jump", 1, "{kind: collocation, order: 5}", 3.0)
    response = lambda x, t: np.where(x > 0.2, 1.0, -1.0) * (1 - np.exp(-t)) + 0.1 * x  # noqa: E731
    times, error, verdict = _true_error(path, response, cut=0.2)
    judged = verdict["undecided"] | (times >= verdict["failing_from"])
    assert not np.any((error > 0.05) & ~judged), times[(error > 0.05) & ~judged]
    assert abs(verdict["failing_from"] - times[np.argmax(error > 0.05)]) <= 0.05 * times[-1]


def test_elements_auto_held_to_two_elements_is_not_flagged_below_the_tolerance(tmp_path):
    """Done when, no false alarm: the same jump, ``elements: auto`` at order 3 held to 2
    elements (12 runs): its true error stays below the tolerance (5 % of the largest std), so a
    flag would be a false alarm."""
    method = "{kind: collocation, order: 3, elements: auto, max_elements: 2}"
    path = _study(tmp_path, "jump", 1, method, 3.0)
    response = lambda x, t: np.where(x > 0.2, 1.0, -1.0) * (1 - np.exp(-t)) + 0.1 * x  # noqa: E731
    _, error, verdict = _true_error(path, response, cut=0.2)
    assert error.max() < 0.05  # the premise: the truth is below the tolerance everywhere
    assert np.isnan(verdict["failing_from"])


def test_a_degenerate_design_without_a_check_is_not_called_reliable(tmp_path):
    """Done when, a degenerate design is flagged: |x1| |x2| (1 + t) at tensor order 1 puts both
    Gauss points of each input at ±1/√3, all 4 runs equal; with ``validation: 0`` the
    ``runs-all-equal`` record must not stand beside a verdict of "reliable"."""
    method = "{kind: collocation, order: 1, validation: 0}"
    path = _study(tmp_path, "kinks", 2, method, 2.0)
    shown = inspect(path)
    assert "[runs-all-equal]" in shown
    (checked,) = [line for line in shown.splitlines() if line.startswith("checked")]
    assert "reliable" not in checked.replace("UNRELIABLE", ""), checked


def test_a_zero_variance_at_the_initial_time_raises_no_leave_one_out_error(tmp_path):
    """Item 5: exp(0.3 x1 t) cos((1 + 0.2 x2) t) equals 1 at t = 0 at every run. LARS fits it
    within 1e-4 of the std; the output that does not vary at t = 0 is recorded
    (``sobol-undefined``), not read as a leave-one-out error."""
    path = _study(tmp_path, "smooth", 2, "{kind: regression, samples: 40, order: 6, seed: 3}", 3.0)
    shown = inspect(path)
    assert "[sobol-undefined]" in shown
    (fit,) = [line for line in shown.splitlines() if line.startswith("fit")]
    loo = float(re.search(r"leave-one-out error up to (\S+),", fit).group(1))
    assert loo < 0.01 and "[regression-loo]" not in shown, shown


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="the sequential drawn check is at its stated confidence, not beyond it: seeds 0 and 7 "
    "of 0-9 call a time past the crossing reliable (seed 7 only t = 0.9, where the truth is "
    "2.001 %), 3 of 0-29 and 10 of 0-99, the 10 % that 90 % one-sided confidence allows "
    "(tests/test_held_out_noise.py); at 10 % two of ten seeds happen one time in four",
)
def test_the_sequential_check_of_two_kinks_is_right_at_its_stated_confidence(tmp_path):
    """Item 4: |x1| |x2| (1 + t) on U[-1, 1]², tensor order 7 (64 runs), tolerance 0.02: its
    true error, 3.16 % of the largest std at t = 2 (8-point Gauss on |x|, in closed form),
    passes 2 % at t = 0.9. Over seeds 0-9 of the default check (8 runs, then 8 more where
    undecided), at 90 % one-sided confidence at most one seed may call a time past the crossing
    reliable, and at most one may flag 5 % of the horizon or more before it."""
    misses = early = 0
    for seed in range(10):
        folder = tmp_path / str(seed)
        folder.mkdir()
        method = f"{{kind: collocation, order: 7, seed: {seed}}}"
        path = _study(folder, "kinks", 2, method, 2.0, "diagnostics: {tolerance: 0.02}")
        with h5py.File(path) as file:
            times = file["time"][:]
            found = file["diagnostics/y"]
            mean, std = 0.25 * (1 + times), np.sqrt(1 / 9 - 1 / 16) * (1 + times)
            error = (
                np.fmax(abs(file["outputs/y/mean"][:] - mean), abs(file["outputs/y/std"][:] - std))
                / found.attrs["scale"]
            )
            flagged = found.attrs["failing_from"]
            judged = found["undecided"][:] | (times >= flagged)
        crossing = times[np.argmax(error > 0.02)]
        assert 0.85 < crossing < 0.95
        misses += bool(np.any((error > 0.02) & ~judged))
        early += bool(flagged < crossing - 0.05 * times[-1])
    assert misses <= 1 and early <= 1, (misses, early)


@pytest.mark.parametrize(
    ("code", "exit_code", "named"),
    [
        ('raise RuntimeError("broken at import")', 2, "model.entry: importing"),
        (
            "import os\n\n\nclass Entry:\n    def __init__(self, x1=0.0):\n        os._exit(7)",
            3,
            "",
        ),
    ],
)
def test_a_model_that_cannot_be_built_exits_as_documented(tmp_path, code, exit_code, named):
    """README, exit codes: a python entry whose import raises is an invalid config at
    ``model.entry`` (2); a model whose building kills its worker could not be built (3)."""
    (tmp_path / "entry.py").write_text(code + "\n\n\ndef f():\n    pass\n")
    entry = "f" if exit_code == 2 else "Entry"
    (tmp_path / "study.yaml").write_text(
        f"name: broken\nmodel: {{kind: python, entry: entry.py:{entry}, params: {{x1: 0.0}}, "
        "outputs: [y]}\n"
        f"time: {{start: 0.0, stop: 1.0, points: 3}}\ninputs: {{x1: {UNIFORM}}}\n"
        "method: {kind: collocation, order: 1}\noutput: out.h5\n"
    )
    done = pcmb_here("run", "study.yaml", "--quiet", cwd=tmp_path)
    assert done.returncode == exit_code and named in done.stderr, done.stderr
    assert not (tmp_path / "out.h5").exists()


@pytest.mark.slow
def test_a_heavy_tailed_response_of_two_normal_inputs_does_not_fool_the_drawn_check(tmp_path):
    """Item 4: exp(0.4 (z1 + z2) t), z1, z2 ~ N(0, 1), tensor order 4 (25 runs, a drawn check
    of 8): mean exp(0.16 t²) and std √(e^{0.64 t²} − e^{0.32 t²}) in closed form; the std's
    error passes 5 % of the largest std at t = 3.5 and reaches 37 % at t = 4. Over seeds 0-9,
    at most one may call a time past the crossing reliable (90 % one-sided confidence)."""
    misses = 0
    for seed in range(10):
        folder = tmp_path / str(seed)
        folder.mkdir()
        method = f"{{kind: collocation, order: 4, seed: {seed}}}"
        path = _study(folder, "lognormal2", 2, method, 4.0)
        with h5py.File(path) as file:
            times = file["time"][:]
            found = file["diagnostics/y"]
            mean = np.exp(0.16 * times**2)
            std = np.sqrt(np.exp(0.64 * times**2) - np.exp(0.32 * times**2))
            error = (
                np.fmax(abs(file["outputs/y/mean"][:] - mean), abs(file["outputs/y/std"][:] - std))
                / found.attrs["scale"]
            )
            judged = found["undecided"][:] | (times >= found.attrs["failing_from"])
        assert times[np.argmax(error > 0.05)] == pytest.approx(3.5) and error[-1] > 0.3
        misses += bool(np.any((error > 0.05) & ~judged))
    assert misses <= 1, misses
