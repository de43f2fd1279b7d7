"""What bounding the main process's native threads buys on a loaded machine.

A random-process input's eigen-solve (the Karhunen-Loeve expansion of
``configs/oscillator_kl_process.yaml``: 1,401 points) runs in the main process while a config
loads, when pcmb's workers are starting or busy. This script loads the cores with ``--load``
busy processes (default: one per core, as workers would) and times the same expansion in a
fresh interpreter, alternately with the BLAS threads the machine gives it (``default``) and
inside :func:`pcmb.run.threads.one_thread_here` (``one thread``): medians and their ratio.
``--load 0`` measures the idle machine.

    python scripts/bench_threads.py [--repeat 5] [--load 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

EXPANSION = """
import time
from contextlib import nullcontext
from pcmb.chaos import process
from pcmb.run.threads import one_thread_here
covariance = process.covariance_from_description({spec})
with {context}:
    start = time.perf_counter()
    process.RandomProcess.karhunen_loeve(covariance, 0.0, 700.0, 1401, energy=0.99)
    print(time.perf_counter() - start)
"""


def _spec() -> str:
    import yaml

    with open(
        os.path.join(os.path.dirname(__file__), "..", "configs", "oscillator_kl_process.yaml")
    ) as handle:
        inputs = yaml.safe_load(handle)["inputs"]
    (section,) = [s for s in inputs.values() if "process" in s]
    return repr(section["covariance"])


def _seconds(context: str, spec: str) -> float:
    code = EXPANSION.format(context=context, spec=spec)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(done.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--load", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    spec = _spec()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    try:
        times: dict[str, list[float]] = {"default": [], "one thread": []}
        for _ in range(args.repeat):
            times["default"].append(_seconds("nullcontext()", spec))
            times["one thread"].append(_seconds("one_thread_here()", spec))
    finally:
        for process in busy:
            process.kill()
            process.wait()
    base = statistics.median(times["default"])
    print(
        f"KL eigen-solve (1,401 points) with {args.load} busy processes, "
        f"median of {args.repeat}, {time.strftime('%Y-%m-%d')}"
    )
    for name, found in times.items():
        median = statistics.median(found)
        print(f"  {name:<11} {median:7.2f} s   ratio {median / base:5.2f}")


if __name__ == "__main__":
    main()
