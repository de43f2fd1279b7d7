"""The command line: run, validate, inspect, schema, exit codes, resume after SIGKILL."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.cli import main

DATA = Path(__file__).parent / "data"


def test_run_writes_a_complete_result(tmp_path, linear_study, capsys):
    config = linear_study()
    out = tmp_path / "explicit.h5"
    assert main(["run", str(config), "-o", str(out), "--quiet"]) == 0
    result = pcmb.load(out)
    # y = a t + b², a ~ U[1, 3], b ~ N(0, 1): E y = 2t + 1.
    np.testing.assert_allclose(result.mean("y"), 2 * result.times + 1, atol=1e-12)
    captured = capsys.readouterr()
    assert captured.out == "" and "wrote" in captured.err
    assert not (tmp_path / "explicit.h5.journal").exists()


def test_output_from_the_config_and_inspect(tmp_path, linear_study, capsys):
    config = linear_study()
    assert main(["run", str(config), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "out.h5")]) == 0
    report = capsys.readouterr().out
    assert "16 ok, 0 failed" in report and "y" in report and "16 terms" in report
    assert "design   kind collocation, grid tensor-gauss, basis tensor, orders (3, 3)" in report
    # Every run made is counted, and every input is shown with its law.
    held_out = len(pcmb.load(tmp_path / "out.h5").held_out.ok)
    assert (
        f"runs     {16 + held_out + 1} in all: 16 of the design, {held_out} held-out "
        f"({held_out} ok), 1 nominal"
    ) in report
    assert "inputs   a ~ uniform(low=1, high=3), b ~ normal(mean=0, std=1)" in report


def test_validate_prints_a_summary_and_runs_nothing(tmp_path, linear_study, capsys):
    config = linear_study()
    assert main(["validate", str(config)]) == 0
    summary = capsys.readouterr().out
    assert "method   collocation: chaos order 3, tensor-gauss nodes" in summary
    assert "16 model runs" in summary and "uniform(low=1.0, high=3.0)" in summary
    assert "\nsize     about " in summary and "free there" in summary
    assert not (tmp_path / "out.h5").exists()


BUILD_MARKER_MODEL = """
import os

import numpy as np


class Marked:
    outputs = ("y",)

    def __init__(self, a=1.0, marker=""):
        self.parameters = {"a": a}
        with open(marker, "a") as file:
            file.write(f"{os.getpid()}\\n")

    def simulate(self, params, times):
        return {"y": np.asarray(params["a"], float)[:, None] * times}
