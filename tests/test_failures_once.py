"""A failed node runs once (1 + retries times), a raising batch is bisected, abort stops early.

Every model here counts its calls for real: it appends a line to a log file per node run
(per-point models) or per ``simulate`` call (batch models), in this process or in a worker.
"""

from __future__ import annotations

import functools
import math
import re
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.adapters.python import FunctionModel
from pcmb.cli import main
from pcmb.config.schema import ExecutionSpec
from pcmb.result import Status
from pcmb.run.executor import run_nodes

TIMES = np.linspace(0.0, 1.0, 5)


@pcmb.pointwise(outputs=("y",))
def logged_point(params: dict, times: np.ndarray) -> dict:
    """y = a t; logs ``a`` per call; raises at the values of ``a`` in ``params["bad"]``.

    With ``params["after"] = (a0, a1)``, a node with ``a > a1`` first waits until the node
    ``a1`` has run (and 0.1 s more), so nodes after a failing chunk finish after it.
    """
    a = float(params["a"])
    if params.get("after") and a > params["after"][1]:
        deadline = time.monotonic() + 30
        while repr(params["after"][1]) not in calls(Path(params["log"])):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        time.sleep(0.1)
    with open(params["log"], "a") as log:
        log.write(f"{a!r}\n")
    if a in params["bad"]:
        raise RuntimeError(f"diverged at a={a!r}")
    return {"y": a * times}


class LoggedBatch:
    """A batch model (y = a t) that logs each call's batch size and raises if a bad node is in
    the batch, as a stacked solver does."""

    outputs = ("y",)

    def __init__(self, log: str, bad: tuple[float, ...]) -> None:
        self.log, self.bad = log, bad
        self.parameters = {"a": 0.0}

    def simulate(self, params: dict, times: np.ndarray) -> dict:
        a = np.asarray(params["a"], float)
        with open(self.log, "a") as log:
            log.write(f"{a.size}\n")
        hit = [float(x) for x in a if float(x) in self.bad]
        if hit:
            raise ValueError(f"no convergence at a={hit[0]!r}")
        return {"y": a[:, None] * times}


def point_factory(log: Path, bad: list[float], after: tuple = ()) -> functools.partial:
    nominal = {"a": 0.0, "log": str(log), "bad": tuple(map(float, bad)), "after": after}
    return functools.partial(FunctionModel, logged_point, nominal)


def calls(log: Path) -> list[str]:
    return log.read_text().split() if log.exists() else []


# -- per-point models: a failed node is not run again -----------------------------------------


@pytest.mark.parametrize("retries", [0, 2])
def test_a_failing_node_of_a_pointwise_batch_runs_once_per_try(tmp_path: Path, retries: int):
    a = np.linspace(1.0, 2.0, 32)  # chunks of 2
    bad = [5, 20]
    log = tmp_path / "calls.log"
    result = run_nodes(
        point_factory(log, list(a[bad])),
        {"a": a},
        TIMES,
        ["y"],
        retries=retries,
        execution=ExecutionSpec(jobs=1),
    )
    assert [f.index for f in result.failures] == bad
    for failure in result.failures:
        value = float(a[failure.index])
        # The node's own reason, not "non-finite output": no second run was needed to learn it.
        assert (
            failure.message
            == f"ModelError: logged_point raised RuntimeError: diverged at a={value!r}"
        )
    counted = calls(log)
    for i, value in enumerate(a):
        assert counted.count(repr(float(value))) == (1 + retries if i in bad else 1), i
    good = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][good], a[good, None] * TIMES)


@pytest.mark.slow
def test_a_failing_pointwise_node_runs_once_in_workers(tmp_path: Path):
    a = np.linspace(1.0, 2.0, 32)
    log = tmp_path / "calls.log"
    result = run_nodes(
        point_factory(log, [float(a[30])]), {"a": a}, TIMES, ["y"], execution=ExecutionSpec(jobs=2)
    )
    assert [f.index for f in result.failures] == [30]
    assert sorted(calls(log)) == sorted(repr(float(x)) for x in a)


# -- a raising batch is bisected ---------------------------------------------------------------


@pytest.mark.parametrize("bad", [0, 7, 8, 15])
def test_a_raising_batch_is_narrowed_by_bisection(tmp_path: Path, bad: int):
    a = np.linspace(1.0, 2.0, 16)
    log = tmp_path / "calls.log"
    factory = functools.partial(LoggedBatch, str(log), (float(a[bad]),))
    result = run_nodes(
        factory, {"a": a}, TIMES, ["y"], chunk_size=16, execution=ExecutionSpec(jobs=1)
    )
    assert [f.index for f in result.failures] == [bad]
    assert result.failures[0].message == f"ValueError: no convergence at a={float(a[bad])!r}"
    # One batched call, then two halves per level down to the bad node (it was 1 + 16).
    assert len(calls(log)) <= 1 + 2 * math.log2(16)
    good = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][good], a[good, None] * TIMES)


