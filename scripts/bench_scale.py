"""How the cost of ``pcmb run`` grows with the work (issue 24, item 5); regenerates the scale
section of ``docs/benchmarks.md``.

A cheap native model (``a·exp(−k t)`` and its shifted copies, one batched numpy call per
chunk) is run as a Monte Carlo study by whole ``pcmb run`` processes, one axis of the work
grown at a time from 1000 runs × 100 times × 1 output:

- runs 10², 10³, 10⁴, 10⁵; time points 10², 10³, 10⁴; outputs 1, 10, 100;
- on the loky backend (2 workers) and on a dask.distributed cluster this script starts
  (``dask scheduler`` and ``dask worker --nworkers 2 --nthreads 1`` on 127.0.0.1, reached
  with ``--address``, ``docs/clusters.md``).

Measured per process: wall seconds; the main process's peak resident memory (its own
``ru_maxrss``, exact); the workers' peak (the sum of their resident memory sampled every
0.05 s, so a short peak can be missed); and, from 10⁴ runs, the marginal wall per run,
(wall − wall of the same study with 2 runs) / (runs − 2), beside the model's own time per
run (one in-process call on every run). The Monte Carlo twin, 10⁶ runs × 1000 times × 2 outputs with
``execution.memory: 2GB``, streams its runs to the file (``docs/benchmarks.md``,
"Streaming"); its peak memory and wall are measured the same way (``--twin``; it writes
32 GB: a 16 GB journal and a 16 GB result file, removed afterwards).

Run: ``python scripts/bench_scale.py [--write] [--twin] [--runs 1000000]``; ``--write``
replaces the parts between the ``bench_scale`` markers in ``docs/benchmarks.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "benchmarks.md"
BASE = {"runs": 1000, "points": 100, "outputs": 1}
#: Fewest runs whose marginal wall per run is reported.
MARGINAL_RUNS = 10_000
GROWN = {
    "runs": (100, 1000, 10_000, 100_000),
    "points": (100, 1000, 10_000),
    "outputs": (1, 10, 100),
}

MODEL = """\
import numpy as np

import pcmb

OUTPUTS = tuple(f"y{{k}}" for k in range({outputs}))


@pcmb.batched(outputs=OUTPUTS)
def decay(params, times):
    a, k = params["a"][:, None], params["k"][:, None]
    y = a * np.exp(-k * times)
    return {{name: y + shift for shift, name in enumerate(OUTPUTS)}}
"""

CONFIG = """\
name: scale
model: {{kind: python, entry: model.py:decay, params: {{a: 1.0, k: 1.0}}}}
time: {{start: 0.0, stop: 5.0, points: {points}}}
inputs:
  a: {{dist: uniform, low: 0.5, high: 1.5}}
  k: {{dist: uniform, low: 0.5, high: 2.0}}
method: {{kind: montecarlo, samples: {runs}, seed: 0}}
execution: {{jobs: 2, memory: {memory}}}
output: out.h5
"""

#: Runs the main process's peak resident memory (ru_maxrss, kB on Linux) into a file.
DRIVER = """\
import resource, runpy, sys
report, sys.argv = sys.argv[1], ["pcmb", *sys.argv[2:]]
try:
    runpy.run_module("pcmb.cli", run_name="__main__")
finally:
    with open(report, "w") as file:
        file.write(str(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024))
"""


def _study(folder: Path, runs: int, points: int, outputs: int, memory: str = "80%") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "model.py").write_text(MODEL.format(outputs=outputs))
    config = folder / "study.yaml"
    config.write_text(CONFIG.format(runs=runs, points=points, memory=memory))
    return config


def _tree_rss(processes: list[psutil.Process]) -> int:
    total = 0
    for process in processes:
        with contextlib.suppress(psutil.Error):
            total += process.memory_info().rss
    return total


def measure(config: Path, *args: str, workers: psutil.Process | None = None) -> dict[str, float]:
    """One whole ``pcmb run``: wall s, main peak bytes, workers' peak bytes (sampled)."""
    report = config.parent / "peak"
    command = [sys.executable, "-c", DRIVER, str(report), "run", str(config), "--quiet", *args]
    start = time.perf_counter()
    process = subprocess.Popen(command, cwd=config.parent, stderr=subprocess.PIPE, text=True)
    watched = psutil.Process(process.pid if workers is None else workers.pid)
    peak = 0
    while process.poll() is None:
        with contextlib.suppress(psutil.Error):
            children = watched.children(recursive=True)
            peak = max(peak, _tree_rss(children))
        time.sleep(0.05)
    wall = time.perf_counter() - start
    errors = process.stderr.read()
    if process.returncode != 0:
        raise RuntimeError(f"pcmb run failed ({process.returncode}): {errors}")
    return {"wall": wall, "main": float(report.read_text()), "workers": float(peak)}


