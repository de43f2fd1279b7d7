"""Tests of pcmb.run.executor: chunking, in-process vs workers, determinism, failures, resume."""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import executor_models as em
import numpy as np
import pytest

from pcmb.config.schema import ExecutionSpec
from pcmb.errors import ModelError, UsageError
from pcmb.references import damped_oscillator
from pcmb.result import NodeFailure, Status
from pcmb.run import executor
from pcmb.run.executor import RunResult, chunk_bounds, run_nodes
from pcmb.run.journal import Journal

TESTS = Path(__file__).resolve().parent
TIMES = np.linspace(0.0, 1.0, 11)
# RK45 at rtol 1e-8 (atol 1e-10) keeps each step's local error near 1e-8 of |x| <= 1; over the
# few hundred steps of the 5 s horizon the global error of x stays well below 1e-6.
OSCILLATOR_TOL = 1e-6


def ramp_params(n_nodes: int) -> dict[str, np.ndarray]:
    return {"a": np.linspace(-1.0, 1.0, n_nodes)}


def ramp_exact(params: dict[str, np.ndarray]) -> np.ndarray:
    # Ramp computes slope[:, None] * times, which is exact per element whatever the batch.
    return params["a"][:, None] * TIMES


@pytest.fixture(scope="module")
def dask_address():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        yield cluster.scheduler_address


# -- chunking --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("n_nodes", "size", "count"),
    [
        (1, 1, 1),
        (15, 1, 15),
        (16, 1, 16),
        (17, 2, 9),
        (48, 3, 16),
        (216, 14, 16),
        (10**5, 256, 391),
    ],
)
def test_default_chunks_follow_the_documented_rule(n_nodes: int, size: int, count: int) -> None:
    bounds = chunk_bounds(n_nodes)
    assert len(bounds) == count
    assert {stop - start for start, stop in bounds[:-1]} <= {size}
    assert [b[0] for b in bounds[1:]] == [b[1] for b in bounds[:-1]]  # contiguous
    assert bounds[0][0] == 0 and bounds[-1][1] == n_nodes


def test_explicit_chunk_size_and_bad_values() -> None:
    assert chunk_bounds(7, 3) == [(0, 3), (3, 6), (6, 7)]
    with pytest.raises(ValueError, match="positive"):
        chunk_bounds(0)
    with pytest.raises(ValueError, match="positive"):
        chunk_bounds(5, 0)


def test_batches_depend_only_on_the_node_count_not_on_jobs() -> None:
    params = ramp_params(24)
    serial, pooled = (
        run_nodes(
            em.Ramp,
            params,
            TIMES,
            ["batch_size", "batch_first", "pid"],
            execution=ExecutionSpec(jobs=jobs),
        )
        for jobs in (1, 2)
    )
    expected_size = np.empty(24)
    expected_first = np.empty(24)
    for start, stop in chunk_bounds(24):
        expected_size[start:stop] = stop - start
        expected_first[start:stop] = params["a"][start]
    for result in (serial, pooled):
        np.testing.assert_array_equal(result.values["batch_size"][:, 0], expected_size)
        np.testing.assert_array_equal(result.values["batch_first"][:, 0], expected_first)
    assert (pooled.values["pid"] != os.getpid()).all()


def test_a_model_preferred_chunk_size_is_used_unless_the_config_sets_one() -> None:
    params = ramp_params(12)
    preferred = run_nodes(
        em.PreferringRamp, params, TIMES, ["batch_size"], execution=ExecutionSpec(jobs=1)
    )
    # At most the preferred 5 per chunk, in as few chunks as equal as can be: 3 of 4, not 5 + 5 + 2.
    np.testing.assert_array_equal(preferred.values["batch_size"][:, 0], [4] * 12)
    explicit = run_nodes(
        em.PreferringRamp,
        params,
        TIMES,
        ["batch_size"],
        chunk_size=4,
        execution=ExecutionSpec(jobs=1),
    )
    np.testing.assert_array_equal(explicit.values["batch_size"][:, 0], [4] * 12)


