"""What pcmb's FMU adapter costs per node, against a bare FMPy loop on the same FMU.

Both run the damped oscillator of models/fmu/ (built here by pythonfmu) over the same 101
output times on [0, 5] s, one co-simulation step per output interval, on one instance made
once and reset between nodes:

- *bare*: FMPy's ``FMU2Slave`` driven by hand: per node ``setupExperiment``, ``setReal`` of
  the four parameters, initialization, then ``doStep`` and ``getReal`` of the two outputs at
  every interval, ``terminate`` and ``reset``;
- *pcmb*: ``FmuModelFactory(...)()``, the model a worker builds once, and its
  ``simulate`` on a chunk of nodes (what a worker runs per chunk).

They run side by side, ``--rounds`` times ``--nodes`` nodes each, which one goes first
alternating (the machine may be shared and noisy: each round's ratio compares runs made
moments apart); the seconds per node and the median ratio pcmb / bare are printed (the
target: at most 1.2).

    python scripts/bench_fmu.py [--rounds 40] [--nodes 50]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from build_fmus import build  # beside this script, on sys.path when it runs
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

import pcmb

TIMES = np.linspace(0.0, 5.0, 101)


def bare_loop(fmu: Path, k: np.ndarray, c: np.ndarray) -> tuple[float, np.ndarray]:
    """Seconds per node of the hand-written FMPy loop, and x, (N, T)."""
    md = read_model_description(str(fmu))
    unzipdir = fmu.with_suffix("")  # beside the FMU, in the script's temporary folder
    if not unzipdir.is_dir():
        extract(str(fmu), unzipdir=unzipdir)
    refs = {v.name: v.valueReference for v in md.modelVariables}
    instance = FMU2Slave(
        guid=md.guid,
        unzipDirectory=str(unzipdir),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="bare",
    )
    instance.instantiate()
    inputs = [refs[name] for name in ("k", "c", "x0", "v0")]
    outputs = [refs["x"], refs["v"]]
    x = np.empty((k.size, TIMES.size))
    start = time.perf_counter()
    for i in range(k.size):
        instance.setupExperiment(startTime=TIMES[0], stopTime=TIMES[-1])
        instance.setReal(inputs, [k[i], c[i], 1.0, 0.0])
        instance.enterInitializationMode()
        instance.exitInitializationMode()
        x[i, 0] = instance.getReal(outputs)[0]
        for j in range(1, TIMES.size):
            instance.doStep(TIMES[j - 1], TIMES[j] - TIMES[j - 1])
            x[i, j] = instance.getReal(outputs)[0]
        instance.terminate()
        instance.reset()
    seconds = (time.perf_counter() - start) / k.size
    instance.freeInstance()
    return seconds, x


def pcmb_adapter(fmu: Path, k: np.ndarray, c: np.ndarray) -> tuple[float, np.ndarray]:
    """Seconds per node of the adapter's ``simulate`` on one chunk, and x, (N, T)."""
    model = pcmb.FmuModelFactory(fmu=fmu, params={"x0": 1.0, "v0": 0.0}, outputs=("x", "v"))()
    start = time.perf_counter()
    out = model.simulate({"k": k, "c": c}, TIMES)
    return (time.perf_counter() - start) / k.size, out["x"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=40)
    parser.add_argument("--nodes", type=int, default=50)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    k = rng.uniform(3.5, 4.5, args.nodes)
    c = rng.uniform(0.2, 0.6, args.nodes)
    with tempfile.TemporaryDirectory() as folder:
        (fmu,) = build(Path(folder))
        seconds: dict[str, list[float]] = {"bare": [], "pcmb": []}
        for round_ in range(args.rounds):
            if round_ % 2:
                ours, x_ours = pcmb_adapter(fmu, k, c)
                bare, x_bare = bare_loop(fmu, k, c)
            else:
                bare, x_bare = bare_loop(fmu, k, c)
                ours, x_ours = pcmb_adapter(fmu, k, c)
            np.testing.assert_array_equal(x_ours, x_bare)  # the same runs, bit for bit
            seconds["bare"].append(bare)
            seconds["pcmb"].append(ours)
    ratios = [o / b for o, b in zip(seconds["pcmb"], seconds["bare"], strict=True)]
    for name, values in seconds.items():
        print(f"{name:<5} median {1e3 * statistics.median(values):.3f} ms per node")
    print(
        f"ratio pcmb / bare: median {statistics.median(ratios):.3f} "
        f"(min {min(ratios):.3f}, max {max(ratios):.3f}) over {args.rounds} rounds of "
        f"{args.nodes} nodes, {TIMES.size} output times"
    )


if __name__ == "__main__":
    main()
