"""Faults at the edges: models that exit, crash or hang, stop signals, statistics that
overflow or do not vary.

The tests run ``python -m pcmb.cli run CONFIG`` in a real process, or ``Study.run`` in this
one (which a crashing model would kill, were it run here): a model that calls ``sys.exit``
or ``os._exit``, or segfaults, at one node is a failure of that node, named with its index;
the failure policy decides what follows (abort: exit 3, no result file; regress: exit 0 and
a complete file). A node that hangs past ``execution.timeout`` is a failure too. pcmb never
exits with the model's code, never exits 0 without writing its result, and on SIGINT,
SIGTERM or SIGKILL leaves no process behind and a journal that resumes to the same bits.

The last ones check the statistics of outputs near 1e200 (finite, exact to 1e-12) and of
outputs that do not vary (std exactly 0, Sobol' indices undefined, with a warning record).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from cli_process import pcmb_here
from executor_models import edges

import pcmb
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.designs import MethodSettings, make_design, statistics_warnings
from pcmb.result import Status

MODEL = '''
import ctypes
import os
import sys
import time

import numpy as np


class Faulty:
    """y = a t; misbehaves (``how``) when its batch holds a node with low < a < high.

    ``how``: "exit" (sys.exit(code)), "os_exit" (os._exit(code)), "segfault", "hang" (an
    endless loop), or "segfault-on-build" (in the constructor, whatever the nodes). Each call
    sleeps ``sleep`` s per node; the process that misbehaves writes its pid to ``marker``.
    With ``BLOCK_ABOVE`` in the run's environment, a call with a node above it waits until
    the run is stopped; with ``HOLD_ABOVE``, such calls log their batch size to
    ``marker.held``, and the first waits until its worker is killed.
    """

    outputs = ("y",)

    def __init__(self, a=0.3, low=2.0, high=2.0, how="exit", code=0, sleep=0.0, marker=""):
        if how == "segfault-on-build":
            ctypes.string_at(0)
        self.parameters = {"a": a}
        self.low, self.high, self.how, self.code = low, high, how, code
        self.sleep, self.marker = sleep, marker

    def simulate(self, params, times):
        a = np.asarray(params["a"], dtype=float)
        time.sleep(self.sleep * a.size)
        block = os.environ.get("BLOCK_ABOVE")
        if block is not None and np.any(a > float(block)):
            time.sleep(3600)
        hold = os.environ.get("HOLD_ABOVE")
        if hold is not None and np.any(a > float(hold)):
            held = self.marker + ".held"
            first = not os.path.exists(held)
            with open(held, "a") as log:
                log.write(f"{a.size}\\n")
            if first:
                time.sleep(3600)
        if np.any((a > self.low) & (a < self.high)):
            with open(self.marker, "a") as marker:
                marker.write(f"{os.getpid()}\\n")
            if self.how == "exit":
                sys.exit(self.code)
            if self.how == "os_exit":
                os._exit(self.code)
            if self.how == "segfault":
                ctypes.string_at(0)
            while True:
                pass
        return {"y": a[:, None] * times}
'''

#: Order 8 on one input: 9 nodes, cut into 9 chunks of one node (the default rule).
ORDER = 8
NODES = pcmb.TensorGrid([pcmb.Uniform(0.0, 1.0)], (ORDER,)).params[:, 0]
#: Node 0 runs first, node 4 is a middle one; NOMINAL (a = 0.3, no node) is the nominal run.
FIRST, MIDDLE, NOMINAL = 0, 4, -1
NOMINAL_A = 0.3
#: The runs of the tests that stop a run midway wait at the nodes above 0.4 (BLOCK_ABOVE),
#: so that the stop lands at a known point: the nominal run and the STOPPED nodes below done.
BLOCKED = {**os.environ, "BLOCK_ABOVE": "0.4"}
STOPPED = int(np.sum(NODES < 0.4))


def _window(index: int | None) -> tuple[float, float]:
    """``(low, high)`` around node ``index``'s value (or the nominal one); empty for None."""
    if index is None:
        return 2.0, 2.0
    gap = 0.5 * np.min(np.diff(NODES))
    centre = NOMINAL_A if index == NOMINAL else NODES[index]
    return float(centre - gap / 4), float(centre + gap / 4)


