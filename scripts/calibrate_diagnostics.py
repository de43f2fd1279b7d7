"""Calibrate the chaos diagnostics on the paper's cases: the verdict against the true error.

    python scripts/calibrate_diagnostics.py                      # every case below
    python scripts/calibrate_diagnostics.py double_well --seeds 20

For each config this runs, through pcmb's public API:

1. the config's chaos study, with its own held-out check (``method.validation``, K = 32 by
   default): its ``failing_from`` is the "flagged" column;
2. a reference for the statistics: a much finer chaos study (order 40 for one input, order 12
   or 7 for the quarter cars) or, for the chaotic Lorenz system, 10,000 Monte Carlo runs;
   the *true* error is the larger of the errors of the mean and the std against it, over
   the output's largest std: what the verdict judges;
3. ``--seeds S`` more held-out checks with other seeds, to show how the verdict varies with
   the K draws (the min and max of their flags);
4. a Monte Carlo twin of 400 runs, on which the surrogate's own pointwise RMS error is
   measured (it bounds the errors of mean and std, and is often much larger).

It prints, per output, the flag against the first time the true error exceeds the tolerance,
their difference in percent of the horizon, the outcome (``ok``: both never or both times;
``FALSE ALARM``; ``MISSED``) and when the surrogate's pointwise error crosses it.
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
#: Config -> the reference study's changes (a much finer run).
REFERENCES = {
    "quarter_car": {"order": 12},
    "pendulum_ode": {"order": 40},
    "pendulum_dae": {"order": 40},
    "terrain_kl": {"order": 7},
    "double_well": {"elements": {"x0": [0.0]}, "order": 40},
    "lorenz_chaotic": {"method": "montecarlo", "samples": 10_000, "seed": 5},
    "mr_damper": {"order": 40},
}
#: Configs run at other orders than their own too: (order, ...).
ORDERS = {"pendulum_ode": (7,), "pendulum_dae": (7,), "double_well": (3,)}
#: Seeds of the extra held-out checks and of the pointwise twin.
SEEDS, TWIN_SEED = 101, 202


def _outcome(flagged: float, true: float) -> str:
    if np.isnan(flagged):
        return "ok" if np.isnan(true) else "MISSED"
    return "FALSE ALARM" if np.isnan(true) else "ok"


def calibrate(case: str, seeds: int, twin: int, jobs: int, tolerance: float) -> list[str]:
    """Table rows for one config: output, flagged, true crossing, outcome, spread, pointwise."""
    config = load_config(ROOT / "configs" / f"{case}.yaml")
    base = Study.from_config(config).replace(jobs=jobs, analysis=None)
    plain = base.replace(validation=0, nominal_run=False)
    reference = plain.replace(**REFERENCES[case]).run(progress=False)
    pointwise = plain.replace(method="montecarlo", samples=twin, seed=TWIN_SEED).run(progress=False)
    checks = [
        plain.replace(method="lhs", samples=base.method.validation, seed=SEEDS + k).run(
            progress=False
        )
        for k in range(seeds)
    ]
    rows = []
    for order in (None, *ORDERS.get(case, ())):
        study = base if order is None else base.replace(order=order)
        result = study.run(progress=False)
        times = result.times
        horizon = times[-1] - times[0]
        for name, found in result.diagnostics.items():
            expansion = result.expansions[name]
            scale = found.scale
            true = np.fmax(
                abs(expansion.mean() - reference.mean(name)),
                abs(expansion.std() - reference.std(name)),
            )
            true_from = verdict(times, true / scale, tolerance)
            error = expansion.evaluate_germ(pointwise.germ) - pointwise.values[name]
            surrogate_from = verdict(times, np.sqrt(np.nanmean(error**2, axis=0)) / scale)
            others = [
                diagnose(
                    name,
                    expansion,
                    result.values[name][result.ok],
                    times,
                    (expansion.evaluate_germ(c.germ), c.values[name]),
                    tolerance,
                ).failing_from
                for c in checks
            ]
            missed = sum(np.isnan(others)) if not np.isnan(true_from) else 0
            alarms = sum(~np.isnan(others)) if np.isnan(true_from) else 0
            shift = 100 * (found.failing_from - true_from) / horizon
            flagged = [f for f in others if not np.isnan(f)]
            span = f"{min(flagged):.3g}–{max(flagged):.3g}" if flagged else "never"
            label = result.design.label if order is None else f"order {order}"
            rows.append(
                f"{case:15s} {label:22s} {name:10s} {found.failing_from:8.4g} {true_from:8.4g} "
                f"{shift:+7.1f} {np.nanmax(true / scale):8.3f}  "
                f"{_outcome(found.failing_from, true_from):11s} {span:>12s} "
                f"{missed + alarms:3d}/{seeds:<3d} {surrogate_from:8.4g}"
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "cases", nargs="*", default=list(REFERENCES), help="config names (configs/*.yaml)"
    )
    parser.add_argument("--seeds", type=int, default=10, help="extra held-out checks")
    parser.add_argument("--twin", type=int, default=400, help="runs of the pointwise twin")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--tolerance", type=float, default=TOLERANCE)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # the studies' own warnings are not the subject here
    print(
        f"{'config':15s} {'method':22s} {'output':10s} {'flagged':>8s} {'true':>8s} "
        f"{'Δ%hor':>7s} {'true max':>8s}  {'outcome':11s} {'other seeds':>12s} "
        f"{'wrong':>7s} {'surrogate':>8s}"
    )
    for case in args.cases:
        for row in calibrate(case, args.seeds, args.twin, args.jobs, args.tolerance):
            print(row, flush=True)


if __name__ == "__main__":
    main()