def test_joblib_parallel_still_works_after_a_pooled_run() -> None:
    import joblib

    run_nodes(em.Ramp, ramp_params(24), TIMES, ["y"], execution=ExecutionSpec(jobs=2))
    assert joblib.Parallel(n_jobs=2)(joblib.delayed(abs)(-k) for k in range(4)) == [0, 1, 2, 3]


@pytest.mark.parametrize("jobs", [1, 2])
def test_the_model_never_runs_in_this_process(jobs: int) -> None:
    result = run_nodes(em.Ramp, ramp_params(24), TIMES, ["pid"], execution=ExecutionSpec(jobs=jobs))
    assert (result.values["pid"] != os.getpid()).all()
    assert len(np.unique(result.values["pid"])) <= jobs


def test_backend_inprocess_runs_here_for_debugging() -> None:
    result = run_nodes(
        em.Ramp, ramp_params(24), TIMES, ["pid"], execution=ExecutionSpec(backend="inprocess")
    )
    assert (result.values["pid"] == os.getpid()).all()


# -- accuracy and determinism ----------------------------------------------------------------


def _oscillator(**settings: Any) -> RunResult:
    """The stacked oscillator at its 48 nodes, run by :func:`run_nodes` with ``settings``."""
    params, times = em.oscillator_nodes(48)
    return run_nodes(em.StackedOscillator, params, times, ["x", "v"], **settings)


def _assert_bit_identical(found: RunResult, serial: RunResult) -> None:
    for name in ("x", "v"):
        np.testing.assert_array_equal(found.values[name], serial.values[name])


@pytest.fixture(scope="module")
def oscillator_serial():
    return _oscillator(execution=ExecutionSpec(jobs=1))


def test_batched_nodes_match_the_closed_form(oscillator_serial) -> None:
    params, times = em.oscillator_nodes(48)
    assert (oscillator_serial.status == Status.OK).all()
    assert oscillator_serial.failures == ()
    error = np.abs(
        oscillator_serial.values["x"] - damped_oscillator(times, params["k"], params["c"])
    )
    assert error.max() < OSCILLATOR_TOL


def test_batch_composition_changes_the_last_bits(oscillator_serial) -> None:
    # Proof that the bit-identity tests below can fail: other chunks give other bits
    # (the stacked error control sees other nodes), though equally accurate values.
    single = _oscillator(chunk_size=1, execution=ExecutionSpec(jobs=1))
    assert not np.array_equal(single.values["x"], oscillator_serial.values["x"])
    np.testing.assert_allclose(single.values["x"], oscillator_serial.values["x"], atol=2e-6)


@pytest.mark.slow
def test_loky_is_bit_identical_to_serial(oscillator_serial) -> None:
    _assert_bit_identical(_oscillator(execution=ExecutionSpec(jobs=2)), oscillator_serial)


@pytest.mark.slow
def test_dask_is_bit_identical_to_serial(oscillator_serial, dask_address: str) -> None:
    pooled = _oscillator(address=dask_address, execution=ExecutionSpec(backend="dask"))
    _assert_bit_identical(pooled, oscillator_serial)
    probe = run_nodes(
        em.Ramp,
        ramp_params(24),
        TIMES,
        ["pid"],
        address=dask_address,
        execution=ExecutionSpec(backend="dask"),
    )
    assert (probe.values["pid"][chunk_bounds(24)[0][1] :] != os.getpid()).all()


@pytest.mark.slow
def test_dask_local_cluster_is_started_and_bit_identical(oscillator_serial) -> None:
    pooled = _oscillator(execution=ExecutionSpec(backend="dask", jobs=2))
    _assert_bit_identical(pooled, oscillator_serial)


def test_field_inputs_are_sliced_per_node() -> None:
    params = {"a": np.linspace(0.0, 1.0, 10), "z": np.arange(30.0).reshape(10, 3)}
    result = run_nodes(em.Ramp, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    expected = (params["a"] + params["z"].sum(axis=1))[:, None] * TIMES
    np.testing.assert_array_equal(result.values["y"], expected)


# -- failures --------------------------------------------------------------------------------


def test_exceptions_are_narrowed_to_the_failing_nodes() -> None:
    params = ramp_params(32)
    bad = [5, 6, 20]
    factory = functools.partial(em.RaisingRamp, params["a"][bad])
    result = run_nodes(factory, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    assert [f.index for f in result.failures] == bad
    for failure in result.failures:
        a = float(params["a"][failure.index])
        assert failure.params == {"a": a}
        assert failure.message == f"ValueError: a={a!r} is outside the model's range"
        assert str(failure).startswith(f"node {failure.index} (a={a:.6g}): ValueError: a=")
    expected_status = np.full(32, Status.OK)
    expected_status[bad] = Status.FAILED
    np.testing.assert_array_equal(result.status, expected_status)
    good = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])
    assert np.isnan(result.values["y"][~good]).all()


