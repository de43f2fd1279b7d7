"""``python -m pcmb.cli`` in a child process, waited for: the tests of what the command line
does as a program (exit codes, stdout and stderr, signals, files left behind).

A test that only needs a run's result calls :func:`pcmb.cli.main` or ``Study.run`` in its own
process instead: a child costs an interpreter start and pcmb's imports.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

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
