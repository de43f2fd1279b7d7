"""A dask cluster the user started (scheduler and workers as processes of their own, on
127.0.0.1 only) as the target of ``pcmb run``, ``pcmb validate`` and ``pcmb.Study``."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.cli import main

#: The bound the issue sets on a refused address (pcmb waits 5 s at most).
REFUSED_WITHIN = 10.0


@contextlib.contextmanager
def _silent_address() -> Iterator[str]:
    """A dask address on 127.0.0.1 that nothing listens on, its port held bound meanwhile (a
    bound socket that does not listen refuses connections), so no other process (another
    test worker's) can take it between choosing and using it."""
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        yield f"tcp://127.0.0.1:{held.getsockname()[1]}"


def _dask(*args: str, log: Path) -> subprocess.Popen:
    """A ``dask`` command in a process group of its own (its nanny's worker too)."""
    command = [sys.executable, "-m", "dask", *args]  # the `dask` command of this Python
    with open(log, "wb") as out:
        return subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )


def _stop(process: subprocess.Popen) -> None:
    """Stop ``process`` and its group: SIGTERM, then SIGKILL after 10 s."""
    for sig, seconds in ((signal.SIGTERM, 10), (signal.SIGKILL, 10)):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)
        try:
            process.wait(seconds)
            return
        except subprocess.TimeoutExpired:
            continue


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The address of a dask scheduler on 127.0.0.1 with two one-thread workers, each a
    process started by the ``dask`` command line; all stopped afterwards."""
    distributed = pytest.importorskip("distributed")
    folder = tmp_path_factory.mktemp("cluster")
    started: list[subprocess.Popen] = []
    try:
        scheduler_file = folder / "scheduler.json"
        started.append(
            _dask(
                "scheduler",
                "--host", "127.0.0.1",
                "--port", "0",
                "--no-dashboard",
                "--scheduler-file", str(scheduler_file),
                log=folder / "scheduler.log",
            )
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            if started[0].poll() is not None:
                break
            time.sleep(0.2)
        if not scheduler_file.exists():
            pytest.skip(
                f"the dask scheduler did not start: {(folder / 'scheduler.log').read_text()}"
            )
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for number in (1, 2):
            started.append(
                _dask(
                    "worker", address,
                    "--host", "127.0.0.1",
                    "--nthreads", "1",
                    "--no-dashboard",
                    "--local-directory", str(folder / f"worker{number}"),
                    log=folder / f"worker{number}.log",
                )
            )  # fmt: skip
        with distributed.Client(address, timeout=30) as client:
            try:
                client.wait_for_workers(2, timeout=90)
            except TimeoutError:
                pytest.skip("the dask workers did not register within 90 s")
        yield address
    finally:
        for process in reversed(started):
            _stop(process)


def _same_result(a: Path | pcmb.StudyResult, b: Path | pcmb.StudyResult) -> None:
    first = pcmb.load(a) if isinstance(a, Path) else a
    second = pcmb.load(b) if isinstance(b, Path) else b
    assert first.outputs == second.outputs
    assert np.array_equal(first.status, second.status)
    for name in first.outputs:
        for statistic in ("values", "mean", "std"):
            assert np.array_equal(
                getattr(first, statistic)(name) if statistic != "values" else first.values[name],
                getattr(second, statistic)(name) if statistic != "values" else second.values[name],
            ), (name, statistic)


@pytest.mark.slow
def test_run_on_the_cluster_matches_the_run_in_process(scheduler, linear_study, tmp_path, capsys):
    config = linear_study(order=2)
    on_cluster, here = tmp_path / "cluster.h5", tmp_path / "here.h5"
    assert main(["run", str(config), "-o", str(on_cluster), "--address", scheduler, "--quiet"]) == 0
    assert main(["run", str(config), "-o", str(here), "--backend", "inprocess", "--quiet"]) == 0
    _same_result(on_cluster, here)


@pytest.mark.slow
def test_validate_reports_the_workers_of_the_cluster(scheduler, linear_study, capsys):
    config = linear_study(order=2)
    assert main(["validate", str(config), "--address", scheduler]) == 0
    summary = capsys.readouterr().out
    assert f"\ncluster  {scheduler}: 2 workers, 2 threads, " in summary
    assert " GiB" in summary.partition("\ncluster  ")[2].splitlines()[0]


@pytest.mark.slow
def test_a_worker_address_is_not_a_scheduler_address(scheduler, linear_study, capsys):
    distributed = pytest.importorskip("distributed")
    with distributed.Client(scheduler, timeout=30) as client:
        worker = next(iter(client.scheduler_info()["workers"]))
    err = _refused(["validate", str(linear_study(order=2)), "--address", worker], capsys)
    assert f"--address: {worker} is a dask Worker, not a scheduler" in err


def _refused(argv: list[str], capsys) -> str:
    """Run ``pcmb argv``, expect exit 2 within the issue's bound; its stderr."""
    start = time.monotonic()
    code = main(argv)
    seconds = time.monotonic() - start
    err = capsys.readouterr().err
    assert code == 2, err
    assert seconds < REFUSED_WITHIN, f"refused after {seconds:.1f} s"
    assert "Traceback" not in err
    return err


