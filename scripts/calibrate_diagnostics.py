"""Calibrate the chaos diagnostics on the paper's cases: the verdict against the true error.

    python scripts/calibrate_diagnostics.py                      # every case below
    python scripts/calibrate_diagnostics.py double_well --twin 1000

For each config this runs, through pcmb's public API:

1. the config's chaos study;
2. K held-out runs at random inputs (its Monte Carlo twin with K samples), from which
   :func:`pcmb.analysis.diagnostics.diagnose` gives ``failing_from``;
3. an independent Monte Carlo twin of M runs, on which the true error is measured: the RMS
   of surrogate minus model over the M runs at each time, over the output's largest std
   (the quantity the held-out check estimates, and a bound on the errors of the mean and
   the std). Its own sampling error is a few percent of its value for M = 400.

It prints, per output, ``failing_from`` against the first time the true error exceeds the
tolerance, their difference in percent of the horizon, and the outcome: ``ok`` (both never
or both times), ``FALSE ALARM`` (flagged, true error never above the tolerance) or
``MISSED``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from pcmb import Study
from pcmb.analysis.diagnostics import TOLERANCE, diagnose, verdict
from pcmb.config import load_config

ROOT = Path(__file__).resolve().parents[1]
CASES = (
    "quarter_car",
    "pendulum_ode",
    "pendulum_dae",
    "terrain_kl",
    "double_well",
    "lorenz_chaotic",
    "mr_damper",
)
#: Seeds of the held-out runs and of the truth twin (independent draws).
HELD_OUT_SEED, TWIN_SEED = 101, 202


def _outcome(flagged: float, true: float) -> str:
    if np.isnan(flagged):
        return "ok" if np.isnan(true) else "MISSED"
    return "FALSE ALARM" if np.isnan(true) else "ok"


def calibrate(case: str, held_out: int, twin: int, jobs: int, tolerance: float) -> list[str]:
    """Table rows for one config: output, failing_from, true crossing, outcome, warnings."""
    config = load_config(ROOT / "configs" / f"{case}.yaml")
    study = Study.from_config(config).replace(jobs=jobs, analysis=None)
    result = study.run(progress=False)
    checks = study.replace(method="montecarlo", samples=held_out, seed=HELD_OUT_SEED)
    truth = study.replace(method="montecarlo", samples=twin, seed=TWIN_SEED)
    checks, truth = checks.run(progress=False), truth.run(progress=False)
    times = result.times
    horizon = times[-1] - times[0]
    rows = []
    for name, expansion in result.expansions.items():
        found = diagnose(
            name,
            expansion,
            result.values[name][result.ok],
            times,
            (expansion.evaluate_germ(checks.germ), checks.values[name]),
            tolerance,
        )
        error = expansion.evaluate_germ(truth.germ) - truth.values[name]
        true = np.sqrt(np.nanmean(error**2, axis=0)) / found.scale if found.scale > 0 else 0 * times
        true_from = verdict(times, true, tolerance)
        shift = 100 * (found.failing_from - true_from) / horizon
        rows.append(
            f"{case:15s} {result.design.label:22s} {name:10s} {found.failing_from:8.4g} "
            f"{true_from:8.4g} {shift:+7.1f} {np.nanmax(true):8.3f} "
            f"{np.nanmax(found.holdout.error):8.3f} {np.nanmax(found.decay):7.3f}  "
            f"{_outcome(found.failing_from, true_from)}"
        )
        rows.extend(f"    {record}" for record in found.warnings)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("cases", nargs="*", default=CASES, help="config names (configs/*.yaml)")
    parser.add_argument("--held-out", type=int, default=16, help="K held-out runs")
    parser.add_argument("--twin", type=int, default=400, help="M runs of the truth twin")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--tolerance", type=float, default=TOLERANCE)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # the studies' own warnings are not the subject here
    print(
        f"{'config':15s} {'method':22s} {'output':10s} {'flagged':>8s} {'true':>8s} "
        f"{'Δ%hor':>7s} {'true max':>8s} {'held max':>8s} {'decay':>7s}  outcome"
    )
    for case in args.cases:
        for row in calibrate(case, args.held_out, args.twin, args.jobs, args.tolerance):
            print(row, flush=True)


if __name__ == "__main__":
    main()
