"""Whole-process times of ``pcmb run`` and ``pcmb validate`` against the import floor.

The floor is ``python -c "import numpy, scipy.integrate, h5py"``: what any Python pipeline
that integrates an ODE and writes HDF5 pays before doing anything. Each round runs, one after
the other, the floor, ``pcmb validate CONFIG`` and ``pcmb run CONFIG -o OUT.h5 --quiet`` (and
the same two commands of a ``--baseline`` tree, to compare code side by side); the machine is
shared and noisy, so the commands alternate and medians are printed, with each command's
ratio to the floor. Bytecode is cached by a first, untimed round. Targets: ``run`` at most
2.5 times the floor, ``validate`` of a python model at most 1.5 times.

    python scripts/bench_startup.py [--repeat 5] [--config configs/quarter_car.yaml]
                                    [--baseline OTHER_TREE]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_timing import load_average, process_env

ROOT = Path(__file__).resolve().parents[1]

#: What every whole-process time is compared with: the imports any such pipeline needs.
FLOOR = "import numpy, scipy.integrate, h5py"
#: The most each command should take, in times the floor.
TARGETS = {"validate": 1.5, "run": 2.5}


def _command(name: str, config: Path, output: Path) -> list[str]:
    command = [sys.executable, "-m", "pcmb.cli", name, str(config)]
    return [*command, "-o", str(output), "--quiet"] if name == "run" else command


def _seconds(command: list[str], tree: Path | None, cwd: Path) -> tuple[float, float]:
    """(wall, CPU) seconds of ``command`` as a whole process, with ``tree`` first on the
    path. CPU is user + system of the process and the children it waited for (its workers):
    it hardly depends on the load of the machine, the wall does."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, cwd=cwd, env=process_env(tree), check=True, capture_output=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "quarter_car.yaml")
    parser.add_argument("--baseline", type=Path, help="another tree of pcmb to compare with")
    args = parser.parse_args()
    config = args.config.resolve()
    trees = {"": ROOT, **({"baseline ": args.baseline.resolve()} if args.baseline else {})}
    # Each tree runs its own copy of the config (and so of the models it names), as the
    # models follow the package's own layout.
    configs = {tree: tree / config.relative_to(ROOT) for tree in trees.values()}
    loads = [load_average()]
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        jobs = {"floor": ([sys.executable, "-c", FLOOR], None)}
        for label, tree in trees.items():
            for name in TARGETS:
                jobs[f"{label}{name}"] = (_command(name, configs[tree], work / "out.h5"), tree)
        times: dict[str, list[float]] = {label: [] for label in jobs}
        cpu: dict[str, list[float]] = {label: [] for label in jobs}
        for round_ in range(args.repeat + 1):  # the first round fills the bytecode caches
            for label, (command, tree) in jobs.items():
                seconds, used = _seconds(command, tree, work)
                if round_:
                    times[label].append(seconds)
                    cpu[label].append(used)
    loads.append(load_average())
    floor = statistics.median(times["floor"])
    print(f"whole processes, median of {args.repeat}, alternating ({config.name}):")
    print(f"  {loads[0]} before, {loads[1]} after")
    print(f"  {'':<52}{'wall':>6}    {'ratio':>5}{'':<22}  CPU s")
    for label, seconds in times.items():
        median = statistics.median(seconds)
        used = statistics.median(cpu[label])
        if label == "floor":
            print(f"  {'floor: python -c ' + repr(FLOOR):<52}{floor:6.2f} s{'':<31}{used:5.2f}")
            continue
        name = label.split()[-1]
        ratio = median / floor
        verdict = "meets" if ratio <= TARGETS[name] else "misses"
        print(
            f"  {'pcmb ' + label:<52}{median:6.2f} s  {ratio:4.2f} x the floor "
            f"({verdict} {TARGETS[name]:g} x)  {used:5.2f}"
        )


if __name__ == "__main__":
    main()
