"""docs/models.md and its runnable examples, end to end.

Every example runs as a user would run it (``pcmb run`` through :func:`pcmb.cli.main`, or the
example script's ``main``), and its numbers are checked against closed forms:

- the damped oscillator (docs/examples/python_oscillator.yaml in every python form,
  oscillator_api.py, configs/command_oscillator.yaml, docs/examples/command_deck.yaml):
  x(t) = e^{-ct/2} (cos ωt + c/(2ω) sin ωt), ω = sqrt(k - c²/4);
- the series RLC circuit in ngspice (configs/ngspice_rlc.yaml, when ngspice is on PATH): the
  same oscillator with k = 1/(LC), c = R/L;
- the pendulum (configs/mujoco_pendulum.yaml, docs/examples/mujoco_pendulum_bind.yaml,
  mujoco_api.py): θ(t) = 2 asin(k sn(K(k) - sqrt(g/L) t, k)), k = sin(θ0/2).

Two checks per statistic. On the result's own nodes, the collocation mean and std are the
tensor Gauss quadratures of the node values, so with the closed form at those nodes they must
agree to rounding (or to the simulator's own integration error): this checks that the door
passes every value exactly. Against a converged reference (a tensor Gauss–Legendre rule with
many more points, independent of pcmb), they must agree to the truncation error of the
example's order: the responses are analytic in the inputs, so that error falls by orders of
magnitude per order, and each tolerance sits between the example's order and the order below
(the tests check that the order below misses it, so the check is not vacuous).

Code blocks of docs/models.md captioned ``File [`path`](link):`` must equal that file;
blocks captioned ``From [`path`](link):`` must be a verbatim run of its lines.
"""

from __future__ import annotations

import os
import re
import runpy
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss

import pcmb
from pcmb.cli import main
from pcmb.references import damped_oscillator, pendulum_angle

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGE = DOCS / "models.md"
EXAMPLES = DOCS / "examples"
CLI_SCRIPT = ROOT / "models" / "oscillator_cli.py"

# The oscillator examples: k ~ U[3.5, 4.5], c ~ U[0.2, 0.6], x(0) = 1 at rest, t in [0, 5].
K_RANGE, C_RANGE = (3.5, 4.5), (0.2, 0.6)
OSCILLATOR_TIMES = np.linspace(0.0, 5.0, 101)
# Order 4: the mean of x is within 2e-12 and its std within 2e-9 of the converged values over
# the grid; order 3 misses the std by 2e-7 (test_oscillator_tolerance_has_teeth).
OSCILLATOR_ORDER, OSCILLATOR_TOLERANCE = 4, 1e-8


def gauss_statistics(function, ranges, points):
    """Mean and std of ``function(*inputs)``, (N, T), for independent uniform inputs on
    ``ranges``, by a tensor Gauss–Legendre rule of ``points`` points per input."""
    z, w = leggauss(points)
    axes = [lo + (hi - lo) * (z + 1) / 2 for lo, hi in ranges]
    grids = np.meshgrid(*axes, indexing="ij")
    weights = np.ones(1)
    for _ in ranges:
        weights = np.multiply.outer(weights, w / 2).ravel()
    values = function(*(g.ravel() for g in grids))
    mean = weights @ values
    return mean, np.sqrt(weights @ (values - mean) ** 2)


def node_statistics(result, name, reference):
    """Mean and std, (T,), of ``reference`` at the result's nodes, by the result's weights."""
    values = reference(*result.params.T)
    mean = result.weights @ values
    return mean, np.sqrt(result.weights @ (values - mean) ** 2)


def oscillator_x(k, c):
    return damped_oscillator(OSCILLATOR_TIMES, k, c)