def _study(
    folder: Path,
    index: int | None,
    code: int,
    jobs: int,
    policy: str,
    how: str = "exit",
    sleep: float = 0.0,
    timeout: float | None = None,
    chunk_size: int | None = None,
) -> Path:
    """A study whose model misbehaves (``how``) at node ``index`` (``None``: never); returns
    the config."""
    (folder / "faulty.py").write_text(MODEL)
    low, high = _window(index)
    limit = "" if timeout is None else f", timeout: {timeout}"
    limit += "" if chunk_size is None else f", chunk_size: {chunk_size}"
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: faulty
            model:
              kind: python
              entry: faulty.py:Faulty
              params: {{a: {NOMINAL_A}, low: {low!r}, high: {high!r}, how: {how}, code: {code},
                        sleep: {sleep}, marker: {str(folder / "marker")!r}}}
              outputs: [y]
            time: {{start: 0.0, stop: 1.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 0.0, high: 1.0}}
            method: {{kind: collocation, order: {ORDER}, validation: 0}}  # faults at chosen nodes
            execution: {{jobs: {jobs}, backend: loky, on_failure: {policy}{limit}}}
            output: {str(folder / "out" / "result.h5")!r}
            """
        )
    )
    (folder / "out").mkdir()
    return config


def _run(config: Path, env: dict[str, str] | None = None) -> tuple[int, str, int]:
    """Exit code, stderr and pid of ``python -m pcmb.cli run CONFIG --quiet`` (in ``env``)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    _, stderr = process.communicate(timeout=300)
    return process.returncode, stderr, process.pid


#: Where the model calls ``sys.exit(code)``, with how many workers (slow: each runs a study).
EXITS = [
    pytest.param(index, code, jobs, id=f"{where}-exit{code}-jobs{jobs}", marks=pytest.mark.slow)
    for index, where in ((FIRST, "first"), (MIDDLE, "middle"))
    for code in (0, 3)
    for jobs in (1, 2)
]


def _check_where_it_ran(folder: Path, pid: int) -> None:
    """The node misbehaved in a worker process, never in pcmb's own."""
    exited = {int(line) for line in (folder / "marker").read_text().split()}
    assert exited and pid not in exited


def _exit_run(folder: Path, index: int, code: int, jobs: int, policy: str) -> tuple[int, str]:
    """Exit code and stderr of ``pcmb run`` of a study whose model calls ``sys.exit(code)`` at
    node ``index``, in this process: a ``sys.exit`` run here by mistake fails the test rather
    than ending it."""
    done = pcmb_here("run", str(_study(folder, index, code, jobs, policy)), "--quiet")
    return done.returncode, done.stderr


@pytest.mark.parametrize(("index", "code", "jobs"), EXITS)
def test_sys_exit_in_the_model_aborts_with_exit_3(
    tmp_path: Path, index: int, code: int, jobs: int
) -> None:
    returncode, stderr = _exit_run(tmp_path, index, code, jobs, "abort")
    assert returncode == 3, stderr
    assert "the model failed at 1 of 9 node(s) (on_failure: abort)" in stderr
    assert f"  node {index} (a={NODES[index]:.6g}): SystemExit: {code} at faulty.py:" in stderr
    # The model's traceback is shown, not one of pcmb's own.
    assert "unexpected error" not in stderr and "pcmb/run/" not in stderr, stderr
    # No result, not even half of one: only the journal of the finished nodes is left.
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.h5.journal"}
    _check_where_it_ran(tmp_path, os.getpid())


@pytest.mark.parametrize(("index", "code", "jobs"), EXITS)
def test_sys_exit_in_the_model_is_regressed_over_with_a_complete_file(
    tmp_path: Path, index: int, code: int, jobs: int
) -> None:
    returncode, stderr = _exit_run(tmp_path, index, code, jobs, "regress")
    assert returncode == 0, stderr
    assert f"node {index} (a={NODES[index]:.6g}): SystemExit: {code}" in stderr
    assert "pcmb: wrote" in stderr
    # A complete file and nothing else: no journal, no temporary file.
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.h5"}
    result = pcmb.load(tmp_path / "out" / "result.h5")
    expected = np.full(ORDER + 1, Status.OK)
    expected[index] = Status.FAILED
    np.testing.assert_array_equal(result.status, expected)
    assert [(f.index, f.message) for f in result.failures] == [(index, f"SystemExit: {code}")]
    assert "nodes-failed" in {w.code for w in result.warnings}
    ok = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][ok], NODES[ok, None] * result.times)
    # y = a t with a ~ U[0, 1]: the refit on the 8 surviving nodes is exact.
    np.testing.assert_allclose(result.mean("y"), 0.5 * result.times, atol=1e-12)
    np.testing.assert_allclose(result.std("y"), result.times / np.sqrt(12.0), atol=1e-12)
    _check_where_it_ran(tmp_path, os.getpid())


# -- crashes and hangs: the worker dies, pcmb goes on ----------------------------------------