def test_non_finite_rows_are_narrowed_in_workers() -> None:
    params = ramp_params(32)
    factory = functools.partial(em.NanRamp, params["a"][[9, 30]], t_bad=0.55)
    result = run_nodes(
        factory, params, TIMES, ["y", "pid", "batch_size"], execution=ExecutionSpec(jobs=2)
    )
    assert [f.index for f in result.failures] == [9, 30]
    # Node 8 shares a chunk with node 9: its finite row from the batch is kept.
    assert result.values["batch_size"][8, 0] == 2
    # TIMES has steps of 0.1: the first time >= 0.55 is 0.6.
    assert {f.message for f in result.failures} == {"non-finite output 'y' at t=0.6"}
    good = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])
    assert (result.values["pid"][good][-1] != os.getpid()).all()


def test_a_nan_node_fails_a_stacked_solve_as_a_whole() -> None:
    # The executor keeps the finite rows of a batch with non-finite rows; that is safe for a
    # stacked solver because a NaN node breaks its step control for the whole call, which is
    # then narrowed node by node.
    params, times = em.oscillator_nodes(48)
    victim = 20  # in chunk [18, 21)
    factory = functools.partial(em.StackedOscillator, poison_k=params["k"][victim])
    result = run_nodes(factory, params, times, ["x"], execution=ExecutionSpec(jobs=1))
    assert [f.index for f in result.failures] == [victim]
    good = result.status == Status.OK
    exact = damped_oscillator(times, params["k"], params["c"])
    assert np.abs(result.values["x"][good] - exact[good]).max() < OSCILLATOR_TOL
    # Its chunk mates were re-run alone: bit for bit what a one-node batch gives.
    mates = {name: values[18:20] for name, values in params.items()}
    alone = run_nodes(
        em.StackedOscillator, mates, times, ["x"], chunk_size=1, execution=ExecutionSpec(jobs=1)
    )
    np.testing.assert_array_equal(result.values["x"][18:20], alone.values["x"])
    assert result.failures[0].message.startswith("output 'x' has shape (1, ")


def test_a_model_returning_the_wrong_shape_fails_every_node() -> None:
    result = run_nodes(
        em.WrongShapeRamp, ramp_params(4), TIMES, ["y"], execution=ExecutionSpec(jobs=1)
    )
    assert len(result.failures) == 4
    assert result.failures[0].message == "output 'y' has shape (1, 10), expected (1, 11)"


