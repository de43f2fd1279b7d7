"""Nothing left running, nothing planted: what pcmb leaves behind when it is killed or refuses.

A ``kill -9`` of pcmb ends every process it started, down to the programs its models start
(a command's own children, a python model's ``subprocess.run``; the processes are found by
a unique ``sleep`` duration in their argv), and its watchdog ends too. A command script whose
``#!`` interpreter is missing is named so. A result temporary left by a kill in the final
write is removed by the next run, and only when its writer is gone. A time grid too large for
memory is refused before anything runs or is written.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
import uuid
from pathlib import Path

import numpy as np
import psutil
import pytest
from cli_process import pcmb_cli, pcmb_here
from test_resume import PYTHON_CONFIG, PYTHON_MODEL, run_and_kill

#: Seconds a process may take to die after pcmb does (the issue's allowance).
GRACE = 5.0


def _marker() -> str:
    """A sleep duration no other process on the machine uses."""
    return f"{300 + uuid.uuid4().int % 10_000}.{uuid.uuid4().int % 1_000_000:06d}"


def _marked(marker: str) -> list[psutil.Process]:
    """The live processes whose argv holds ``marker``."""
    found = []
    for process in psutil.process_iter(["cmdline", "status"]):
        if marker in (process.info["cmdline"] or []) and process.info["status"] != "zombie":
            found.append(process)
    return found


def _alive(processes: list[psutil.Process]) -> list[psutil.Process]:
    """Those of ``processes`` still running (a zombie has ended), each once."""
    alive = []
    for process in {p.pid: p for p in processes}.values():
        with contextlib.suppress(psutil.NoSuchProcess):
            if process.is_running() and process.status() != psutil.STATUS_ZOMBIE:
                alive.append(process)
    return alive


def _command_study(folder: Path, marker: str) -> Path:
    """A command model: a shell script whose child sleeps ``marker`` seconds."""
    wrapper = folder / "wrapper.sh"
    wrapper.write_text(f"#!/bin/sh\nsleep {marker}\necho done\n")
    wrapper.chmod(0o755)
    return _config(
        folder,
        f"""\
        kind: command
        command: [./wrapper.sh]
        params: {{a: 1.0}}
        outputs: [y]
        output: {{file: out.csv}}
        run_dir: {str(folder / "runs")!r}
        """,
    )


def _python_study(folder: Path, marker: str) -> Path:
    """A python model that runs ``sleep marker`` with ``subprocess.run``."""
    (folder / "sleeper.py").write_text(
        textwrap.dedent(
            f"""\
            import subprocess

            import numpy as np

            import pcmb


            @pcmb.pointwise(outputs=("y",))
            def sleeper(params, times):
                subprocess.run(["sleep", "{marker}"], check=True)
                return {{"y": params["a"] * np.ones_like(times)}}
            """
        )
    )
    return _config(
        folder,
        """\
        kind: python
        entry: sleeper.py:sleeper
        params: {a: 1.0}
        outputs: [y]
        """,
    )


def _config(folder: Path, model: str) -> Path:
    config = folder / "study.yaml"
    config.write_text(
        "name: lifeline\nmodel:\n"
        + textwrap.indent(textwrap.dedent(model), "  ")
        + textwrap.dedent(
            f"""\
            time: {{start: 0.0, stop: 1.0, points: 3}}
            inputs:
              a: {{dist: uniform, low: 0.5, high: 1.5}}
            method: {{kind: collocation, order: 1, validation: 0}}
            execution: {{jobs: 2, backend: loky}}
            output: {str(folder / "out.h5")!r}
            """
        )
    )
    return config


def _kill_9_leaves_nothing(arguments: list[str], marker: str, programs: int) -> None:
    """Start ``pcmb ARGUMENTS``, wait until ``programs`` of the model's marked programs run,
    SIGKILL pcmb: nothing it started, its one watchdog included, is alive after GRACE."""
    pcmb = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", *arguments],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    started: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + 120
        while len(_marked(marker)) < programs:  # the model's programs are running
            assert pcmb.poll() is None, pcmb.stderr.read()
            assert time.monotonic() < deadline, "the models' programs did not start in time"
            time.sleep(0.05)
        # Everything pcmb started (workers, helpers, the programs and their children).
        started = psutil.Process(pcmb.pid).children(recursive=True)
        assert {p.pid for p in _marked(marker)} <= {p.pid for p in started}
        watchdogs = [p for p in started if "pcmb/run/lifeline.py" in " ".join(p.cmdline())]
        assert len(watchdogs) == 1  # it must end too, once its work is done
        os.kill(pcmb.pid, signal.SIGKILL)
        pcmb.wait(timeout=10)
        deadline = time.monotonic() + GRACE
        while (left := _alive(started + _marked(marker))) and time.monotonic() < deadline:
            time.sleep(0.05)
        described = [(p.pid, " ".join(p.cmdline())) for p in left if p.is_running()]
        assert left == [], f"still alive {GRACE:g} s after pcmb was killed: {described}"
    finally:
        for process in _alive(started + _marked(marker)):
            with contextlib.suppress(psutil.NoSuchProcess):
                process.kill()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(pcmb.pid, signal.SIGKILL)
        pcmb.wait()
        pcmb.stderr.close()


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kill -9 semantics of Linux")
@pytest.mark.parametrize(
    ("study", "backend"),
    [(_command_study, "loky"), (_python_study, "loky"), (_python_study, "dask")],
    ids=["command", "python", "python-dask"],
)
def test_kill_9_of_pcmb_leaves_no_program_of_a_model_running(
    tmp_path: Path, study, backend: str
) -> None:
    marker = _marker()
    config = study(tmp_path, marker)
    config.write_text(config.read_text().replace("backend: loky", f"backend: {backend}"))
    _kill_9_leaves_nothing(["run", str(config), "--quiet"], marker, programs=2)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kill -9 semantics of Linux")
def test_kill_9_of_pcmb_validate_leaves_nothing_of_the_model_running(tmp_path: Path) -> None:
    """pcmb validate builds the model in one worker process of its own: killed while the
    model's constructor waits for a program, pcmb leaves neither that process nor the
    program running."""
    marker = _marker()
    (tmp_path / "slow_build.py").write_text(
        "import subprocess\n\n\nclass SlowBuild:\n    outputs = ('y',)\n\n"
        "    def __init__(self, a=1.0):\n"
        f"        subprocess.run(['sleep', '{marker}'], check=True)\n\n"
        "    def simulate(self, params, times):\n        raise NotImplementedError\n"
    )
    config = _config(tmp_path, "kind: python\nentry: slow_build.py:SlowBuild\nparams: {a: 1.0}\n")
    _kill_9_leaves_nothing(["validate", str(config)], marker, programs=1)


# -- a script whose interpreter is missing --------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    ("shebang", "named"),
    [
        ("#!/usr/bin/nonexistent-interpreter", "interpreter '/usr/bin/nonexistent-interpreter'"),
        ("#!/usr/bin/env nonexistent-interpreter", "interpreter 'nonexistent-interpreter'"),
    ],
    ids=["path", "env"],
)
def test_a_script_with_a_missing_interpreter_is_named_at_its_key(
    tmp_path: Path, shebang: str, named: str
) -> None:
    script = tmp_path / "simulate.sh"
    script.write_text(f"{shebang}\nprint('never')\n")
    script.chmod(0o755)
    config = _config(
        tmp_path,
        """\
        kind: command
        command: [./simulate.sh]
        params: {a: 1.0}
        outputs: [y]
        output: {file: out.csv}
        """,
    )
    done = subprocess.run(
        [sys.executable, "-m", "pcmb.cli", "run", str(config)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert "model.command[0]" in done.stderr and named in done.stderr, done.stderr
    assert "No such file or directory" not in done.stderr
    assert not (tmp_path / "out.h5.journal").exists()


# -- the warm workers' semaphores, at the end of a command ------------------------------------


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="named semaphores are not in /dev/shm")
def test_closing_the_warm_workers_frees_their_semaphores_before_it_returns() -> None:
    """``pcmb`` kills its warm loky workers on the way out (a config error, a finished run):
    every named semaphore of their queues is unlinked and unregistered by then, not left to
    loky's daemon threads during interpreter exit, where one can be unlinked but never
    unregistered and the resource tracker warns on stderr (1 to 5 in 180 loaded runs). Nor
    left to the call queue's feeder thread, which loky's shutdown does not join: its queue's
    3 semaphores were still there in 2 of 200 runs beside busy loops on both cores."""
    probe = textwrap.dedent(
        """\
        import glob, os
        from pcmb.run.backends import close_kept, warm_up
        mine = f"/dev/shm/sem.loky-{os.getpid()}-*"
        before = set(glob.glob(mine))  # a killed process of the same pid may have left some
        warm_up(2)
        close_kept(kill=True)
        print(len(set(glob.glob(mine)) - before))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["0"], done.stdout + done.stderr
    assert "resource_tracker" not in done.stderr, done.stderr


