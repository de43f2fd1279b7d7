"""Run every config in ``configs/`` and compare its result datasets with a saved baseline.

Usage::

    python scripts/check_identical.py save BASELINE_DIR     # run all configs, keep the files
    python scripts/check_identical.py check BASELINE_DIR    # run again, compare bit for bit
    python scripts/check_identical.py check BASELINE_DIR quarter_car   # only these configs

Only the public command line is used (``pcmb run CONFIG -o FILE``), so the script checks
the whole path a user takes. Every numeric dataset under ``/`` is compared byte for byte;
attributes that record when or how a file was made (``created``, ``versions``,
``command_line``, ``seconds``) are not. A config without a baseline file is reported as
new. Exit status 1 when anything differs.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def run_all(folder: Path, names: list[str]) -> dict[str, Path]:
    """Run the configs of ``configs/`` named in ``names`` (every one when empty) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    written = {}
    configs = sorted((ROOT / "configs").glob("*.yaml"))
    unknown = set(names) - {config.stem for config in configs}
    if unknown:
        sys.exit(f"no such config in configs/: {', '.join(sorted(unknown))}")
    for config in configs:
        if names and config.stem not in names:
            continue
        target = folder / f"{config.stem}.h5"
        command = ["pcmb", "run", str(config), "-o", str(target), "--quiet"]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            sys.exit(f"{config.name}: pcmb run exited {done.returncode}\n{done.stderr}")
        written[config.stem] = target
    return written


def datasets(path: Path) -> dict[str, np.ndarray]:
    found: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as file:

        def visit(name: str, item: object) -> None:
            if isinstance(item, h5py.Dataset) and item.dtype.kind in "fiucb":
                found[name] = item[()]

        file.visititems(visit)
    return found


def differences(baseline: Path, fresh: Path) -> list[str]:
    old, new = datasets(baseline), datasets(fresh)
    problems = [f"missing {name}" for name in sorted(set(old) - set(new))]
    for name in sorted(set(old) & set(new)):
        a, b = old[name], new[name]
        if a.shape != b.shape or a.dtype != b.dtype:
            problems.append(f"{name}: {a.dtype}{a.shape} -> {b.dtype}{b.shape}")
        elif a.tobytes() != b.tobytes():
            both = np.isfinite(a) & np.isfinite(b) if a.dtype.kind == "f" else None
            worst = np.max(np.abs(a - b)[both]) if both is not None and both.any() else np.nan
            problems.append(f"{name}: differs (largest difference {worst:.3g})")
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=["save", "check"])
    parser.add_argument("baseline", type=Path)
    parser.add_argument("configs", nargs="*", help="config names (file stems); default: all")
    args = parser.parse_args()
    if args.action == "save":
        for stem, path in run_all(args.baseline, args.configs).items():
            print(f"saved {stem}: {len(datasets(path))} datasets")
        return 0
    failed = 0
    with tempfile.TemporaryDirectory() as scratch:
        for stem, path in run_all(Path(scratch), args.configs).items():
            baseline = args.baseline / f"{stem}.h5"
            count = len(datasets(path))
            if not baseline.is_file():
                print(f"{stem:<22} new: no baseline to compare with ({count} datasets)")
                continue
            problems = differences(baseline, path)
            print(f"{stem:<22} {'identical' if not problems else 'DIFFERENT'} ({count} datasets)")
            for problem in problems:
                print(f"    {problem}")
            failed += bool(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
