"""Resuming for real: `pcmb run` processes killed with SIGKILL, edited files, concurrent runs.

A run that is killed, or holds the lock while others try, is a real ``python -m pcmb.cli``
process; the resumes and refusals that follow run :func:`pcmb.cli.main` in this process
(``tests/cli_process.py``): the journal a killed process left is their subject, not the
process. The models of this file block instead of sleeping, so that a kill always lands at a
known point: ``BLOCK_AFTER=K`` in a run's environment makes its model hang (until the run is
killed) at its (K+1)-th call; a study's nodes come first (its held-out runs and nominal run
after them, in the same campaign), so that is after K journaled chunks of one node each; a
design with rounds sends its nominal run ahead of them (``run_and_kill(nominal_first=True)``);
``GATE=path`` makes it wait after the first two nodes for as long as ``path`` exists.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import gated_pcmb, pcmb_here

from pcmb.result import StudyResult
from pcmb.store import load

PYTHON_MODEL = """
import os
import time

import pcmb

CALLS = [0]


@pcmb.pointwise(outputs=("y",))
def line(params, times):
    CALLS[0] += 1
    block = os.environ.get("BLOCK_AFTER")
    if block is not None and CALLS[0] > int(block):
        time.sleep(3600)
    gate = os.environ.get("GATE")
    while gate and CALLS[0] > 2 and os.path.exists(gate):
        time.sleep(0.01)
    return {"y": params["a"] * times + params["b"] ** 2}
"""

#: What the python and command studies share after their model section.
STUDY = """\
time: {start: 0.0, stop: 2.0, points: 5}
inputs:
  a: {dist: uniform, low: 1.0, high: 3.0}
  b: {dist: normal, mean: 0.0, std: 1.0}
method: {kind: collocation, order: 3}
execution: {jobs: 1, chunk_size: 1}
output: out.h5
"""

PYTHON_CONFIG = """\
name: resume
model:
  kind: python
  entry: model.py:line
  params: {a: 1.0, b: 0.0}
"""
PYTHON_CONFIG += STUDY

# A command model: program ./sim.py (a path), a template rendered per node and a data file
# linked into every work directory. With BLOCK_AFTER it counts its runs in CALLS_FILE and
# hangs, until pcmb is killed (its parent changes), at run K+1.
SIMULATOR = """\
#!/usr/bin/env python3
import json
import os
import sys
import time

block, calls = os.environ.get("BLOCK_AFTER"), os.environ.get("CALLS_FILE")
if block and calls:
    with open(calls, "a") as log:
        log.write("run\\n")
    with open(calls) as log:
        if sum(1 for _ in log) > int(block):
            parent = os.getppid()
            while os.getppid() == parent:
                time.sleep(0.01)
            sys.exit(1)
scale = float(open("scale.txt").read())
a = float(open("input.txt").read().split("=")[1])
document = json.load(open(sys.argv[1]))
b = document["params"]["b"]
with open("out.csv", "w") as out:
    out.write("time,y\\n")
    for t in document["times"]:
        out.write(f"{t!r},{scale * (a * t + b * b)!r}\\n")
"""

COMMAND_CONFIG = """\
name: resume-command
model:
  kind: command
  command: [./sim.py, params.json]
  params: {a: 1.0, b: 0.0}
  outputs: [y]
  output: {file: out.csv}
  templates: [input.txt]
  files: [data/scale.txt]
  run_dir: runs
"""
COMMAND_CONFIG += STUDY


def pcmb_run(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``pcmb run study.yaml --quiet ARGS`` in ``folder``, in this process."""
    return pcmb_here("run", "study.yaml", "--quiet", *args, cwd=folder)


def records(folder: Path) -> list[Path]:
    """Every journaled chunk, of every round."""
    return sorted((folder / "out.h5.journal").rglob("record-*.npz"))