# The RLC example: R ~ U[8, 12] ohm, L ~ U[0.9, 1.1] mH, C ~ U[0.9, 1.1] uF, t in [0, 1 ms].
RLC_RANGES = [(8.0, 12.0), (0.9e-3, 1.1e-3), (0.9e-6, 1.1e-6)]
RLC_TIMES = np.linspace(0.0, 1e-3, 201)
RLC_ORDER = 4
# output -> (tolerance of node values and mean, tolerance of the std). ngspice's trapezoidal
# steps (at most a hundredth of the output step) put every node within 7e-7 V of the exact vc
# and 2.2e-8 A of il, and the mean inherits that bias (4.7e-7 V, 1.5e-8 A); the std is off by
# 9e-8 V and 3e-9 A, and order 4 by 4e-8 V and 9e-10 A, while order 3 misses it by 1.3e-6 V
# and 2.9e-8 A (test_rlc_tolerance_has_teeth).
RLC_TOLERANCES = {"vc": (1.5e-6, 3e-7), "il": (5e-8, 1e-8)}
INSTALL_NGSPICE = "apt-get install ngspice, brew install ngspice or conda-forge's ngspice"


def rlc_vc(R, L, C):
    """Capacitor voltage (N, T) of the discharging series RLC circuit, from 1 V."""
    return damped_oscillator(RLC_TIMES, 1 / (L * C), R / L)


def rlc_il(R, L, C):
    """Loop current (N, T), -C vc' = e^{-ct/2} sin(ωt) / (L ω)."""
    R, L, C = (np.asarray(v, dtype=float)[..., None] for v in (R, L, C))
    c, omega = R / L, np.sqrt(1 / (L * C) - (R / L) ** 2 / 4)
    return np.exp(-c * RLC_TIMES / 2) * np.sin(omega * RLC_TIMES) / (L * omega)


@pytest.fixture
def fresh_example_module():
    """Forget ``damped_oscillator`` imported by module name, before and after the test."""
    sys.modules.pop("damped_oscillator", None)
    yield
    sys.modules.pop("damped_oscillator", None)


def run_config(config: Path, out: Path, *extra: str):
    """``pcmb run CONFIG -o OUT --quiet`` must succeed; the result read back."""
    assert main(["run", str(config), "-o", str(out), "--quiet", *extra]) == 0
    return pcmb.load(out)


def check_oscillator(result, *, node_tolerance=1e-12):
    """x of an oscillator example against the closed form, node by node and in statistics."""
    assert result.input_names == ("k", "c")
    assert np.array_equal(result.times, OSCILLATOR_TIMES)
    assert result.values["x"].shape == ((OSCILLATOR_ORDER + 1) ** 2, OSCILLATOR_TIMES.size)
    exact = oscillator_x(*result.params.T)
    assert np.abs(result.values["x"] - exact).max() <= node_tolerance
    mean, std = node_statistics(result, "x", oscillator_x)
    assert np.abs(result.mean("x") - mean).max() <= node_tolerance + 1e-14
    assert np.abs(result.std("x") - std).max() <= node_tolerance + 1e-14
    mean, std = gauss_statistics(oscillator_x, [K_RANGE, C_RANGE], 60)
    assert np.abs(result.mean("x") - mean).max() <= OSCILLATOR_TOLERANCE
    assert np.abs(result.std("x") - std).max() <= OSCILLATOR_TOLERANCE


def test_oscillator_tolerance_has_teeth():
    converged = gauss_statistics(oscillator_x, [K_RANGE, C_RANGE], 60)
    at_order = gauss_statistics(oscillator_x, [K_RANGE, C_RANGE], OSCILLATOR_ORDER + 1)
    below = gauss_statistics(oscillator_x, [K_RANGE, C_RANGE], OSCILLATOR_ORDER)
    for a, b in zip(at_order, converged, strict=True):  # mean, std
        assert np.abs(a - b).max() < OSCILLATOR_TOLERANCE / 4
    assert np.abs(below[1] - converged[1]).max() > 10 * OSCILLATOR_TOLERANCE


# --------------------------------------------------------------------------- kind: python


def test_python_example_config_as_is(tmp_path):
    result = run_config(EXAMPLES / "python_oscillator.yaml", tmp_path / "out.h5")
    check_oscillator(result)
    assert result.nominal_params == {"k": 4.0, "c": 0.4}  # model.params