CRASHES = {"segfault": "worker process died (signal 11, SIGSEGV)", "os_exit": "exit code 7"}


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
@pytest.mark.parametrize("index", [FIRST, MIDDLE], ids=["first", "middle"])
@pytest.mark.parametrize("how", sorted(CRASHES))
def test_a_crash_costs_only_its_node(tmp_path: Path, how: str, index: int, jobs: int) -> None:
    config = _study(tmp_path, index, 7, jobs, "abort", how=how)
    returncode, stderr, pid = _run(config)
    assert returncode == 3, stderr
    assert f"node {index} (a={NODES[index]:.6g}): " in stderr and CRASHES[how] in stderr
    assert "Traceback" not in stderr
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.h5.journal"}
    _check_where_it_ran(tmp_path, pid)


@pytest.mark.slow
@pytest.mark.parametrize(("policy", "how"), [("regress", "segfault"), ("retry", "os_exit")])
def test_a_crash_follows_the_failure_policy(tmp_path: Path, policy: str, how: str) -> None:
    config = _study(tmp_path, MIDDLE, 7, 2, policy, how=how)
    returncode, stderr, pid = _run(config)
    runs = (tmp_path / "marker").read_text().split()
    if policy == "regress":  # a complete file without the node
        assert returncode == 0, stderr
        result = pcmb.load(tmp_path / "out" / "result.h5")
        assert np.flatnonzero(result.status == Status.FAILED).tolist() == [MIDDLE]
        assert CRASHES[how] in result.failures[0].message
        np.testing.assert_allclose(result.mean("y"), 0.5 * result.times, atol=1e-12)
    else:  # retries: 1, then abort; run in the pool, alone, and once more
        assert returncode == 3, stderr
        assert CRASHES[how] in stderr
        assert len(runs) == 3
    assert pid not in {int(r) for r in runs}


@pytest.mark.slow
def test_a_crash_in_the_nominal_run_is_a_warning(tmp_path: Path) -> None:
    config = _study(tmp_path, NOMINAL, 7, 2, "abort", how="segfault")
    returncode, stderr, pid = _run(config)
    assert returncode == 0, stderr
    assert "the nominal run failed, so none is stored: worker process died (signal 11" in stderr
    result = pcmb.load(tmp_path / "out" / "result.h5")
    assert "nominal-failed" in {w.code for w in result.warnings}
    assert (result.status == Status.OK).all()
    _check_where_it_ran(tmp_path, pid)


@pytest.mark.slow
def test_a_nominal_run_past_the_timeout_leaves_no_design_node_unrun(tmp_path: Path) -> None:
    # Chunks [0-2] [3-5] [6-8] [nominal], one call each, two workers: [6-8] runs beside the
    # nominal run and, the first time, waits until its worker is killed (HOLD_ABOVE); the
    # nominal run hangs, and its timeout (2 s against [6-8]'s 6 s) kills both workers with
    # [6-8] in flight: no sleep races the timeout. That kill must not cost [6-8] its run, as
    # a failed nominal run never stops a study.
    config = _study(tmp_path, NOMINAL, 0, 2, "abort", how="hang", timeout=2.0, chunk_size=3)
    held = {**os.environ, "HOLD_ABOVE": str(0.5 * (NODES[5] + NODES[6]))}
    returncode, stderr, _ = _run(config, held)
    assert returncode == 0, stderr
    # [6-8] was held and run again whole: the nominal run's timeout killed it (had its own
    # come first, its nodes would have run one by one, and this test proved nothing).
    assert (tmp_path / "marker.held").read_text().split() == ["3", "3"]
    assert "the nominal run failed, so none is stored: timed out after 2 s" in stderr
    result = pcmb.load(tmp_path / "out" / "result.h5")
    assert (result.status == Status.OK).all(), result.status
    assert result.design.fit == "projection"
    np.testing.assert_allclose(result.mean("y"), 0.5 * result.times, atol=1e-12)