"""


@pytest.mark.slow
def test_validate_builds_the_model_once_in_one_worker_process_without_a_pool(tmp_path):
    """pcmb validate checks the config and the study in one short-lived worker process, where
    the model is built once; pcmb's own process starts no loky pool (never imports joblib)."""
    (tmp_path / "marked.py").write_text(BUILD_MARKER_MODEL)
    marker = tmp_path / "built"
    config = tmp_path / "marked.yaml"
    config.write_text(
        "name: marked\n"
        "model: {kind: python, entry: marked.py:Marked, params: {a: 1.0, marker: MARKER}}\n"
        "time: {start: 0.0, stop: 1.0, points: 3}\n"
        "inputs: {a: {dist: uniform, low: 1.0, high: 2.0}}\n"
        "method: {kind: collocation, order: 2}\n"
        "execution: {jobs: 2, backend: loky}\n".replace("MARKER", f"'{marker}'")
    )
    code = (
        "import os, sys\n"
        "from pcmb.cli import main\n"
        f"assert main(['validate', {str(config)!r}]) == 0\n"
        "print(os.getpid(), 'joblib' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    pid, joblib = done.stdout.split()[-2:]
    built = marker.read_text().split()
    assert len(built) == 1 and built[0] != pid, built
    assert joblib == "False"


def test_schema_is_json(capsys):
    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert "properties" in schema or "$defs" in schema


def test_invalid_config_exits_2_without_traceback_or_file(tmp_path, linear_study, capsys):
    config = linear_study()
    config.write_text(config.read_text().replace("high: 3.0", "high: 0.5"))
    assert main(["run", str(config)]) == 2
    err = capsys.readouterr().err
    assert "inputs.a" in err and "Traceback" not in err
    assert not (tmp_path / "out.h5").exists()


def test_usage_errors_exit_2(capsys):
    assert main(["run"]) == 2
    assert main(["frobnicate"]) == 2


def test_result_file_errors_exit_2_with_their_kind(tmp_path, capsys):
    assert main(["inspect", "/nonexistent.h5"]) == 2
    assert capsys.readouterr().err == "pcmb: file: /nonexistent.h5: no such file\n"
    garbage = tmp_path / "garbage.h5"
    garbage.write_text("not a result")
    assert main(["report", str(garbage)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pcmb: file: ") and "not a readable pcmb result file" in err
    assert "invalid configuration" not in err and "Traceback" not in err


def test_bad_jobs_is_a_usage_error(tmp_path, linear_study, capsys):
    config = linear_study()
    assert main(["run", str(config), "--jobs", "0"]) == 2
    assert capsys.readouterr().err == "pcmb: usage: --jobs must be >= 1, got 0\n"
    assert not (tmp_path / "out.h5").exists()


def test_run_builds_one_study_with_the_command_lines_execution(tmp_path, linear_study, monkeypatch):
    """--jobs and --backend are folded into the config's execution before the one study is
    built (not a study built, then rebuilt with them)."""
    built = []
    real_init = pcmb.Study.__init__

    def counted(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        built.append(self.execution)

    monkeypatch.setattr(pcmb.Study, "__init__", counted)
    config = linear_study(execution="jobs: 2, on_failure: regress")
    argv = ["run", str(config), "--jobs", "1", "--backend", "inprocess", "--quiet"]
    assert main(argv) == 0
    assert len(built) == 1
    assert (built[0].jobs, built[0].backend, built[0].on_failure) == (1, "inprocess", "regress")


def test_model_failure_exits_3_naming_the_nodes(tmp_path, linear_study, capsys):
    config = linear_study(extra_params=", fail_above: 2.5")
    assert main(["run", str(config), "--quiet"]) == 3
    err = capsys.readouterr().err
    assert "blew up at a=2.86" in err and "node 12 (a=2.86" in err
    assert not (tmp_path / "out.h5").exists()
    # Finished nodes are not lost: the journal stays, and a plain re-run refuses to clobber it.
    assert (tmp_path / "out.h5.journal").is_dir()
    assert main(["run", str(config), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_regress_policy_records_the_failures(tmp_path, linear_study):
    config = linear_study(
        extra_params=", fail_above: 2.5", execution="jobs: 1, on_failure: regress"
    )
    assert main(["run", str(config), "--quiet"]) == 0
    result = pcmb.load(tmp_path / "out.h5")
    assert np.sum(result.status == 2) == 4
    assert any("left out" in w.message for w in result.warnings)


@pytest.mark.slow
def test_sigkill_then_resume_gives_identical_results(tmp_path, linear_study):
    """Kill a real `pcmb run` mid-way; --resume runs only the rest and matches a clean run.

    64 nodes at 0.05 s each in the killed run (3.2 s; none in the resume) in chunks of 4:
    the kill after 3 records leaves ~2.6 s of slack before the run could finish on its own.
    """
    config = linear_study(order=7, execution="jobs: 1, chunk_size: 4")
    out = tmp_path / "out.h5"
    journal = tmp_path / "out.h5.journal"
    command = [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet"]
    slow = {**os.environ, "LINEAR_DELAY": "0.05"}
    process = subprocess.Popen(command, cwd=tmp_path, env=slow, start_new_session=True)
    deadline = time.monotonic() + 60
    while len(list(journal.glob("record-*.npz"))) < 3:
        assert process.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert not out.exists()
    done_before = len(list(journal.glob("record-*.npz")))
    assert 3 <= done_before < 16  # 64 nodes in chunks of 4

    assert main(["run", str(config), "--resume", "--quiet"]) == 0
    resumed = pcmb.load(out)
    assert not journal.exists()

    # The reference: the same study run whole.
    again = linear_study(order=7, execution="jobs: 1, chunk_size: 4", name="clean")
    clean = tmp_path / "clean.h5"
    assert main(["run", str(again), "-o", str(clean), "--quiet"]) == 0
    reference = pcmb.load(clean)
    for name in ("y", "z"):
        np.testing.assert_array_equal(resumed.values[name], reference.values[name])
        np.testing.assert_array_equal(
            resumed.expansions[name].coefficients, reference.expansions[name].coefficients
        )


@pytest.mark.slow
def test_a_run_imports_no_heavy_module_it_does_not_need(linear_study):
    """`pcmb run` of a python-kind study must not import mujoco, matplotlib, scipy.stats/signal.
    At order 1, as its expansion has no curved tail, the study draws its held-out runs: a
    placed check (one input, or a tail along one normal input, as b² at order 3) needs
    scipy.stats for the germ's density at its Leja points."""
    config = linear_study(order=1)
    code = (
        "import sys; from pcmb.cli import main; "
        f"assert main(['run', {str(config)!r}, '--quiet']) == 0; "
        "print(sorted(m for m in ('mujoco', 'matplotlib', 'scipy.stats', 'scipy.signal', "
        "'distributed') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _decay_config(tmp_path, time: str, extra: str = "") -> str:
    """y = exp(-k t) with k log-uniform on [0.1, 10] (tests/data/toy_models.py's Decay)."""
    config = tmp_path / "decay.yaml"
    config.write_text(
        f"""\
name: decay
model:
  kind: python
  entry: {DATA / "toy_models.py"}:Decay
  params: {{k: 1.0, y0: 1.0}}
  outputs: [y]
time: {time}
inputs:
  k: {{dist: loguniform, low: 0.1, high: 10.0}}
method: {{kind: collocation, order: 10}}
execution: {{jobs: 1}}
output: {tmp_path / "decay.h5"}
{extra}"""
    )
    return str(config)


def test_log_spaced_times_and_a_loguniform_rate(tmp_path):
    from scipy.special import exp1

    config = _decay_config(tmp_path, "{start: 1.0e-3, stop: 20.0, points: 30, spacing: log}")
    assert main(["run", config, "--quiet"]) == 0
    result = pcmb.load(tmp_path / "decay.h5")
    np.testing.assert_allclose(result.times, np.geomspace(1e-3, 20.0, 30), rtol=1e-15)
    # Order 10 in the Legendre germ of ln k: the mean is the 11-point Gauss-Legendre rule in
    # ln k, to round-off; and that rule is the closed form E exp(-k t) = (E1(0.1 t) -
    # E1(10 t)) / ln 100 up to its own error, which shrinks geometrically with the points.
    t = result.times
    nodes, weights = np.polynomial.legendre.leggauss(11)
    rates = np.exp(np.log(10.0) * nodes)  # ln k = ln 0.1 + (ln 100)(ξ + 1)/2
    rule = (weights / 2) @ np.exp(-np.outer(rates, t))
    np.testing.assert_allclose(result.mean("y"), rule, rtol=1e-12, atol=1e-15)
    exact = (exp1(0.1 * t) - exp1(10.0 * t)) / np.log(100.0)
    finer_nodes, finer_weights = np.polynomial.legendre.leggauss(22)
    finer = (finer_weights / 2) @ np.exp(-np.outer(np.exp(np.log(10.0) * finer_nodes), t))
    np.testing.assert_allclose(finer, exact, atol=1e-12)  # the rule converges to the law


def test_listed_times_are_the_grid_and_a_spectrum_refuses_them(tmp_path, capsys):
    config = _decay_config(tmp_path, "{values: [0.0, 0.5, 2.0, 5.0]}")
    assert main(["run", config, "--quiet"]) == 0
    np.testing.assert_array_equal(pcmb.load(tmp_path / "decay.h5").times, [0.0, 0.5, 2.0, 5.0])
    capsys.readouterr()
    config = _decay_config(tmp_path, "{values: [0.0, 0.5, 2.0, 5.0]}", "analysis: {psd: [y]}\n")
    assert main(["validate", config]) == 2
    assert "analysis.psd: a spectrum needs a uniform time grid" in capsys.readouterr().err


def test_validate_sizes_the_file_for_the_runs_a_refining_design_may_make(
    tmp_path, linear_study, capsys
):
    """``order: auto`` may end with its ``max_runs`` (200) design runs, checked by up to 50
    held-out runs (max(8, ¼ of them)), all stored and journaled: the size line counts 250
    runs, not the first round's nodes."""
    from pcmb.run.output import estimate_size, format_bytes

    config = linear_study()
    text = config.read_text().replace("order: 3}", "order: auto, max_runs: 200}")
    config.write_text(text.replace("  b: {dist: normal, mean: 0.0, std: 1.0}\n", ""))
    assert main(["validate", str(config)]) == 0
    summary = capsys.readouterr().out
    assert "at most 200 in all + 8 to 50 held-out runs" in summary
    # 5 times, outputs y and z, input a.
    size = format_bytes(estimate_size(200 + 50, 5, 2, 1).total)
    assert f"\nsize     about {size} at most" in summary, summary.splitlines()[-2]