@pytest.mark.slow
@pytest.mark.parametrize(
    ("entry", "node_tolerance"),
    [
        ("damped_oscillator.py:oscillator_point", 1e-12),
        ("damped_oscillator.py:oscillator_batch", 1e-12),
        ("damped_oscillator.py:OscillatorODE", 1e-8),  # DOP853 at rtol 1e-10, atol 1e-12
        ("damped_oscillator.py:FACTORY", 1e-12),
        ("damped_oscillator:Oscillator", 1e-12),  # package.module:Name
    ],
)
def test_python_example_config_with_every_entry(
    tmp_path, entry, node_tolerance, fresh_example_module
):
    # The config's other entries, as its comment lists them (copied with the model file, so
    # that the relative entry resolves in tmp_path).
    shutil.copy(EXAMPLES / "damped_oscillator.py", tmp_path)
    text = (EXAMPLES / "python_oscillator.yaml").read_text(encoding="utf-8")
    old = "entry: damped_oscillator.py:Oscillator "
    assert old in text
    text = text.replace(old, f"entry: {entry} ")
    if entry.endswith("FACTORY"):
        text, count = re.subn(r"\n  params: .*", "", text)
        assert count == 1
    config = tmp_path / "python_oscillator.yaml"
    config.write_text(text, encoding="utf-8")
    result = run_config(config, tmp_path / "out.h5")
    check_oscillator(result, node_tolerance=node_tolerance)


def test_python_example_from_the_api(capsys, monkeypatch, fresh_example_module):
    monkeypatch.syspath_prepend(str(EXAMPLES))  # as `python docs/examples/oscillator_api.py`
    results = runpy.run_path(str(EXAMPLES / "oscillator_api.py"))["main"](jobs=1)
    assert set(results) == {
        "class",
        "per-point function",
        "batch function",
        "stacked ODE",
        "factory",
    }
    for label, result in results.items():
        check_oscillator(result, node_tolerance=1e-8 if label == "stacked ODE" else 1e-12)
        assert result.values.keys() == {"x", "v"}
    exact = results["class"]
    for label in ("per-point function", "batch function", "factory"):
        assert np.array_equal(results[label].values["x"], exact.values["x"]), label
        assert np.array_equal(results[label].values["v"], exact.values["v"]), label
    assert len(capsys.readouterr().out.splitlines()) == 5


def test_unmarked_function_error_is_the_one_the_page_shows(tmp_path, capsys):
    (tmp_path / "unmarked.py").write_text(
        "import numpy as np\n\n\ndef oscillator(params, times):\n"
        '    return {"x": np.cos(2 * times)}\n'
    )
    text = (EXAMPLES / "python_oscillator.yaml").read_text(encoding="utf-8")
    text = text.replace("entry: damped_oscillator.py:Oscillator ", "entry: unmarked.py:oscillator ")
    (tmp_path / "unmarked.yaml").write_text(text.replace("outputs: [x, v]", "outputs: [x]"))
    assert main(["validate", str(tmp_path / "unmarked.yaml")]) == 2
    err = capsys.readouterr().err
    message = err.split("model.entry: ", 1)[1].strip()
    assert message.startswith("oscillator is an unmarked function")
    page = " ".join(PAGE.read_text(encoding="utf-8").split())
    assert message in page


# --------------------------------------------------------------------------- kind: command


def test_command_script_runs_by_itself():
    text = CLI_SCRIPT.read_text(encoding="utf-8")
    assert text.startswith("#!/usr/bin/env python3\n")
    assert os.access(CLI_SCRIPT, os.X_OK), "chmod +x models/oscillator_cli.py"
    imports = set(re.findall(r"^import (\w+)|^from (\w+)", text, re.MULTILINE))
    assert {name for pair in imports for name in pair if name} <= set(sys.stdlib_module_names)


@pytest.mark.slow
def test_command_config(tmp_path):
    result = run_config(ROOT / "configs" / "command_oscillator.yaml", tmp_path / "out.h5")
    check_oscillator(result)
    # v = x' from the same file: e^{-ct/2} (-k/ω) sin ωt from rest at x = 1.
    k, c = result.params.T[:, :, None]
    omega = np.sqrt(k - c**2 / 4)
    v = -np.exp(-c * OSCILLATOR_TIMES / 2) * k / omega * np.sin(omega * OSCILLATOR_TIMES)
    assert np.abs(result.values["v"] - v).max() <= 1e-12


@pytest.mark.slow
def test_command_deck_example(tmp_path):
    result = run_config(EXAMPLES / "command_deck.yaml", tmp_path / "out.h5")
    check_oscillator(result)
    assert result.values.keys() == {"x"}


