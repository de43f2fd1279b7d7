"""Timing helper shared by the benchmark scripts (imported from this folder)."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path


def median_seconds(func: Callable[[], object], repeat: int) -> float:
    """Median wall time of ``repeat`` calls of ``func`` (the machine is shared and noisy)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def process_env(tree: Path | None = None) -> dict[str, str]:
    """The environment of a timed whole process: bytecode written and read (a user's
    ``PYTHONDONTWRITEBYTECODE`` would make every run compile pcmb afresh, 0.2-0.3 s), with
    ``tree`` first on the path when given."""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
    return env


def load_average() -> str:
    """The 1-minute load average and the cores, for the figures printed with it."""
    return f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