@pytest.mark.slow
def test_a_crash_while_building_the_model_is_a_model_error(tmp_path: Path) -> None:
    config = _study(tmp_path, None, 7, 2, "abort", how="segfault-on-build")
    for command in ("validate", "run"):
        process = subprocess.run(
            [sys.executable, "-m", "pcmb.cli", command, str(config)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert process.returncode == 3, process.stderr
        assert "could not build the model: worker process died (signal 11" in process.stderr
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.slow
def test_a_hang_past_the_timeout_is_a_failed_node(tmp_path: Path) -> None:
    config = _study(tmp_path, MIDDLE, 0, 2, "regress", how="hang", timeout=2.0)
    start = time.monotonic()
    returncode, stderr, _ = _run(config)
    assert returncode == 0, stderr
    assert time.monotonic() - start < 60
    result = pcmb.load(tmp_path / "out" / "result.h5")
    assert np.flatnonzero(result.status == Status.FAILED).tolist() == [MIDDLE]
    assert "timed out after 2 s (2 s per node; its worker process was killed)" in (
        result.failures[0].message
    )
    assert len((tmp_path / "marker").read_text().split()) == 1  # known to hang: not run again


# -- stop signals: nothing left running, nothing lost ----------------------------------------


def _session_processes(session: int) -> list[int]:
    """Pids of the live processes of a session (zombies excluded)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[3]) == session and fields[0] != "Z":
                found.append(int(stat.parent.name))
    return found


def _no_survivors(session: int) -> None:
    deadline = time.monotonic() + 10
    while (alive := _session_processes(session)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert alive == [], f"processes of the run still alive: {alive}"


def _blocked_run(config: Path) -> subprocess.Popen[str]:
    """``pcmb run CONFIG`` started in a session of its own, waiting at the nodes above 0.4."""
    return subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet"],
        stderr=subprocess.PIPE,
        text=True,
        env=BLOCKED,
        start_new_session=True,  # its own session: the test finds every process it started
    )


def _wait_until_blocked(process: subprocess.Popen[str], journal: Path) -> None:
    """Wait until the STOPPED nodes below 0.4 are journaled: the run is then waiting at the
    next nodes, and cannot finish before it is stopped."""
    deadline = time.monotonic() + 120
    while len(list(journal.glob("record-*.npz"))) < STOPPED:
        # Not its stderr: the workers hold that pipe open while they live.
        assert process.poll() is None, f"the run ended early (exit {process.returncode})"
        assert time.monotonic() < deadline, "the nodes below 0.4 did not finish in time"
        time.sleep(0.02)


STOPS = {
    "sigint-group": (signal.SIGINT, True, 130, "interrupted (SIGINT)"),
    "sigterm": (signal.SIGTERM, False, 143, "stopped by SIGTERM"),
    "sighup": (signal.SIGHUP, False, 129, "stopped by SIGHUP"),
    "sigkill": (signal.SIGKILL, False, -9, ""),
}


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads processes from /proc (Linux)")
@pytest.mark.parametrize("stop", sorted(STOPS))
def test_a_stopped_run_leaves_nothing_behind_and_resumes_to_the_same_bits(
    tmp_path: Path, stop: str
) -> None:
    number, group, code, words = STOPS[stop]
    (tmp_path / "whole").mkdir()
    reference = _study(tmp_path / "whole", None, 0, 2, "abort")
    assert pcmb_here("run", str(reference), "--quiet").returncode == 0
    config = _study(tmp_path, None, 0, 2, "abort")
    process = _blocked_run(config)
    try:
        _wait_until_blocked(process, tmp_path / "out" / "result.h5.journal")
        (os.killpg if group else os.kill)(process.pid, number)
        _, stderr = process.communicate(timeout=60)
        assert process.returncode == code, stderr
        assert words in stderr
        _no_survivors(process.pid)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.h5.journal"}
    resumed = pcmb_here("run", str(config), "--quiet", "--resume")
    assert resumed.returncode == 0, resumed.stderr
    whole = pcmb.load(tmp_path / "whole" / "out" / "result.h5")
    again = pcmb.load(tmp_path / "out" / "result.h5")
    np.testing.assert_array_equal(again.values["y"], whole.values["y"])
    np.testing.assert_array_equal(
        again.expansions["y"].coefficients, whole.expansions["y"].coefficients
    )


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads processes from /proc (Linux)")
def test_sigint_to_pcmb_alone_stops_it_despite_a_stuck_worker(tmp_path: Path) -> None:
    config = _study(tmp_path, MIDDLE, 0, 2, "abort", how="hang")
    process = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet"],
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "marker").exists():  # the worker is stuck in its endless loop
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < deadline, "the hanging node did not start in time"
            time.sleep(0.02)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=30)
        assert process.returncode == 130, stderr
        _no_survivors(process.pid)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_the_users_ctrl_c_still_interrupts_the_run(tmp_path: Path, jobs: int) -> None:
    # A terminal sends SIGINT to its whole foreground process group: pcmb and its workers.
    config = _study(tmp_path, None, 0, jobs, "abort")
    process = _blocked_run(config)
    try:
        _wait_until_blocked(process, tmp_path / "out" / "result.h5.journal")
        os.killpg(process.pid, signal.SIGINT)
        _, stderr = process.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    assert process.returncode == 130, stderr
    assert "pcmb: interrupted (SIGINT); finished nodes are kept in the journal" in stderr
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.h5.journal"}


# -- statistics at the edges: outputs near 1e200 and outputs that do not vary -----------------

EDGE_TIMES = np.linspace(0.0, 2.0, 5)
EDGE_INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}


def _edge_study() -> pcmb.Study:
    return pcmb.Study(
        edges,
        EDGE_INPUTS,
        EDGE_TIMES,
        method={"kind": "collocation", "order": {"a": 1, "b": 2}},
        execution={"jobs": 1},
        params={"a": 2.0, "b": 0.0},
    )


def test_huge_and_constant_outputs_get_honest_statistics_and_records(tmp_path: Path) -> None:
    path = tmp_path / "edges.h5"
    with pytest.warns(pcmb.PcmbWarning) as issued:
        result = _edge_study().run(path)
    # Only the loud record is issued; "does not vary" is recorded, not issued at every run.
    assert [str(w.message).endswith("[square-overflow]") for w in issued] == [True]
    # huge: Var = 1e400 (0.01 t²/3 + 2 · 0.0025 t⁴) is no float; its std is, to 1e-12.
    exact = 1e200 * np.sqrt(0.01 * EDGE_TIMES**2 / 3.0 + 0.005 * EDGE_TIMES**4)
    np.testing.assert_allclose(result.std("huge"), exact, rtol=1e-12, atol=0.0)
    assert np.isfinite(result.sobol_first("huge")[:, 1:]).all()
    np.testing.assert_allclose(result.sobol_total("huge")[:, 1:].sum(axis=0), 1.0, rtol=1e-12)
    # flat never varies: std exactly 0, Sobol' indices undefined, and a record saying so.
    assert np.all(result.std("flat") == 0.0) and np.isnan(result.sobol_first("flat")).all()
    records = {(w.code, w.output): w for w in result.warnings}
    assert records["sobol-undefined", "flat"].time_range == (0.0, 2.0)
    assert "at all 5 times" in records["sobol-undefined", "flat"].message
    for name in ("huge", "z"):  # both are fixed at t = 0 only
        assert records["sobol-undefined", name].time_range == (0.0, 0.0)
        assert result.std(name)[0] == 0.0 and np.isnan(result.sobol_first(name)[:, 0]).all()
    top = np.max(result.values["huge"])
    assert f"values up to {top:.3g}" in records["square-overflow", "huge"].message
    assert not any(w.code == "statistic-non-finite" for w in result.warnings)
    # The file keeps the same numbers and records.
    loaded = pcmb.load(path)
    assert set(loaded.warnings) == set(result.warnings)
    for name in result.outputs:
        np.testing.assert_array_equal(loaded.std(name), result.std(name))
        np.testing.assert_array_equal(loaded.sobol_total(name), result.sobol_total(name))


def test_non_finite_statistics_are_recorded_with_their_cause() -> None:
    grid = pcmb.TensorGrid(list(EDGE_INPUTS.values()), (1, 2))
    values = edges(dict(zip(EDGE_INPUTS, grid.params.T, strict=True)), EDGE_TIMES)
    values["z"][3, 2:] = np.nan  # a NaN run the executor would have refused, kept anyway
    ok = np.ones(grid.size, dtype=bool)
    design = make_design(EDGE_INPUTS, MethodSettings("collocation", (1, 2)))
    recovered = design.recover(grid, values, ok, EDGE_TIMES)
    found = {(w.code, w.output): w for w in recovered.warnings}
    z = found["statistic-non-finite", "z"]
    assert z.time_range == (1.0, 2.0)
    assert z.message.startswith("the mean or std is not finite (NaN or inf) at 3 consecutive")
    assert "the runs kept hold values that are not finite" in z.message
    # Without the grid, the records name time indices instead.
    bare = {(w.code, w.output): w for w in design.recover(grid, values, ok).warnings}
    assert bare["statistic-non-finite", "z"].time_range is None
    assert "time indices 2..4" in bare["statistic-non-finite", "z"].message
    # Finite runs whose statistics still are not (here: coefficients beyond the float range).
    expansion = recovered.expansions["huge"]
    coefficients = expansion.coefficients.copy()
    coefficients[1, 4] = np.inf
    beyond = ChaosExpansion(coefficients, expansion.multi_index, expansion.distributions)
    (record, *_) = statistics_warnings({"huge": beyond}, {"huge": values["huge"]}, ok, EDGE_TIMES)
    assert (record.code, record.time_range) == ("statistic-non-finite", (2.0, 2.0))
    top = np.max(values["huge"])
    assert f"values up to {top:.3g} put them beyond the floating-point range" in record.message