def _gone_pid() -> int:
    """The pid of a process that has ended (and been reaped)."""
    done = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    )
    return int(done.stdout)


def test_semaphores_of_ended_processes_of_this_user_are_removed_and_only_those(tmp_path) -> None:
    """What ``kill -9`` of pcmb's process group leaves (its resource tracker dies with it):
    removed when this user's process of that pid is gone; kept when the process lives, the
    file is another user's, or it is no regular file."""
    from pcmb.run.backends import remove_orphaned_semaphores

    gone, alive = _gone_pid(), os.getpid()
    orphans = [tmp_path / f"sem.loky-{gone}-{tag}" for tag in ("k2ax_9q1", "0aa3mz8b")]
    kept = [tmp_path / f"sem.loky-{alive}-k2ax_9q1", tmp_path / f"sem.mp-{gone}-k2ax_9q1"]
    for path in (*orphans, *kept):
        path.write_bytes(bytes(32))
    link = tmp_path / f"sem.loky-{gone}-linked1"
    link.symlink_to(kept[0])
    if os.geteuid() == 0:  # a file of another user, in a shared folder
        kept.append(tmp_path / f"sem.loky-{gone}-theirs1")
        kept[-1].write_bytes(bytes(32))
        os.chown(kept[-1], 65534, 65534)
    assert remove_orphaned_semaphores(tmp_path) == 2
    assert sorted(tmp_path.iterdir()) == sorted([*kept, link])
    assert remove_orphaned_semaphores(tmp_path / "absent") == 0


