"""``pcmb ARGS`` waited for, as a child process (:func:`pcmb_cli`) or in this one
(:func:`pcmb_here`); both give the exit code, stdout and stderr.

A child is what a user runs: it is needed where the process itself is tested (signals, its
environment, stdin, what it imports, what dies with it). Elsewhere :func:`pcmb_here` tests
the same contract without a child's start-up (an interpreter, pcmb's imports, a fresh pool of
workers: the models still run in worker processes, kept warm across the tests).
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from pcmb.cli import main

#: Seconds a command may take before the test fails (a hang fails, it does not stall the suite).
TIMEOUT = 300


def pcmb_cli(
    *args: str,
    cwd: Path | None = None,
    env: Mapping[str, str] | None = None,
    stdin: str | None = None,
) -> subprocess.CompletedProcess[str]:
    """``pcmb ARGS`` in ``cwd``, its environment this one's with ``env`` on top; ``stdin``
    is typed into it. Its exit code is not checked: the tests check it."""
    return subprocess.run(
        [sys.executable, "-m", "pcmb.cli", *args],
        cwd=cwd,
        env=None if env is None else {**os.environ, **env},
        input=stdin,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Print a warning to (the redirected) stderr, as Python does in a process of its own."""
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def pcmb_here(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``pcmb ARGS`` in ``cwd`` by :func:`pcmb.cli.main` in this process: what
    :func:`pcmb_cli` returns. Warnings are shown as a fresh interpreter shows them (the
    suite's own filter turns them into errors)."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with (
        contextlib.chdir(cwd or Path.cwd()),
        contextlib.redirect_stdout(stdout),
        contextlib.redirect_stderr(stderr),
        warnings.catch_warnings(),
    ):
        warnings.resetwarnings()
        for quiet in (DeprecationWarning, PendingDeprecationWarning, ImportWarning):
            warnings.simplefilter("ignore", quiet)
        warnings.simplefilter("ignore", ResourceWarning)
        warnings.showwarning = _show_warning
        code = main(list(args))
    return subprocess.CompletedProcess(list(args), code, stdout.getvalue(), stderr.getvalue())


@contextlib.contextmanager
def gated_pcmb(
    *args: str, cwd: Path, gate: Path, ready: Callable[[], bool]
) -> Iterator[subprocess.Popen[str]]:
    """``pcmb ARGS`` started in ``cwd`` (a child in a session of its own) with ``GATE=gate``
    in its environment, its model waiting while that file exists: the process, once
    ``ready()`` holds (within a minute, the process still running). On leaving the block the
    gate opens and the process must end with exit 0; a block that fails kills it and its
    workers."""
    gate.touch()
    process = subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", *args],
        cwd=cwd,
        env={**os.environ, "GATE": str(gate)},
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not ready():
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.01)
        yield process
        gate.unlink()
        _, err = process.communicate(timeout=120)
        assert process.returncode == 0, err
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