def test_a_model_cannot_write_into_its_inputs() -> None:
    params = ramp_params(4)
    original = params["a"].copy()
    result = run_nodes(em.MutatingRamp, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    assert {f.message for f in result.failures} == {
        "ValueError: assignment destination is read-only"
    }
    np.testing.assert_array_equal(params["a"], original)


def test_retries_rerun_failed_nodes() -> None:
    params = ramp_params(32)
    # The node fails in its first two calls: the chunk's batch call and its first single run.
    flaky = functools.partial(em.FlakyRamp, params["a"][[3]], failures=2)
    failed = run_nodes(
        functools.partial(flaky, nonce=uuid.uuid4().hex),
        params,
        TIMES,
        ["y"],
        execution=ExecutionSpec(),
    )
    assert [f.index for f in failed.failures] == [3]
    assert failed.failures[0].message.startswith("RuntimeError: transient failure 2")
    healed = run_nodes(
        functools.partial(flaky, nonce=uuid.uuid4().hex),
        params,
        TIMES,
        ["y"],
        retries=1,
        execution=ExecutionSpec(),
    )
    assert healed.failures == ()
    np.testing.assert_array_equal(healed.values["y"], ramp_exact(params))


# -- BaseExceptions of the model's code -------------------------------------------------------


class LeavingRamp(em.Ramp):
    """Raises a BaseException (``how``) when a node with ``a`` in ``bad`` is in its batch.

    ``sigint`` sends the process a real SIGINT (what Ctrl-C does) and then, as models do, lets
    the KeyboardInterrupt through (``sigint``), swallows it (``sigint-swallowed``), turns it
    into ``sys.exit(1)`` (``sigint-exit``) or into an ordinary error (``sigint-error``).
    ``replaced`` installs its own SIGINT handler before raising KeyboardInterrupt.
    """

    def __init__(self, bad: list[float], how: str) -> None:
        self.bad, self.how = np.asarray(bad), how

    def check(self, params: dict[str, np.ndarray]) -> None:
        if not np.isin(params["a"], self.bad).any():
            return
        if self.how == "exit0":
            sys.exit(0)
        if self.how == "exit-text":
            sys.exit("stopping here")
        if self.how == "keyboard":
            raise KeyboardInterrupt
        if self.how == "generator":
            raise GeneratorExit
        if self.how == "replaced":
            signal.signal(signal.SIGINT, signal.default_int_handler)
            raise KeyboardInterrupt
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # the handler interrupts the sleep
        except KeyboardInterrupt:
            if self.how == "sigint":
                raise
            if self.how == "sigint-exit":
                sys.exit(1)
            if self.how == "sigint-error":
                raise RuntimeError("interrupted") from None


class ExitingFactory:
    """A factory whose model calls ``sys.exit(2)`` while it is built."""

    def __call__(self) -> em.Ramp:
        sys.exit(2)


LEAVINGS = [
    ("exit0", "SystemExit: 0"),
    ("exit-text", "SystemExit: stopping here"),
    ("keyboard", "KeyboardInterrupt raised by the model (no Ctrl-C reached pcmb)"),
    ("generator", "GeneratorExit"),
]


@pytest.mark.parametrize(("how", "message"), LEAVINGS)
def test_base_exceptions_of_the_model_are_failures_of_its_nodes(how: str, message: str) -> None:
    params = ramp_params(32)
    bad = [0, 13]  # in the first chunk (run in this process) and in a later one
    factory = functools.partial(LeavingRamp, list(params["a"][bad]), how)
    result = run_nodes(factory, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    assert [(f.index, f.message) for f in result.failures] == [(i, message) for i in bad]
    good = result.status == Status.OK
    assert good.sum() == 30
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # left as found


@pytest.mark.slow
@pytest.mark.parametrize(("how", "message"), LEAVINGS[::2])
def test_base_exceptions_in_workers_are_failures_of_their_nodes(how: str, message: str) -> None:
    params = ramp_params(24)
    bad = [13, 20]
    factory = functools.partial(LeavingRamp, list(params["a"][bad]), how)
    result = run_nodes(factory, params, TIMES, ["y", "pid"], execution=ExecutionSpec(jobs=2))
    assert [(f.index, f.message) for f in result.failures] == [(i, message) for i in bad]
    good = result.status == Status.OK
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])
    assert (result.values["pid"][good][-1] != os.getpid()).all()  # run by workers