def test_command_failed_runs_keep_their_work_directory(tmp_path):
    # A deck without k: the script exits with code 2; every node fails, the policy aborts.
    deck = (EXAMPLES / "oscillator_deck.txt").read_text(encoding="utf-8")
    (tmp_path / "oscillator_deck.txt").write_text(deck.replace("k = {{ k }}\n", ""))
    text = (EXAMPLES / "command_deck.yaml").read_text(encoding="utf-8")
    text = text.replace("../../models/oscillator_cli.py", str(CLI_SCRIPT))
    text = text.replace("order: 4", "order: 1")
    text = text.replace("keep: failed", f"run_dir: {tmp_path / 'nodes'}\n  keep: failed")
    # One chunk, so abort sees every node of it fail (it stops dispatching after a failure).
    text = text.replace("on_failure: abort}", "on_failure: abort, chunk_size: 4}")
    (tmp_path / "broken.yaml").write_text(text, encoding="utf-8")
    out = tmp_path / "out.h5"
    assert main(["run", str(tmp_path / "broken.yaml"), "-o", str(out), "--quiet"]) == 3
    assert not out.exists()
    kept = sorted((tmp_path / "nodes").iterdir())
    # 2 x 2 nodes, and the held-out runs that had started beside them (in the same campaign)
    # when abort saw them fail: each failed at the deck.
    assert len(kept) >= 4
    for workdir in kept:
        assert {p.name for p in workdir.iterdir()} == {
            "oscillator_deck.txt",
            "params.json",
            "stdout.txt",
            "stderr.txt",
        }
        assert "KeyError: 'k'" in (workdir / "stderr.txt").read_text()


def test_rlc_tolerance_has_teeth():
    for name, exact in (("vc", rlc_vc), ("il", rlc_il)):
        converged = gauss_statistics(exact, RLC_RANGES, 24)
        at_order = gauss_statistics(exact, RLC_RANGES, RLC_ORDER + 1)
        below = gauss_statistics(exact, RLC_RANGES, RLC_ORDER)
        tolerance, std_tolerance = RLC_TOLERANCES[name]
        assert np.abs(at_order[0] - converged[0]).max() < tolerance / 4
        assert np.abs(at_order[1] - converged[1]).max() < std_tolerance / 4
        assert np.abs(below[1] - converged[1]).max() > 2 * std_tolerance


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("ngspice") is None, reason=f"ngspice is not on PATH ({INSTALL_NGSPICE})"
)
def test_ngspice_rlc_config(tmp_path):
    result = run_config(ROOT / "configs" / "ngspice_rlc.yaml", tmp_path / "out.h5")
    assert result.input_names == ("R", "L", "C")
    assert np.array_equal(result.times, RLC_TIMES)
    assert result.params.shape == ((RLC_ORDER + 1) ** 3, 3)
    for name, exact in (("vc", rlc_vc), ("il", rlc_il)):
        tolerance, std_tolerance = RLC_TOLERANCES[name]
        assert np.abs(result.values[name] - exact(*result.params.T)).max() <= tolerance
        mean, std = gauss_statistics(exact, RLC_RANGES, 24)
        assert np.abs(result.mean(name) - mean).max() <= tolerance
        assert np.abs(result.std(name) - std).max() <= std_tolerance


# --------------------------------------------------------------------------- kind: mujoco


@pytest.mark.slow
def test_mujoco_pendulum_config(tmp_path):
    result = run_config(ROOT / "configs" / "mujoco_pendulum.yaml", tmp_path / "out.h5")
    times = result.times
    assert times[-1] == 15.0 and result.params.shape == (8, 1)  # order 7

    def theta(length):
        return pendulum_angle(times, length)

    # RK4 at 1 ms: below 1e-10 rad per node over 15 s (models/mujoco/pendulum.xml).
    assert np.abs(result.values["theta"] - theta(result.params[:, 0])).max() <= 1e-9
    mean, std = node_statistics(result, "theta", theta)
    assert np.abs(result.mean("theta") - mean).max() <= 1e-9
    assert np.abs(result.std("theta") - std).max() <= 1e-9
    # Against the converged statistics the truncation error of order 7 grows with time as the
    # nodes' periods drift apart: 2e-8 in the std up to 5 s (order 5: 2e-6), 2e-3 by 15 s.
    mean, std = gauss_statistics(theta, [(0.8, 1.2)], 200)
    early = times <= 5.0
    assert np.abs(result.mean("theta") - mean)[early].max() <= 1e-7
    assert np.abs(result.std("theta") - std)[early].max() <= 1e-7
    assert np.abs(result.std("theta") - std).max() > 1e-4  # the page says why


