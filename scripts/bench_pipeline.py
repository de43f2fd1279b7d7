"""Whole-process benchmark of ``pcmb run configs/quarter_car.yaml`` (issue 4).

Three whole processes (imports included), each timed ``--repeat`` times; medians are
printed:

- the main job, ``pcmb run configs/quarter_car.yaml -o OUT.h5 --quiet``;
- the floor, ``python -c "import numpy, scipy.integrate, h5py"``: what any Python pipeline
  that integrates an ODE and writes HDF5 pays before doing anything. The main job is
  reported side by side with it, as a ratio (target: at most 2.5 times the floor);
- the baseline a user writes today with chaospy on the same model: Gauss quadrature of
  order 5 (216 nodes), one ``solve_ivp`` per node at the same tolerance as pcmb's model
  (DOP853, rtol 1e-8, atol 1e-10), ``fit_quadrature`` and mean/std.

Also: ``pcmb --help`` start-up time against a bare ``python -c pass``; and the CPU seconds
(user + system) of each tree's main job: its own when ``pcmb run`` returns, and its workers',
those of the whole process and the children it reaped (its workers, at exit) less its own.
The workers' CPU hardly depends on the load of the machine, the wall does.

The jobs alternate (the machine is shared: the load of the moment hits each of them), after an
untimed round that fills the bytecode caches; ``--baseline OTHER_TREE`` adds the main job of
another tree of pcmb, side by side.

Run: ``python scripts/bench_pipeline.py [--repeat 5] [--baseline OTHER_TREE]``.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from bench_timing import load_average, median_seconds, process_env

ROOT = Path(__file__).resolve().parents[1]

#: What every whole-process time is compared with: the imports any such pipeline needs.
FLOOR = "import numpy, scipy.integrate, h5py"
#: The main job should take at most this many times the floor.
TARGET_RATIO = 2.5
#: ... and at most this fraction of the chaospy pipeline's time.
CHAOSPY_RATIO = 0.1

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


#: ``pcmb run ARGS`` as ``python -m pcmb.cli`` runs it, then the CPU seconds of the process so
#: far on the last line of stdout.
RUN_AND_SAY_CPU = """
import resource, sys
from pcmb.cli import main
code = main(["run", *sys.argv[1:]])
own = resource.getrusage(resource.RUSAGE_SELF)
print(own.ru_utime + own.ru_stime)
sys.exit(code)
"""


def _process(
    command: list[str], cwd: Path, tree: Path | None = None
) -> Callable[[], tuple[str, float]]:
    """A call that runs ``command`` as a whole process (failing loudly if it fails), with
    ``tree`` first on the path: its stdout, and the CPU seconds of the process and of the
    children it reaped."""
    env = process_env(tree)

    def run() -> tuple[str, float]:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(command, cwd=cwd, env=env, check=True, capture_output=True, text=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        used = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        return done.stdout, used

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--baseline", type=Path, help="another tree of pcmb to compare with")
    args = parser.parse_args()
    trees = {"": ROOT, **({"baseline ": args.baseline.resolve()} if args.baseline else {})}
    loads = [load_average()]
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        baseline = work / "chaospy_pipeline.py"
        baseline.write_text(CHAOSPY_PIPELINE)
        jobs = {"floor": _process([sys.executable, "-c", FLOOR], work)}
        for label, tree in trees.items():
            # Each tree runs its own copy of the config (its models follow its own layout).
            config = tree / "configs" / "quarter_car.yaml"
            command = [sys.executable, "-c", RUN_AND_SAY_CPU, str(config), "-o", "qc.h5"]
            jobs[f"{label}pcmb run"] = _process([*command, "--quiet"], work, tree)
        jobs["chaospy"] = _process([sys.executable, str(baseline)], work)
        for job in jobs.values():  # untimed: fills the bytecode caches
            job()
        times: dict[str, list[float]] = {label: [] for label in jobs}
        cpu: dict[str, list[list[float]]] = {label: [] for label in jobs}
        for _ in range(args.repeat):  # alternating: the load of the moment hits every job
            for label, job in jobs.items():
                start = time.perf_counter()
                out, used = job()
                times[label].append(time.perf_counter() - start)
                if label.endswith("pcmb run"):
                    own = float(out.strip().splitlines()[-1])
                    cpu[label].append([own, used - own])
        help_s = median_seconds(_process([sys.executable, "-m", "pcmb.cli", "--help"], work), 5)
        bare_s = median_seconds(_process([sys.executable, "-c", "pass"], work), 5)
    loads.append(load_average())
    median = {label: statistics.median(seconds) for label, seconds in times.items()}
    floor, theirs = median["floor"], median["chaospy"]
    print(f"whole process, median of {args.repeat} (quarter car, 216 nodes x 301 times):")
    print(f"  {loads[0]} before, {loads[1]} after")
    print(f"  {'floor: python -c ' + repr(FLOOR):<58}{floor:7.2f} s")
    print(f"  {'chaospy pipeline':<58}{theirs:7.2f} s")
    for label in trees:
        ours = median[f"{label}pcmb run"]
        ratio = ours / floor
        verdict = "meets" if ratio <= TARGET_RATIO else "misses"
        own, workers = (
            statistics.median(used) for used in zip(*cpu[f"{label}pcmb run"], strict=True)
        )
        print(
            f"  {label + 'pcmb run configs/quarter_car.yaml':<58}{ours:7.2f} s  "
            f"{ratio:.2f} x the floor ({verdict} {TARGET_RATIO:g} x), "
            f"{ours / theirs:.3f} x chaospy (target {CHAOSPY_RATIO:g}); "
            f"CPU {own:.2f} s own, {workers:.2f} s workers"
        )
    print(f"pcmb --help {help_s * 1e3:.0f} ms (bare python {bare_s * 1e3:.0f} ms), median of 5")


if __name__ == "__main__":
    main()
