"""Benchmark of the native simulators (issue 3): one stacked batch vs one solver call per node.

The quarter car of ``configs/quarter_car.yaml`` (cubic spring, sine terrain, 0–3 s, 301 output
times) on its 216 collocation nodes (6 Gauss–Legendre points in each of A, kT, c), at the
model's default tolerances (DOP853, rtol 1e-8, atol 1e-10, per node):

- batched: one ``simulate`` call with B = 216, i.e. one ``solve_ivp`` call on 864 states;
- baseline: 216 ``simulate`` calls with B = 1, i.e. 216 ``solve_ivp`` calls at the same
  tolerances, as a per-point loop over the nodes would run them;

and the largest difference between the two results, per output, relative to the output's
largest magnitude (both runs promise 1e-6 of it against a tight reference).

The model is loaded through pcmb's own entry-point loader, as a config's
``entry: ../models/quarter_car.py:QuarterCar`` would be.

Run: ``python scripts/bench_models.py [--repeat 3]``. Medians are printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from bench_timing import median_seconds

from pcmb.adapters.python import load_entry

ROOT = Path(__file__).resolve().parents[1]
RANGES = {"A": (0.025, 0.075), "kT": (1.2e5, 1.8e5), "c": (800.0, 1200.0)}  # the config's
POINTS = 6  # order 5


def _nodes():
    """The 6×6×6 tensor Gauss–Legendre grid of the config's ranges: name -> (216,)."""
    points, _ = np.polynomial.legendre.leggauss(POINTS)
    axes = [0.5 * (lo + hi) + 0.5 * (hi - lo) * points for lo, hi in RANGES.values()]
    mesh = np.meshgrid(*axes, indexing="ij")
    return {name: m.ravel() for name, m in zip(RANGES, mesh, strict=True)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing (median)")
    args = parser.parse_args()

    model = load_entry("models/quarter_car.py:QuarterCar", ROOT)()
    params = _nodes()
    n_nodes = len(params["A"])
    times = np.linspace(0.0, 3.0, 301)

    def batched():
        return model.simulate(params, times)

    def per_node():
        runs = [
            model.simulate({name: values[i : i + 1] for name, values in params.items()}, times)
            for i in range(n_nodes)
        ]
        return {name: np.concatenate([run[name] for run in runs]) for name in model.outputs}

    seconds_batched = median_seconds(batched, args.repeat)
    seconds_per_node = median_seconds(per_node, args.repeat)
    together, alone = batched(), per_node()

    print(f"quarter car, {n_nodes} nodes x {times.size} times, rtol {model.rtol:g}")
    print(f"  one batched solve_ivp call      {seconds_batched:8.3f} s")
    print(f"  {n_nodes} per-node solve_ivp calls   {seconds_per_node:8.3f} s")
    print(f"  ratio per-node / batched        {seconds_per_node / seconds_batched:8.1f} x")
    for name in ("x1", "x2", "v1", "v2", "a1"):
        difference = np.abs(together[name] - alone[name]).max()
        scale = np.abs(alone[name]).max()
        relative = difference / scale
        print(f"  max |batched - per-node| {name:2s}   {difference:9.2e} ({relative:.1e} rel)")


if __name__ == "__main__":
    main()