@pytest.mark.slow
@pytest.mark.parametrize("how", ["sigint", "sigint-swallowed", "sigint-exit", "sigint-error"])
def test_a_sigint_while_the_model_runs_interrupts_the_run(how: str) -> None:
    # Whatever the model makes of the user's Ctrl-C, the run stops with KeyboardInterrupt.
    params = ramp_params(32)
    factory = functools.partial(LeavingRamp, [params["a"][13]], how)
    with pytest.raises(KeyboardInterrupt):
        run_nodes(factory, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_keyboard_interrupt_pcmb_cannot_attribute_stays_the_users() -> None:
    # The model replaced the SIGINT handler: a SIGINT could have raised it unseen.
    params = ramp_params(32)
    factory = functools.partial(LeavingRamp, [params["a"][13]], "replaced")
    with pytest.raises(KeyboardInterrupt):
        run_nodes(factory, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.slow
def test_a_keyboard_interrupt_outside_the_main_thread_is_the_models() -> None:
    # Python delivers SIGINT to the main thread only (dask runs tasks in worker threads).
    params = ramp_params(8)
    found: list = []
    factory = functools.partial(LeavingRamp, [params["a"][5]], "keyboard")
    thread = threading.Thread(
        target=lambda: found.append(
            run_nodes(factory, params, TIMES, ["y"], execution=ExecutionSpec(jobs=1))
        )
    )
    thread.start()
    thread.join()
    assert [(f.index, f.message) for f in found[0].failures] == [(5, LEAVINGS[2][1])]


def test_a_model_that_exits_while_it_is_built_raises_model_error() -> None:
    with pytest.raises(ModelError, match=r"could not build the model: SystemExit: 2$"):
        run_nodes(ExitingFactory(), ramp_params(4), TIMES, ["y"], execution=ExecutionSpec())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("how", "cause"), [("segv", "signal 11, SIGSEGV"), ("exit", "exit code 7")]
)
def test_a_dying_worker_costs_only_its_node(how: str, cause: str) -> None:
    params = ramp_params(24)
    victim = 13  # in chunk [12, 14), not in the first chunk that runs in-process
    factory = functools.partial(em.CrashingRamp, params["a"][victim], how, os.getpid())
    result = run_nodes(factory, params, TIMES, ["y", "batch_size"], execution=ExecutionSpec(jobs=2))
    assert [f.index for f in result.failures] == [victim]
    assert result.failures[0].message == f"worker process died ({cause})"
    good = np.arange(24) != victim
    assert (result.status[good] == Status.OK).all()
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])
    # Only the killer's chunk was split into single runs; every other chunk kept its batch.
    assert result.values["batch_size"][12, 0] == 1
    assert (np.delete(result.values["batch_size"][:, 0], [12, 13]) == 2).all()


@pytest.mark.slow
def test_a_dying_dask_worker_costs_only_its_node() -> None:
    dask = pytest.importorskip("dask")
    distributed = pytest.importorskip("distributed")
    params = ramp_params(24)
    factory = functools.partial(em.CrashingRamp, params["a"][13], "segv", os.getpid())
    # Give up on a task at its first worker death (dask retries 3 times by default).
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 0}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
    ):
        result = run_nodes(
            factory,
            params,
            TIMES,
            ["y"],
            address=cluster.scheduler_address,
            execution=ExecutionSpec(backend="dask"),
        )
    assert [str(f) for f in result.failures] == [
        "node 13 (a=0.130435): worker process died (dask KilledWorker: see the dask worker logs)"
    ]
    good = np.arange(24) != 13
    np.testing.assert_array_equal(result.values["y"][good], ramp_exact(params)[good])


class _Died(Exception):
    pass


class _ScriptedPool:
    """An in-process pool where a task holding the victim node 'kills its worker' a few times.

    It exercises the bookkeeping of deaths (suspects, isolation, retries) without the seconds
    each real worker death and pool rebuild cost. Results are delivered a little after
    submission, so a task submitted just before the victim is still in flight when the victim
    'dies', and is lost with it, as with loky.
    """

    slots = 2

    def __init__(self, victim: float, deaths: int) -> None:
        self.victim, self.deaths = victim, deaths
        self.in_flight: list[tuple[Future, threading.Timer]] = []
        self.rebuilds = 0

    def submit(self, fn, *args) -> Future:
        future: Future = Future()
        if self.victim in args[1]["a"] and self.deaths > 0:
            self.deaths -= 1
            for other, timer in self.in_flight:
                timer.cancel()
                if not other.done():
                    other.set_exception(_Died())
            self.in_flight = []
            future.set_exception(_Died())
            return future
        timer = threading.Timer(0.05, self._deliver, (future, fn(*args)))
        self.in_flight.append((future, timer))
        timer.start()
        return future

    def _deliver(self, future: Future, outcome: object) -> None:
        if not future.done():
            future.set_result(outcome)

    def death(self, error: BaseException) -> str | None:
        return "worker process died (scripted)" if isinstance(error, _Died) else None

    def rebuild(self) -> None:
        self.rebuilds += 1

    def close(self, kill: bool = False) -> None:
        pass


