"""Whole-process benchmark of ``pcmb run configs/quarter_car.yaml`` (issue 4).

Baseline: the pipeline a user writes today with chaospy on the same model — Gauss
quadrature of order 5 (216 nodes), one ``solve_ivp`` per node at the same tolerance as
pcmb's model (DOP853, rtol 1e-8, atol 1e-10), ``fit_quadrature`` and mean/std. Both run as
whole processes (imports included), interleaved, ``--repeat`` times; medians are printed.

Also: ``pcmb --help`` start-up time against a bare ``python -c pass``.

Run: ``python scripts/bench_pipeline.py [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHAOSPY_PIPELINE = """
import chaospy
import numpy as np
from scipy.integrate import solve_ivp

Ms, Mu, k, f = 250.0, 35.0, 6.0e6, 1.0
times = np.linspace(0.0, 3.0, 301)
joint = chaospy.J(
    chaospy.Uniform(0.025, 0.075), chaospy.Uniform(1.2e5, 1.8e5), chaospy.Uniform(800.0, 1200.0)
)
nodes, weights = chaospy.generate_quadrature(5, joint, rule="gaussian")


def rhs(t, y, A, kT, c):
    x1, x2, v1, v2 = y
    spring, damper = k * (x1 - x2) ** 3, c * (v1 - v2)
    z = A * np.sin(2 * np.pi * f * t)
    return [v1, v2, (-spring - damper) / Ms, (spring + damper + kT * (z - x2)) / Mu]


runs = []
for A, kT, c in nodes.T:
    sol = solve_ivp(rhs, (0.0, 3.0), [0.0] * 4, method="DOP853", t_eval=times,
                    rtol=1e-8, atol=1e-10, args=(A, kT, c))
    runs.append(sol.y[:2].T.ravel())
expansion = chaospy.generate_expansion(5, joint, normed=True)
model = chaospy.fit_quadrature(expansion, nodes, weights, np.array(runs))
mean, std = chaospy.E(model, joint), chaospy.Std(model, joint)
print(float(mean.max()), float(std.max()))
"""


def _timed(command: list[str], cwd: Path) -> float:
    start = time.perf_counter()
    subprocess.run(command, cwd=cwd, check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        baseline = work / "chaospy_pipeline.py"
        baseline.write_text(CHAOSPY_PIPELINE)
        pcmb_run = [
            sys.executable, "-m", "pcmb.cli", "run", str(ROOT / "configs" / "quarter_car.yaml"),
            "-o", str(work / "qc.h5"), "--quiet",
        ]  # fmt: skip
        pcmb_times, chaospy_times = [], []
        for _ in range(args.repeat):
            pcmb_times.append(_timed(pcmb_run, work))
            chaospy_times.append(_timed([sys.executable, str(baseline)], work))
        ours, theirs = statistics.median(pcmb_times), statistics.median(chaospy_times)
        print(
            f"quarter car, 216 nodes x 301 times, whole process (median of {args.repeat}): "
            f"pcmb run {ours:.2f} s, chaospy pipeline {theirs:.2f} s -> ratio {ours / theirs:.3f}"
        )
        help_times = [_timed([sys.executable, "-m", "pcmb.cli", "--help"], work) for _ in range(5)]
        bare = [_timed([sys.executable, "-c", "pass"], work) for _ in range(5)]
        print(
            f"pcmb --help {statistics.median(help_times) * 1e3:.0f} ms "
            f"(bare python {statistics.median(bare) * 1e3:.0f} ms), median of 5"
        )


if __name__ == "__main__":
    main()