def model_seconds(folder: Path, runs: int, points: int) -> float:
    """The model's own time on every run, in this process (chunks of 256, as pcmb cuts)."""
    namespace: dict[str, object] = {}
    exec((folder / "model.py").read_text(), namespace)
    decay = namespace["decay"]
    rng = np.random.default_rng(0)
    times = np.linspace(0.0, 5.0, points)
    start = time.perf_counter()
    for first in range(0, runs, 256):
        size = min(256, runs - first)
        decay({"a": rng.uniform(0.5, 1.5, size), "k": rng.uniform(0.5, 2.0, size)}, times)
    return time.perf_counter() - start


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def dask_cluster() -> Iterator[tuple[str, psutil.Process]]:
    """A scheduler and 2 single-threaded workers on 127.0.0.1: the address and the worker
    command's process (whose children are the workers)."""
    from distributed import Client

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    python = [sys.executable, "-m"]
    scheduler_args = ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
    scheduler = subprocess.Popen(
        [*python, "distributed.cli.dask_scheduler", *scheduler_args], **quiet
    )
    worker_args = ["--nworkers", "2", "--nthreads", "1", "--no-dashboard", "--memory-limit", "0"]
    worker = subprocess.Popen(
        [*python, "distributed.cli.dask_worker", address, *worker_args], **quiet
    )
    try:
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield address, psutil.Process(worker.pid)
    finally:
        for process in (worker, scheduler):
            process.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(30)
            if process.poll() is None:
                process.kill()


def _row(axis: str, value: int, backend: str, found: dict, fixed: dict, model: float) -> str:
    runs = value if axis == "runs" else BASE["runs"]
    # Below MARGINAL_RUNS the runs' share of the wall is within the noise of a shared machine.
    marginal = (
        f"{(found['wall'] - fixed['wall']) / (runs - 2) * 1e6:.0f}"
        if runs >= MARGINAL_RUNS
        else "–"
    )
    size = {**BASE, axis: value}
    return (
        f"| {backend} | {size['runs']:,} | {size['points']:,} | {size['outputs']} | "
        f"{found['wall']:.1f} | {found['main'] / 1e6:.0f} | {found['workers'] / 1e6:.0f} | "
        f"{marginal} | {model / runs * 1e6:.1f} |"
    )


def scale_table(work: Path) -> list[str]:
    lines = [
        "| backend | runs | times | outputs | wall s | main peak MB | workers peak MB "
        "| marginal µs/run | model µs/run |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for backend in ("loky", "dask"):
        with contextlib.ExitStack() as stack:
            args: tuple[str, ...] = ()
            workers = None
            if backend == "dask":
                address, workers = stack.enter_context(dask_cluster())
                args = ("--address", address)
            fixed_cache: dict[tuple[int, int], dict] = {}
            for axis, values in GROWN.items():
                for value in values:
                    size = {**BASE, axis: value}
                    folder = work / f"{backend}-{axis}-{value}"
                    config = _study(folder, **size)
                    key = (size["points"], size["outputs"])
                    if key not in fixed_cache:
                        small = _study(work / f"{backend}-fixed-{key}", 2, *key)
                        fixed_cache[key] = measure(small, *args, workers=workers)
                    found = measure(config, *args, workers=workers)
                    model = model_seconds(folder, size["runs"], size["points"])
                    lines.append(_row(axis, value, backend, found, fixed_cache[key], model))
                    print(lines[-1], flush=True)
                    shutil.rmtree(folder)
    return lines


def twin(work: Path, runs: int) -> list[str]:
    config = _study(work / "twin", runs, 1000, 2, memory="2GB")
    found = measure(config)
    size = runs * 1000 * 2 * 8
    line = (
        f"Monte Carlo twin, {runs:,} runs × 1000 times × 2 outputs ({size / 1e9:.1f} GB of "
        f"values), `execution.memory: 2GB`, loky, 2 workers: **{found['wall'] / 60:.1f} min**, "
        f"main process peak **{found['main'] / 1e9:.2f} GB** (ru_maxrss), workers' peak "
        f"{found['workers'] / 1e9:.2f} GB (sampled)."
    )
    print(line, flush=True)
    shutil.rmtree(work / "twin")
    return [line]


def _write(part: str, lines: list[str]) -> None:
    """Replace the lines between ``<!-- bench_scale:PART -->`` and its end marker."""
    begin, end = f"<!-- bench_scale:{part} -->", f"<!-- bench_scale:{part} end -->"
    text = PAGE.read_text()
    block = "\n".join([begin, *lines, end])
    if begin not in text:
        raise SystemExit(f"{PAGE} has no {begin} marker")
    text = re.sub(re.escape(begin) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    PAGE.write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md")
    parser.add_argument("--twin", action="store_true", help="also run the Monte Carlo twin")
    parser.add_argument("--only-twin", action="store_true", help="run the twin alone")
    parser.add_argument("--runs", type=int, default=1_000_000, help="runs of the twin")
    parser.add_argument("--work", help="folder for the studies (default: a temporary one)")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    load = os.getloadavg()[0]
    note = f"Load average when started: {load:.1f} on {os.cpu_count()} cores."
    with tempfile.TemporaryDirectory(dir=args.work) as work:
        if not args.only_twin:
            table = [*scale_table(Path(work)), "", note]
            if args.write:
                _write("table", table)
        if args.twin or args.only_twin:
            found = [*twin(Path(work), args.runs), "", note]
            if args.write:
                _write("twin", found)
    print(note)


if __name__ == "__main__":
    main()