@pytest.mark.parametrize(("retries", "survives"), [(0, False), (1, True)])
def test_isolation_names_the_killer_and_retries_it(retries: int, survives: bool) -> None:
    params = ramp_params(24)
    params["a"][13] = 13.0  # a unique value to recognise the victim's batches
    campaign = executor._Campaign(
        executor._factory(em.Ramp), params, TIMES, ("y", "batch_size"), retries, None
    )
    tasks = campaign.plan(chunk_bounds(24))
    # Deaths: chunk [12, 14) in the pool, that chunk alone, node 13 alone; then it survives.
    pool = _ScriptedPool(victim=13.0, deaths=3)
    executor._run_pooled(campaign, pool, tasks, executor._Limits())
    result = campaign.result(0.0)
    assert [f.index for f in result.failures] == ([] if survives else [13])
    good = result.status == Status.OK
    assert good.sum() == 24 - (not survives)
    np.testing.assert_array_equal(result.values["y"][good], (params["a"][:, None] * TIMES)[good])
    assert result.values["batch_size"][12, 0] == 1  # the killer chunk was split
    assert (np.delete(result.values["batch_size"][:, 0], [12, 13]) == 2).all()
    assert pool.rebuilds == 3  # after each of the three deaths


# -- arguments and models --------------------------------------------------------------------


def test_bad_arguments_are_all_reported_before_anything_runs() -> None:
    # The execution settings come validated, where they are declared (ExecutionSpec).
    em.SIMULATED.clear()
    params = {"a": np.zeros(4), "b": np.zeros(5), "c": np.array([0.0, np.nan, 1.0, 2.0])}
    with pytest.raises(UsageError) as caught:
        run_nodes(em.Ramp, params, TIMES, "y", execution=ExecutionSpec())
    text = str(caught.value)
    for key in ("params.c", "params:", "outputs"):
        assert f"run_nodes: {key}" in text
    assert em.SIMULATED == []


@pytest.mark.slow
def test_an_output_the_model_lacks_is_rejected_before_running() -> None:
    em.SIMULATED.clear()
    with pytest.raises(UsageError, match=r"outputs: the model has no output \['z'\]"):
        run_nodes(em.Ramp, ramp_params(4), TIMES, ["y", "z"], execution=ExecutionSpec())
    assert em.SIMULATED == []


def test_a_model_that_cannot_be_built_raises_model_error() -> None:
    with pytest.raises(ModelError, match="could not build the model: FileNotFoundError"):
        run_nodes(em.BrokenFactory(), ramp_params(4), TIMES, ["y"], execution=ExecutionSpec())


def test_node_failure_formats_on_one_line() -> None:
    failure = NodeFailure(17, {"A": 0.05, "kT": 1.3e5, "z": (1.0, 2.0, 3.0, 4.0)}, "bad\n  thing")
    assert str(failure) == "node 17 (A=0.05, kT=130000, z=[1, 2, 3, ... (4 values)]): bad thing"


def test_progress_line_only_when_asked_or_on_a_terminal(capsys: pytest.CaptureFixture) -> None:
    run_nodes(
        em.Ramp, ramp_params(24), TIMES, ["y"], progress=True, execution=ExecutionSpec(jobs=1)
    )
    err = capsys.readouterr().err  # not a terminal: whole lines, the last at 100 %
    assert "\r" not in err and err.endswith("\n")
    assert err.splitlines()[-1].startswith("pcmb: 24/24 nodes (100%)")
    assert "nodes/s, ETA 0:00:00" in err
    run_nodes(
        em.Ramp, ramp_params(24), TIMES, ["y"], execution=ExecutionSpec(jobs=1)
    )  # stderr is not a terminal here
    assert capsys.readouterr().err == ""


# -- journal and resume ----------------------------------------------------------------------


