"""What running the model in worker processes costs: the main job, isolated and not.

Runs ``pcmb run configs/quarter_car.yaml`` alternately in up to three ways and prints the
median wall time of each and the ratios to the first:

- ``--baseline REV``: the code of a git revision from before model isolation (run from a
  temporary worktree of this repository), which ran small campaigns in its own process;
- ``workers``: this tree's default, the model's code in warm loky workers, with the held-out
  check off (``method.validation: 0``) so that only isolation differs from the baseline;
- ``in-process``: this tree with ``--backend inprocess`` (no isolation, no parallelism);
- ``workers, held-out on``: this tree's main job as it ships, with its held-out check.

The machine is shared and noisy: the runs alternate, and medians are reported.

    python scripts/bench_isolation.py [--repeat 10] [--baseline a6ba91e]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "quarter_car.yaml"


def _seconds(tree: Path, config: Path, output: Path, extra: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pcmb.cli",
            "run",
            str(config),
            "-o",
            str(output),
            "--quiet",
            *extra,
        ],
        check=True,
        capture_output=True,
        cwd=tree,
        env={**os.environ, "PYTHONPATH": str(tree)},
    )
    elapsed = time.perf_counter() - start
    output.unlink()
    return elapsed


def _without_validation(folder: Path) -> Path:
    """The main job's config with the held-out check off, its model path made absolute."""
    text = CONFIG.read_text().replace("../models/", f"{ROOT}/models/")
    method = "method: {kind: collocation, order: 5, basis: tensor}"
    if method not in text:
        raise SystemExit(f"{CONFIG}: expected the line {method!r}")
    config = folder / "quarter_car_no_validation.yaml"
    config.write_text(text.replace(method, method[:-1] + ", validation: 0}"))
    return config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--baseline", help="git revision to compare with (e.g. a6ba91e)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        config = _without_validation(folder)
        ways = {
            "workers": (ROOT, config, []),
            "in-process": (ROOT, config, ["--backend", "inprocess"]),
            "workers, held-out on": (ROOT, CONFIG, []),
        }
        if args.baseline:
            baseline = folder / "baseline"
            subprocess.run(
                [
                    "git",
                    "-C",
                    str(ROOT),
                    "worktree",
                    "add",
                    "--detach",
                    str(baseline),
                    args.baseline,
                ],
                check=True,
                capture_output=True,
            )
            ways = {
                f"baseline {args.baseline}": (baseline, baseline / CONFIG.relative_to(ROOT), [])
            } | ways
        try:
            times: dict[str, list[float]] = {way: [] for way in ways}
            for k in range(args.repeat):
                for way, (tree, path, extra) in ways.items():
                    times[way].append(_seconds(tree, path, folder / f"{k}.h5", extra))
        finally:
            if args.baseline:
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(baseline)],
                    check=True,
                )
    medians = {way: statistics.median(values) for way, values in times.items()}
    first = next(iter(medians))
    for way, median in medians.items():
        ratio = median / medians[first]
        print(f"{way:<20} median {median:.2f} s over {args.repeat} runs, {ratio:.2f}x")


if __name__ == "__main__":
    main()