@pytest.mark.slow
@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="named semaphores are not in /dev/shm")
def test_a_run_after_a_killed_process_group_removes_its_semaphores(tmp_path) -> None:
    """Each ``kill -9`` of a ``pcmb run``'s process group left its 15 semaphores in /dev/shm
    (10,051 after a day of test suites); the next run removes them."""
    (tmp_path / "model.py").write_text(PYTHON_MODEL)
    (tmp_path / "study.yaml").write_text(PYTHON_CONFIG)
    killed = run_and_kill(tmp_path, after=2)
    left = sorted(Path("/dev/shm").glob(f"sem.loky-{killed}-*"))
    assert left  # what loky's resource tracker, killed too, did not unlink
    done = pcmb_cli("run", "study.yaml", "--quiet", "--resume", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert [path for path in left if path.exists()] == []


# -- a result file's temporary, left by a kill -9 during the final write ---------------------

LINEAR = """\
import numpy as np

import pcmb


@pcmb.pointwise(outputs=("y",))
def linear(params, times):
    return {"y": params["a"] * times}
"""


def _linear_study(folder: Path) -> Path:
    (folder / "linear.py").write_text(LINEAR)
    return _config(
        folder,
        """\
        kind: python
        entry: linear.py:linear
        params: {a: 1.0}
        outputs: [y]
        """,
    )


#: ``pcmb run`` that is killed (SIGKILL) in its final write, the result's temporary written in
#: full but not yet renamed into place.
KILLED_IN_THE_FINAL_WRITE = """\
import os, signal, sys

import pcmb.run.files
import pcmb.run.journal  # binds the real replace_durably: the journal's records are written
from pcmb.cli import main


def killed(temporary, path):
    os.kill(os.getpid(), signal.SIGKILL)


pcmb.run.files.replace_durably = killed
main(["run", sys.argv[1], "--quiet"])
"""


@pytest.mark.slow
def test_a_temporary_left_by_a_kill_in_the_final_write_is_removed_by_the_resume(
    tmp_path: Path,
) -> None:
    config = _linear_study(tmp_path)
    killed = subprocess.run(
        [sys.executable, "-c", KILLED_IN_THE_FINAL_WRITE, str(config)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    left = {p.name for p in tmp_path.iterdir() if p.name.startswith(".out.h5.")}
    assert len(left) == 1 and (tmp_path / left.pop()).stat().st_size > 0
    resumed = subprocess.run(
        [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet", "--resume"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert resumed.returncode == 0, resumed.stderr
    assert sorted(p.name for p in tmp_path.iterdir() if "out.h5" in p.name) == ["out.h5"]


#: Writes ``sys.argv[1]`` by write_durably, then waits before renaming it into place.
WRITING = """\
import signal, sys
from pathlib import Path

import pcmb.run.files


def waiting(temporary, path):
    print("written", flush=True)
    signal.pause()


pcmb.run.files.replace_durably = waiting
pcmb.run.files.write_durably(Path(sys.argv[1]), b"x" * 100_000)
"""


def test_only_the_temporaries_of_dead_writers_are_removed(tmp_path: Path) -> None:
    from pcmb.run.output import check_output

    output = tmp_path / "out.h5"
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITING, str(output)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert writer.stdout.readline() == "written\n"
        (temporary,) = tmp_path.iterdir()
        check_output(output, create=True)  # what a run checks first
        assert list(tmp_path.iterdir()) == [temporary]  # its writer is still at work
    finally:
        writer.kill()
        writer.wait()
        writer.stdout.close()
    check_output(output, create=True)
    assert list(tmp_path.iterdir()) == []


# -- a time grid too large for memory --------------------------------------------------------

HUGE_POINTS = 10_000_000

WIDE = """\
import numpy as np

import pcmb


@pcmb.batched(outputs=("x", "v"))
def wide(params, times):
    zeros = np.zeros((params["a"].size, times.size))
    return {"x": zeros, "v": zeros}
"""


@pytest.mark.slow
@pytest.mark.parametrize("resume", [False, True], ids=["run", "resume"])
def test_a_time_grid_too_large_for_memory_is_refused_before_any_run(
    tmp_path: Path, resume: bool
) -> None:
    (tmp_path / "wide.py").write_text(WIDE)
    config = _config(
        tmp_path,
        """\
        kind: python
        entry: wide.py:wide
        params: {a: 1.0}
        """,
    ).read_text()
    config = config.replace("points: 3", f"points: {HUGE_POINTS}").replace("jobs: 2", "jobs: 1")
    (tmp_path / "study.yaml").write_text(config)
    done = pcmb_here("run", str(tmp_path / "study.yaml"), *["--resume"] * resume)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    message = done.stderr.lower()
    assert "memory" in message and "available" in message and "time.points" in message
    assert f"{HUGE_POINTS} times" in done.stderr
    # Nothing was written: no journal, no result, no temporary.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.yaml", "wide.py"]
    if not resume:  # pcmb validate checks what a run checks
        checked = pcmb_here("validate", str(tmp_path / "study.yaml"))
        assert checked.returncode == 2 and "of memory, more than" in checked.stderr


@pytest.mark.slow
def test_the_memory_estimate_of_the_quarter_car_is_small() -> None:
    from pcmb.config.schema import load_config
    from pcmb.study import Study

    config = load_config(Path(__file__).parents[1] / "configs" / "quarter_car.yaml")
    study = Study.from_config(config)
    estimate = study.memory_estimate(study.node_set().size, config.model.outputs)
    # It counts what the config asks for: the (order + 1)^d tensor nodes, the most held-out
    # runs the study may make, every time, both outputs, and the range check's draws.
    nodes = (config.method.order + 1) ** len(config.inputs)
    assert (estimate.nodes, estimate.held_out) == (nodes, study.held_out_runs(nodes)[1])
    assert (estimate.width, estimate.outputs) == (config.time.points, len(config.model.outputs))
    assert estimate.draws > 0
    # A few copies of 270 runs × 301 times × 2 outputs (1.3 MB each): tens of MB, not more.
    assert estimate.values < estimate.total < 64 * 2**20


def test_an_interpreter_gone_after_the_check_is_named_in_the_failure(tmp_path: Path) -> None:
    from pcmb.adapters.command.model import CommandModel
    from pcmb.errors import ModelError

    script = tmp_path / "simulate.sh"
    script.write_text("#!/bin/sh\necho time,y > out.csv\n")
    script.chmod(0o755)
    model = CommandModel(
        [str(script)], params={"a": 1.0}, outputs=["y"], output_file="out.csv", keep="none"
    )
    script.write_text("#!/usr/bin/nonexistent-interpreter\n")  # changed after the check
    with pytest.raises(ModelError) as failed:
        model.run_point({"a": 1.0}, np.linspace(0.0, 1.0, 3))
    assert "interpreter '/usr/bin/nonexistent-interpreter'" in str(failed.value)
    assert "No such file or directory" not in str(failed.value)


@pytest.mark.slow
def test_pcmb_ends_without_waiting_for_workers_still_starting(tmp_path: Path) -> None:
    """`pcmb run` starts its workers before it reads the config: on a bad config it exits at
    once, killing them, instead of waiting for them to finish starting."""
    (tmp_path / "sitecustomize.py").write_text(  # loky's workers hang while they start
        "import sys, time\nif 'LokyProcess' in ' '.join(sys.argv): time.sleep(600)\n"
    )
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    done = subprocess.run(
        [sys.executable, "-m", "pcmb.cli", "run", str(tmp_path / "missing.yaml"), "-o", "o.h5"],
        cwd=tmp_path,
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