@pytest.mark.slow
def test_nothing_listening_at_the_address_exits_2(linear_study, capsys):
    config = linear_study(order=2)
    with _silent_address() as address:
        err = _refused(["run", str(config), "--address", address, "--quiet"], capsys)
    assert f"--address: no dask scheduler answered at {address}" in err
    assert "Timed out trying to connect" in err
    assert not (config.parent / "out.h5.journal").exists()


@pytest.mark.slow
def test_a_port_that_is_not_dask_is_refused_by_validate(linear_study, capsys):
    with socket.socket() as silent:  # accepts connections, never says a word
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        config = linear_study(order=2, execution=f"backend: dask, address: '{address}'")
        err = _refused(["validate", str(config)], capsys)
    assert f"execution.address: {address} did not answer as a dask scheduler" in err


def test_an_address_that_is_not_one_is_refused(linear_study, capsys):
    config = linear_study(order=2)
    err = _refused(["sweep", str(config), "--address", "127.0.0.1", "--quiet"], capsys)
    assert "--address: '127.0.0.1' is not a dask scheduler address" in err


def test_address_needs_the_dask_backend(linear_study, capsys):
    config = linear_study(order=2)
    with _silent_address() as address:
        err = _refused(["run", str(config), "--address", address, "--backend", "loky"], capsys)
    assert "--address" in err and "--backend dask" in err


def _study(**execution) -> pcmb.Study:
    @pcmb.pointwise(outputs=("y",))
    def model(params, times):  # local, so that it is pickled by value for the workers
        return {"y": params["a"] * np.sin(params["w"] * times)}

    return pcmb.Study(
        model,
        {"a": pcmb.Uniform(0.5, 1.5), "w": pcmb.Normal(2.0, 0.1)},
        times=np.linspace(0, 1, 5),
        order=2,
        params={"a": 1.0, "w": 2.0},
        validation=0,
        **execution,
    )


@pytest.mark.slow
def test_a_client_from_python_is_used_and_left_open(scheduler):
    distributed = pytest.importorskip("distributed")
    here = _study(backend="inprocess").run()
    with distributed.Client(scheduler, timeout=30) as client:
        on_cluster = _study(backend="dask", address=client).run()
        assert client.status == "running"
        assert client.submit(sum, [1, 2]).result() == 3
    _same_result(on_cluster, here)


@pytest.mark.slow
def test_a_cluster_from_python_is_used_and_left_open():
    distributed = pytest.importorskip("distributed")
    here = _study(backend="inprocess").run()
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        on_cluster = _study(backend="dask", address=cluster).run()
        assert cluster.status.name == "running"
        with distributed.Client(cluster) as client:
            assert client.submit(sum, [1, 2]).result() == 3
    _same_result(on_cluster, here)