def test_bisection_retries_each_failed_node(tmp_path: Path):
    a = np.linspace(1.0, 2.0, 16)
    log = tmp_path / "calls.log"
    factory = functools.partial(LoggedBatch, str(log), (float(a[3]), float(a[12])))
    result = run_nodes(
        factory, {"a": a}, TIMES, ["y"], chunk_size=16, retries=2, execution=ExecutionSpec(jobs=1)
    )
    assert [f.index for f in result.failures] == [3, 12]
    # Each bad node's one-node calls: its first try and 2 retries.
    assert calls(log).count("1") <= 2 * (1 + 2) + 2  # + at most one good mate alone per side
    assert len(calls(log)) <= 1 + 2 * 2 * math.log2(16) + 2 * 2


def test_nothing_fails_nothing_changes(tmp_path: Path):
    a = np.linspace(1.0, 2.0, 48)
    log = tmp_path / "calls.log"
    result = run_nodes(
        functools.partial(LoggedBatch, str(log), ()),
        {"a": a},
        TIMES,
        ["y"],
        execution=ExecutionSpec(jobs=1),
    )
    assert result.failures == ()
    assert calls(log) == ["3"] * 16  # one call per chunk, the chunks of the documented rule


# -- on_failure: abort stops dispatching -------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_stop_on_failure_stops_early_and_names_every_failure_found(tmp_path: Path, jobs: int):
    a = np.linspace(1.0, 2.0, 64)  # 16 chunks of 4
    bad = [9, 10, 60]  # two in chunk 2, one in chunk 15
    log = tmp_path / "calls.log"
    # The nodes after chunk 2 wait for it to finish: the failure is known before they are.
    after = (float(a[8]), float(a[11]))
    result = run_nodes(
        point_factory(log, list(a[bad]), after),
        {"a": a},
        TIMES,
        ["y"],
        stop_on_failure=True,
        execution=ExecutionSpec(jobs=jobs),
    )
    ran = len(calls(log))
    # Chunks 0 to 2, plus at most the chunks in flight beside chunk 2 and after it (one per
    # worker and one queued).
    assert 12 <= ran <= 4 * (3 + jobs + 1)
    assert [f.index for f in result.failures] == [9, 10]
    assert all("diverged" in f.message for f in result.failures)
    assert np.sum(result.status == Status.PENDING) == 64 - ran
    assert np.sum(result.status == Status.OK) == ran - 2
    # Without the policy every node runs.
    log.unlink()
    everything = run_nodes(
        point_factory(log, list(a[bad])), {"a": a}, TIMES, ["y"], execution=ExecutionSpec(jobs=jobs)
    )
    assert [f.index for f in everything.failures] == bad
    assert len(calls(log)) == 64


MODEL = """
import os
import pcmb


@pcmb.pointwise(outputs=("y",))
def model(params, times):
    with open(params["log"], "a") as log:
        log.write(f"{params['a']!r}\\n")
    if params["a"] > 2.5 and os.path.exists(params["flag"]):
        raise RuntimeError(f"blew up at a={params['a']}")
    return {"y": params["a"] * times + params["b"] ** 2}
"""


@pytest.mark.slow
def test_abort_keeps_finished_chunks_and_resume_runs_the_rest(tmp_path: Path, capsys):
    (tmp_path / "point_model.py").write_text(MODEL)
    flag, log, out = tmp_path / "fail.flag", tmp_path / "calls.log", tmp_path / "out.h5"
    flag.touch()
    config = tmp_path / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: abort
            model:
              kind: python
              entry: {tmp_path / "point_model.py"}:model
              params: {{a: 1.0, b: 0.0, log: {str(log)!r}, flag: {str(flag)!r}}}
              outputs: [y]
            time: {{start: 0.0, stop: 2.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 1.0, high: 3.0}}
              b: {{dist: normal, mean: 0.0, std: 1.0}}
            method: {{kind: collocation, order: 7, validation: 0}}  # counts runs: no held-out ones
            execution: {{jobs: 1, chunk_size: 4, on_failure: abort}}
            output: {out}
            """
        )
    )
    assert main(["run", str(config), "--quiet"]) == 3
    err = capsys.readouterr().err
    first = len(calls(log))
    assert first < 64  # a > 2.5 is reached late in the node order, but far from the end
    assert "node(s) not run" in err and "--resume" in err
    # Every failure of the finished chunks is counted (and named, once per cause).
    failed = int(re.search(r"the model failed at (\d+) of 64 node", err).group(1))
    assert failed and "blew up" in err
    assert (tmp_path / "out.h5.journal").is_dir()
    flag.unlink()
    assert main(["run", str(config), "--resume", "--quiet"]) == 0
    # The nominal run is the campaign's last (joined to the nodes): the stopped run never made
    # it; the resumed one ran only the nodes not finished before (the pending and the failed
    # ones), and the nominal run.
    finished = first - failed
    assert len(calls(log)) - first == (64 - finished) + 1
    result = pcmb.load(out)
    assert (result.status == Status.OK).all()