@pytest.mark.slow
def test_mujoco_bind_example_from_yaml_and_python(tmp_path):
    result = run_config(EXAMPLES / "mujoco_pendulum_bind.yaml", tmp_path / "out.h5")
    times = result.times
    assert result.input_names == ("theta0", "gz")

    def theta(theta0, gz):
        return pendulum_angle(times, np.ones_like(theta0), theta0, g=-gz)

    assert np.abs(result.values["theta"] - theta(*result.params.T)).max() <= 1e-9
    # xpos of the bob: L sin(theta), L = 1 (the hinge axis is -y)
    assert np.abs(result.values["bob_x"] - np.sin(result.values["theta"])).max() <= 1e-12
    # Order 4: within 5e-10 of the converged statistics; order 3 misses the std by 7e-8.
    ranges = [(0.6, 1.0), (-10.3, -9.3)]
    mean, std = gauss_statistics(theta, ranges, 40)
    assert np.abs(result.mean("theta") - mean).max() <= 1e-8
    assert np.abs(result.std("theta") - std).max() <= 1e-8
    below = gauss_statistics(theta, ranges, 4)
    assert np.abs(below[1] - std).max() > 3e-8
    assert result.nominal_params == {"theta0": 0.7853981633974483, "gz": -9.81}
    assert np.abs(result.nominal["theta"] - theta(np.pi / 4, -9.81)).max() <= 1e-9

    api = runpy.run_path(str(EXAMPLES / "mujoco_api.py"))["main"](jobs=1)
    for name in ("theta", "omega", "bob_x"):
        assert np.array_equal(api.values[name], result.values[name])
    assert np.array_equal(api.nominal["theta"], result.nominal["theta"])


# --------------------------------------------------------------------------- the page


CAPTION = re.compile(r"^(File|From) \[`([^`]+)`\]\(([^)]+)\):$")
FENCE = re.compile(r"^```")


def captioned_blocks():
    """(kind, path, link, block text) for every captioned code block of the page."""
    lines = PAGE.read_text(encoding="utf-8").splitlines(keepends=True)
    blocks = []
    for i, line in enumerate(lines):
        match = CAPTION.match(line.rstrip("\n"))
        if not match:
            continue
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        assert j < len(lines) and FENCE.match(lines[j]), f"no code block after line {i + 1}"
        end = next(k for k in range(j + 1, len(lines)) if lines[k].rstrip("\n") == "```")
        blocks.append((*match.groups(), "".join(lines[j + 1 : end])))
    return blocks


def test_page_blocks_captioned_as_files_are_those_files():
    blocks = captioned_blocks()
    assert len(blocks) >= 8
    shown = set()
    for kind, path, link, block in blocks:
        target = ROOT / path
        assert (DOCS / link).resolve() == target.resolve(), f"{path}: link {link}"
        text = target.read_text(encoding="utf-8")
        if kind == "File":
            assert block == text, f"the block captioned {path} differs from the file"
        else:
            assert block.endswith("\n") and block in text, f"block from {path} is not in it"
            assert text.startswith(block) or f"\n{block}" in text, f"{path}: partial lines"
        shown.add(path)
    # every runnable example is on the page
    examples = {f"docs/examples/{p.name}" for p in EXAMPLES.iterdir() if p.is_file()}
    assert examples | {"configs/command_oscillator.yaml"} <= shown


def test_page_names_only_files_that_exist():
    page = PAGE.read_text(encoding="utf-8")
    named = set(re.findall(r"`((?:docs|configs|models|pcmb|tests)/[\w./-]+\.\w+)`", page))
    assert named, "the page names no file"
    missing = sorted(path for path in named if not (ROOT / path).exists())
    assert not missing, missing
    links = set(re.findall(r"\]\(([^)#:]+)\)", page))
    broken = sorted(link for link in links if not (DOCS / link).exists())
    assert not broken, broken
