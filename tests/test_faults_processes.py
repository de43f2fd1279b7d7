"""Nothing left running, nothing planted: what pcmb leaves behind when it is killed or refuses.

A ``kill -9`` of pcmb ends every process it started, down to the programs its models start
(a command's own children, a python model's ``subprocess.run``); the processes are found by
a unique ``sleep`` duration in their argv.
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

import psutil
import pytest

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


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kill -9 semantics of Linux")
@pytest.mark.parametrize("study", [_command_study, _python_study], ids=["command", "python"])
def test_kill_9_of_pcmb_leaves_no_program_of_a_model_running(tmp_path: Path, study) -> None:
    marker = _marker()
    config = study(tmp_path, marker)
    pcmb = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "run", str(config), "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    started: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + 120
        while len(_marked(marker)) < 2:  # both workers are in their models' programs
            assert pcmb.poll() is None, pcmb.stderr.read()
            assert time.monotonic() < deadline, "the models' programs did not start in time"
            time.sleep(0.05)
        # Everything pcmb started (workers, helpers, the programs and their children).
        started = psutil.Process(pcmb.pid).children(recursive=True)
        assert {p.pid for p in _marked(marker)} <= {p.pid for p in started}
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


# -- a script whose interpreter is missing --------------------------------------------------


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