def test_resume_takes_journaled_nodes_and_reruns_failed_ones(tmp_path: Path) -> None:
    params = ramp_params(32)
    flaky = functools.partial(em.FlakyRamp, params["a"][[3]], failures=2, nonce=uuid.uuid4().hex)
    journal = Journal(tmp_path / "run.journal", "fp", 32, ["y"], TIMES.size)
    # In this process, to count the calls (SIMULATED) and keep the model's state.
    first = run_nodes(
        flaky, params, TIMES, ["y"], journal=journal, execution=ExecutionSpec(backend="inprocess")
    )
    assert [f.index for f in first.failures] == [3] and first.resumed == 0
    assert Journal(tmp_path / "run.journal", "fp", 32, ["y"], TIMES.size).messages() == {
        3: first.failures[0].message
    }
    em.SIMULATED.clear()
    # Same factory, same cached model: its third call for node 3 succeeds.
    second = run_nodes(
        flaky, params, TIMES, ["y"], journal=journal, execution=ExecutionSpec(backend="inprocess")
    )
    assert second.resumed == 31 and second.failures == ()
    assert em.SIMULATED == [1]  # only node 3, alone as in its narrowed chunk
    np.testing.assert_array_equal(second.values["y"], ramp_exact(params))
    em.SIMULATED.clear()
    third = run_nodes(
        flaky, params, TIMES, ["y"], journal=journal, execution=ExecutionSpec(backend="inprocess")
    )
    assert third.resumed == 32 and em.SIMULATED == []
    np.testing.assert_array_equal(third.values["y"], ramp_exact(params))


@pytest.mark.slow
def test_a_journal_of_another_shape_is_refused(tmp_path: Path) -> None:
    journal = Journal(tmp_path / "j", "fp", 16, ["y"], TIMES.size)
    with pytest.raises(UsageError, match="delete it or start over with --fresh"):
        run_nodes(
            em.Ramp, ramp_params(32), TIMES, ["y"], journal=journal, execution=ExecutionSpec()
        )


_KILLED_RUN = """
import sys
sys.path.insert(0, {tests!r})
import functools
import executor_models as em
from pcmb.config.schema import ExecutionSpec
from pcmb.run.executor import run_nodes
from pcmb.run.journal import Journal

params, times = em.oscillator_nodes(48)
journal = Journal(sys.argv[1], "fp", 48, ["x", "v"], times.size)
model = functools.partial(em.StackedOscillator, sleep=0.4)
execution = ExecutionSpec(jobs=2)
run_nodes(model, params, times, ["x", "v"], journal=journal, progress=False, execution=execution)
"""


@pytest.mark.slow
def test_a_run_killed_with_sigkill_resumes_to_identical_results(
    tmp_path: Path, oscillator_serial
) -> None:
    script = tmp_path / "run.py"
    script.write_text(_KILLED_RUN.format(tests=str(TESTS)))
    directory = tmp_path / "out.h5.journal"
    process = subprocess.Popen(
        [sys.executable, str(script), str(directory)],
        start_new_session=True,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while len(list(directory.glob("record-*.npz"))) < 5:
            assert process.poll() is None, process.stderr.read().decode()
            assert time.monotonic() < deadline, "the run journaled too few chunks in time"
            time.sleep(0.05)
        process.send_signal(signal.SIGKILL)
        process.wait()
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)  # its loky workers too
        process.wait()
        process.stderr.close()
    params, times = em.oscillator_nodes(48)
    journal = Journal(directory, "fp", 48, ["x", "v"], times.size)
    journaled = journal.completed()[0].size
    assert 15 <= journaled < 48  # >= 5 chunks of 3 nodes, not all of them
    em.SIMULATED.clear()
    resumed = run_nodes(
        em.StackedOscillator,
        params,
        times,
        ["x", "v"],
        journal=journal,
        execution=ExecutionSpec(backend="inprocess"),
    )
    assert resumed.resumed == journaled
    assert sum(em.SIMULATED) == 48 - journaled
    assert (resumed.status == Status.OK).all()
    for name in ("x", "v"):
        np.testing.assert_array_equal(resumed.values[name], oscillator_serial.values[name])


def test_a_death_by_a_signal_python_has_no_name_for_is_still_reported() -> None:
    from pcmb.run.backends import _died

    assert _died([-11, -(signal.SIGRTMIN + 1), 3]) == (
        f"worker process died (signal 11, SIGSEGV; signal {signal.SIGRTMIN + 1}, "
        f"SIGRT{signal.SIGRTMIN + 1}; exit code 3)"
    )
