"""Regenerate the sweep charts and tables of ``docs/benchmarks.md`` with one command.

Usage::

    python scripts/benchmark_sweeps.py [CASE ...] [--folder results/benchmarks] [--no-peers]

For each case given (default: all of :data:`CASES`) it runs ``pcmb sweep configs/<case>.yaml``
into ``<folder>/<case>`` (``--resume`` continues an interrupted run), adds the peers with
``scripts/peers_sweep.py`` when chaospy and OpenTURNS are importable (the ``peers`` extra),
copies the chart to ``docs/figures/sweep_<case>.png`` and rewrites the part of
``docs/benchmarks.md`` between the ``sweeps`` markers: per case swept so far, the runs and
seconds of the cheapest setting of every method reaching std error 1e-2 and 1e-4, with the
machine and date.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib.util
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

from pcmb.sweep.table import read_sweep, summary

ROOT = Path(__file__).resolve().parent.parent
#: Case -> what its chart shows (each is ``configs/<case>.yaml`` and its ``sweep:`` section,
#: or the default sweep of its method).
CASES = {
    "quarter_car": "the main job: tensor, Smolyak, adaptive, LARS and Monte Carlo",
    "pendulum_ode": "one smooth input: order 1 to 12 against order 14",
    "pendulum_dae": "the same pendulum in DAE form",
    "terrain_kl": "four Karhunen–Loève germs of a random road",
    "double_well": "where chaos fails: one element stalls, two elements converge",
    "ishigami": "Ishigami (a = 7, b = 0.1), a scalar output",
    "borehole": "Borehole, eight inputs, a scalar output",
}
BEGIN, END = "<!-- sweeps:begin -->", "<!-- sweeps:end -->"


def _run(command: list[str]) -> None:
    print("$", " ".join(command), flush=True)
    subprocess.run(command, check=True, cwd=ROOT)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=list(CASES), help=f"of {', '.join(CASES)}")
    parser.add_argument("--folder", type=Path, default=ROOT / "results" / "benchmarks")
    parser.add_argument("--no-peers", action="store_true", help="pcmb's methods only")
    parser.add_argument("--resume", action="store_true", help="continue interrupted sweeps")
    parser.add_argument(
        "--docs-only", action="store_true", help="run nothing: rewrite the docs from <folder>"
    )
    args = parser.parse_args()
    if args.docs_only:
        args.cases = []
    unknown = sorted(set(args.cases) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}: choose from {', '.join(CASES)}")
    peers = not args.no_peers and all(
        importlib.util.find_spec(name) is not None for name in ("chaospy", "openturns")
    )
    if args.cases and not peers and not args.no_peers:
        print("peers skipped: chaospy and OpenTURNS come with pip install -e '.[peers]'")
    for case in args.cases:
        config = ROOT / "configs" / f"{case}.yaml"
        folder = args.folder / case
        resume = ["--resume"] if args.resume else []
        _run([sys.executable, "-m", "pcmb.cli", "sweep", str(config), "-o", str(folder), *resume])
        if peers:
            _run(
                [sys.executable, str(ROOT / "scripts" / "peers_sweep.py"), str(config), str(folder)]
            )
    blocks = []
    for case in CASES:  # every case swept so far, in order
        found = args.folder / case / "sweep.h5"
        if not found.is_file():
            continue
        figure = ROOT / "docs" / "figures" / f"sweep_{case}.png"
        shutil.copyfile(found.with_name("sweep.png"), figure)
        text = summary(read_sweep(found))
        blocks.append(
            f"### {case}: {CASES[case]}\n\n![{case}](figures/{figure.name})\n\n```\n{text}\n```\n"
        )
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    stamp = dt.date.today().isoformat()
    body = (
        f"{BEGIN}\n*Made by `python scripts/benchmark_sweeps.py` on {stamp} ({machine}); "
        f"seconds are wall time on that machine.*\n\n" + "\n".join(blocks) + END
    )
    page = ROOT / "docs" / "benchmarks.md"
    text = page.read_text(encoding="utf-8")
    if BEGIN in text:
        text = text[: text.index(BEGIN)] + body + text[text.index(END) + len(END) :]
    else:
        text = text.rstrip() + "\n\n## Sweeps: error against runs and seconds\n\n" + body + "\n"
    page.write_text(text, encoding="utf-8")
    print(f"wrote {page}")


if __name__ == "__main__":
    main()
