"""What running the model in worker processes costs: the main job, isolated and not.

Runs ``pcmb run configs/quarter_car.yaml`` alternately with the default backend (loky: the
model's code in warm worker processes) and with ``--backend inprocess`` (the model's code in
pcmb's own process, no isolation), and prints the median wall time of each and their ratio.
The machine is shared and noisy: the runs alternate, and medians are reported.

    python scripts/bench_isolation.py [--repeat 10]
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
CONFIG = ROOT / "configs" / "quarter_car.yaml"


def _seconds(extra: list[str], output: Path) -> float:
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pcmb.cli",
            "run",
            str(CONFIG),
            "-o",
            str(output),
            "--quiet",
            *extra,
        ],
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    times: dict[str, list[float]] = {"workers (loky)": [], "in-process": []}
    with tempfile.TemporaryDirectory() as folder:
        for k in range(args.repeat):
            output = Path(folder) / f"run{k}.h5"
            times["workers (loky)"].append(_seconds([], output))
            output.unlink()
            times["in-process"].append(_seconds(["--backend", "inprocess"], output))
    medians = {name: statistics.median(values) for name, values in times.items()}
    for name, median in medians.items():
        print(f"{name:<16} median {median:.2f} s over {args.repeat} runs")
    ratio = medians["workers (loky)"] / medians["in-process"]
    print(f"ratio workers / in-process: {ratio:.2f}")


if __name__ == "__main__":
    main()