def run_and_kill(
    folder: Path, *args: str, after: int, nominal_first: bool = False, **env: str
) -> int:
    """Start ``pcmb run`` blocking after ``after`` more nodes, wait for them, SIGKILL its
    process group; its pid. ``nominal_first``: the model's first call is the nominal run (a
    design with rounds sends it ahead of the nodes; it is not journaled)."""
    wanted = len(records(folder)) + after
    process = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "run", "study.yaml", "--quiet", *args],
        cwd=folder,
        # Without rounds the nodes come first, then the held-out runs and the nominal run
        # (not journaled); with rounds the nominal run comes first (``nominal_first``).
        env={**os.environ, "BLOCK_AFTER": str(after + nominal_first), **env},
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        while len(records(folder)) < wanted:
            assert process.poll() is None, process.stderr.read().decode()
            assert time.monotonic() < deadline, "the run journaled too few nodes in time"
            time.sleep(0.01)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        process.stderr.close()
    assert len(records(folder)) == wanted  # the model hangs at the next node
    assert not (folder / "out.h5").exists()
    return process.pid


def resume_and_rerun(folder: Path) -> tuple[StudyResult, StudyResult]:
    """Finish an interrupted run with ``--resume`` (its journal then gone) and run the same
    study afresh into ``clean.h5`` (in this process): both results, resumed first."""
    resumed = pcmb_run(folder, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert not (folder / "out.h5.journal").exists()
    clean = pcmb_run(folder, "-o", "clean.h5")
    assert clean.returncode == 0, clean.stderr
    return load(folder / "out.h5"), load(folder / "clean.h5")


def assert_same_runs(folder: Path, first: StudyResult, second: StudyResult) -> None:
    """The resumed ``out.h5`` and the clean ``clean.h5`` hold the same node values and
    coefficients, bit for bit."""
    clean = output_values(folder / "clean.h5")
    for name, values in output_values(folder / "out.h5").items():
        assert values.tobytes() == clean[name].tobytes()
        np.testing.assert_array_equal(
            first.expansions[name].coefficients, second.expansions[name].coefficients
        )


def inspected(path: Path) -> str:
    """What ``pcmb inspect PATH`` prints."""
    shown = pcmb_here("inspect", str(path))
    assert shown.returncode == 0, shown.stderr
    return shown.stdout


def snapshot(directory: Path, *, lock: bool = True) -> dict[str, bytes]:
    """Every file of a journal, its folders' too (the held-out runs'), and its bytes (without
    the lock files, if ``lock`` is False: a run that takes over the lock of a killed one
    writes its own PID there)."""
    return {
        str(p.relative_to(directory)): p.read_bytes()
        for p in sorted(directory.rglob("*"))
        if p.is_file() and (lock or p.name != "lock")
    }


def output_values(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as file:
        return {name: file[f"outputs/{name}/values"][()] for name in file["outputs"]}


@pytest.fixture
def python_study(tmp_path: Path) -> Path:
    (tmp_path / "model.py").write_text(PYTHON_MODEL)
    (tmp_path / "study.yaml").write_text(PYTHON_CONFIG)
    return tmp_path


@pytest.mark.slow
def test_a_changed_entry_file_is_refused_naming_it_and_restoring_it_resumes(
    python_study: Path,
) -> None:
    folder = python_study
    run_and_kill(folder, after=3)
    journal = folder / "out.h5.journal"
    before = snapshot(journal, lock=False)
    assert (journal / "lock").is_file()  # left by the killed run: no stale lock, see below

    entry = folder / "model.py"
    entry.write_text(PYTHON_MODEL.replace('params["b"] ** 2', 'params["b"] ** 2 + 1.0'))
    refused = pcmb_run(folder, "--resume")
    assert refused.returncode == 2, refused.stderr
    assert f"model file {entry.resolve()} has changed since" in refused.stderr
    assert "Traceback" not in refused.stderr
    assert snapshot(journal, lock=False) == before  # nothing written, nothing deleted

    entry.write_text(PYTHON_MODEL)  # the same content again (a new mtime): resumable
    resumed = pcmb_run(folder, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert not journal.exists()
    with h5py.File(folder / "out.h5", "r") as file:
        params, times = file["nodes/params"][()], file["time"][()]
        np.testing.assert_array_equal(file["nodes/status"][()], 1)
        y = file["outputs/y/values"][()]
    # Every node, journaled or not, computed by the same code: a t + b², bit for bit.
    np.testing.assert_array_equal(y, params[:, [0]] * times + params[:, [1]] ** 2)


@pytest.mark.slow
def test_config_edits_that_cannot_change_node_values_keep_the_finished_work(
    python_study: Path,
) -> None:
    folder = python_study
    config = folder / "study.yaml"
    run_and_kill(folder, after=3)
    first = snapshot(folder / "out.h5.journal", lock=False)

    # Comments only: the resumed run continues (and is killed again after 3 more nodes).
    config.write_text("# a comment\n" + PYTHON_CONFIG.replace("\n", "  # why not\n", 3))
    run_and_kill(folder, "--resume", after=3)
    second = snapshot(folder / "out.h5.journal", lock=False)
    assert {name: second[name] for name in first} == first
    assert len(records(folder)) == 6

    # Everything that cannot change a node's value: name, jobs, backend, failure policy,
    # an analysis.
    config.write_text(
        PYTHON_CONFIG.replace("name: resume", "name: renamed").replace(
            "execution: {jobs: 1, chunk_size: 1}",
            "execution: {jobs: 2, backend: inprocess, chunk_size: 1, on_failure: retry, "
            "retries: 3}\nanalysis: {psd: [], samples: 1000}",
        )
    )
    resumed = pcmb_run(folder, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert not (folder / "out.h5.journal").exists()

    config.write_text(PYTHON_CONFIG)
    clean = pcmb_run(folder, "-o", "clean.h5")
    assert clean.returncode == 0, clean.stderr
    resumed_values = output_values(folder / "out.h5")
    clean_values = output_values(folder / "clean.h5")
    assert set(resumed_values) == set(clean_values) == {"y"}
    for name, values in clean_values.items():
        assert resumed_values[name].tobytes() == values.tobytes()


@pytest.mark.slow
def test_changed_command_files_are_refused_by_name(tmp_path: Path) -> None:
    folder = tmp_path
    simulator = folder / "sim.py"
    simulator.write_text(SIMULATOR)
    simulator.chmod(0o755)
    template = folder / "input.txt"
    template.write_text("a = {{ a }}\n")
    (folder / "data").mkdir()
    data = folder / "data" / "scale.txt"
    data.write_text("1.0\n")
    (folder / "study.yaml").write_text(COMMAND_CONFIG)
    run_and_kill(folder, after=3, CALLS_FILE=str(folder / "calls.log"))
    journal = folder / "out.h5.journal"
    before = snapshot(journal, lock=False)

    for path, edited in (
        (data, "2.0\n"),
        (template, "a = {{ a }}\n# a comment the simulator ignores, but pcmb cannot know\n"),
        (simulator, SIMULATOR + "# edited\n"),
    ):
        original = path.read_text()
        path.write_text(edited)
        refused = pcmb_run(folder, "--resume")
        assert refused.returncode == 2, refused.stderr
        assert f"model file {path.resolve()} has changed" in refused.stderr
        assert snapshot(journal, lock=False) == before
        path.write_text(original)


@pytest.mark.slow
def test_a_second_run_on_the_same_output_is_refused_naming_the_first(
    python_study: Path,
) -> None:
    folder = python_study
    journal = folder / "out.h5.journal"
    run = ("run", "study.yaml", "--quiet")

    def journaled() -> bool:
        """The first run journaled its first two nodes (the model's first two calls): it
        holds the lock and waits at the gate."""
        return len(records(folder)) >= 2

    with gated_pcmb(*run, cwd=folder, gate=folder / "gate", ready=journaled) as first:
        before = snapshot(journal)
        for args in ((), ("--resume",)):
            second = pcmb_run(folder, *args)
            assert second.returncode == 2, second.stderr
            assert (
                f"another pcmb run (PID {first.pid}) is writing out.h5.journal; wait for it"
                in second.stderr
            )
            assert "Traceback" not in second.stderr and "interrupted" not in second.stderr
            assert snapshot(journal) == before
    assert not journal.exists()
    with h5py.File(folder / "out.h5", "r") as file:
        params, times = file["nodes/params"][()], file["time"][()]
        np.testing.assert_array_equal(file["nodes/status"][()], 1)
        y = file["outputs/y/values"][()]
    assert y.shape == (16, 5)
    np.testing.assert_array_equal(y, params[:, [0]] * times + params[:, [1]] ** 2)
