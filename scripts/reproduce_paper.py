"""Reproduce the papers' cases: polynomial chaos, the matching Monte Carlo, and the report.

    python scripts/reproduce_paper.py all --quick         # every case, reduced Monte Carlo
    python scripts/reproduce_paper.py double_well         # one case, the papers' sample counts
    python scripts/reproduce_paper.py all --docs          # also refresh docs/figures/

For each case (a config in configs/) this runs, through pcmb's public API only:

1. the config's chaos study, and the other chaos orders the paper shows;
2. its Monte Carlo twin (same model, inputs, grid, executor and analysis) with the sample
   count of the papers (``--quick``: a tenth, at least 100);
3. ``pcmb report`` of the chaos result with the others overlaid;

and prints and stores (``summary.json``) the comparison numbers: largest differences of
mean and std, sampling noise, the first time the chaos leaves the Monte Carlo noise band,
wall times, and a few case-specific quantities the papers discuss. Results go to
``results/paper/<case>/`` (``--out`` to change).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import pcmb
from pcmb.analysis.comparison import compare, method_label
from pcmb.analysis.report import write_report
from pcmb.analysis.statistics import output_draws
from pcmb.references import double_well, pendulum_angle, statistical_linearization

ROOT = Path(__file__).resolve().parents[1]
#: --quick divides the Monte Carlo sample counts by this (keeping at least 100 runs).
QUICK_FACTOR = 10


def _mean_square_at_end(runs: dict[str, pcmb.StudyResult], config: Any) -> dict[str, float]:
    """E[x²] at the final time (Part II Table 1), and statistical linearization's value.

    Linearization replaces h x³ by k_eq x with k_eq = 3 h E[x²] (Gaussian closure); the
    stationary response to the two random-phase modes then has
    E[x²] = Σ_i A_i² / ((k_eq - m ω_i²)² + c² ω_i²), solved for E[x²] (Part II Eq. 17–24).
    """
    found = {label: float(r.mean("x")[-1] ** 2 + r.std("x")[-1] ** 2) for label, r in runs.items()}
    p = config.model.params
    omegas = (p["speed"] / p["L1"], p["speed"] / p["L2"])
    found["statistical linearization"] = statistical_linearization(
        p["m"], p["c"], p["h"], (p["A1"], p["A2"]), omegas
    )
    return found


def _uniform_average(
    function: Callable[[np.ndarray], np.ndarray], low: float, high: float, points: int = 2000
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std over a uniform input of function(θ) -> (points, T), by Gauss–Legendre
    quadrature fine enough to be exact at plotting accuracy (the reference)."""
    nodes, weights = np.polynomial.legendre.leggauss(points)
    values = function(0.5 * (low + high) + 0.5 * (high - low) * nodes)
    mean = 0.5 * weights @ values
    return mean, np.sqrt(0.5 * weights @ (values - mean) ** 2)


def _errors_against(
    runs: dict[str, pcmb.StudyResult], output: str, mean: np.ndarray, std: np.ndarray, at: Any
) -> dict[str, float]:
    """Largest |error| of each run's mean and std against the reference, at time indices."""
    found = {}
    for label, result in runs.items():
        found[f"{label}: max |mean - exact|"] = float(
            np.max(np.abs(result.mean(output)[at] - mean[at]))
        )
        found[f"{label}: max |std - exact|"] = float(
            np.max(np.abs(result.std(output)[at] - std[at]))
        )
    return found


def _double_well(runs: dict[str, pcmb.StudyResult], config: Any) -> dict[str, float]:
    """Against the exact solution x0 eᵗ / √(1 + x0² (e^{2t} - 1)), at t = 2 and 4: the mean and
    std, and the weight of the left well P(x < 0), exactly P(x0 < 0) = 0.625 at all times
    (0 is an equilibrium)."""
    times = next(iter(runs.values())).times
    spec = config.inputs["x0"]
    mean, std = _uniform_average(lambda x0: double_well(times, x0), spec.low, spec.high)
    at = [int(np.argmin(np.abs(times - t))) for t in (2.0, 4.0)]
    found: dict[str, float] = {"exact P(x < 0)": 0.625}
    for k, t in zip(at, (2.0, 4.0), strict=True):
        found[f"exact mean at t={t:g}"] = float(mean[k])
        found[f"exact std at t={t:g}"] = float(std[k])
    for label, result in runs.items():
        for k, t in zip(at, (2.0, 4.0), strict=True):
            found[f"{label}: mean at t={t:g}"] = float(result.mean("x")[k])
            found[f"{label}: std at t={t:g}"] = float(result.std("x")[k])
            _, draws = output_draws(result, "x", [t], result.analysis.settings)
            found[f"{label}: P(x < 0) at t={t:g}"] = float(np.mean(draws[:, 0] < 0.0))
    return found


def _pendulum(runs: dict[str, pcmb.StudyResult], config: Any) -> dict[str, float]:
    """θ against the exact solution θ = 2 asin(k sn(K(k) - √(g/L) t, k)), k = sin(θ0/2)
    (release from rest), over the whole time grid; for the DAE also the constraint."""
    params, spec = config.model.params, config.inputs["L"]
    if params.get("omega0", 0.0) != 0.0:
        raise ValueError("the exact pendulum solution used here needs a release from rest")
    times = next(iter(runs.values())).times

    def exact(length: np.ndarray) -> np.ndarray:
        return pendulum_angle(times, length, params["theta0"], params["g"])

    mean, std = _uniform_average(exact, spec.low, spec.high)
    found = _errors_against(runs, "theta", mean, std, slice(None))
    for label, result in runs.items():
        if "constraint" in result.values:
            found[f"{label}: max |x² + y² - L²|"] = float(
                np.nanmax(np.abs(result.values["constraint"]))
            )
    return found


@dataclass(frozen=True)
class Case:
    """A paper case: its config, Monte Carlo size, other chaos orders, doc figures."""

    config: str
    monte_carlo: int
    other_orders: tuple[int, ...] = ()
    extras: Callable[[dict[str, pcmb.StudyResult], Any], dict[str, float]] | None = None
    figures: tuple[str, ...] = field(default_factory=tuple)


CASES = {
    "quarter_car": Case(
        "quarter_car.yaml",
        2000,
        figures=("x1_time.png", "x1_compare.png", "x1_pdf.png", "x1_psd.png", "x1_psd_pdf.png"),
    ),
    "quarter_car_beta": Case("quarter_car_beta.yaml", 2000, figures=("x1_time.png",)),
    "mr_damper": Case("mr_damper.yaml", 2000, (7,), figures=("x1_time.png", "x1_pdf.png")),
    "terrain_kl": Case("terrain_kl.yaml", 2000, figures=("x1_compare.png", "x1_pdf.png")),
    "oscillator_kl": Case(
        "oscillator_kl.yaml",
        3000,
        extras=_mean_square_at_end,
        figures=("x_compare.png", "x_psd.png"),
    ),
    "double_well": Case(
        "double_well.yaml", 10_000, (3,), extras=_double_well, figures=("x_pdf.png", "x_time.png")
    ),
    "lorenz_stable": Case("lorenz_stable.yaml", 1000, figures=("z_compare.png",)),
    "lorenz_chaotic": Case(
        "lorenz_chaotic.yaml", 1000, figures=("z_compare.png", "x_compare.png", "x_pdf.png")
    ),
    "pendulum_ode": Case(
        "pendulum_ode.yaml",
        2000,
        (3, 7),
        extras=_pendulum,
        figures=("theta_time.png", "y_compare.png"),
    ),
    "pendulum_dae": Case(
        "pendulum_dae.yaml",
        2000,
        (3, 7),
        extras=_pendulum,
        figures=("x_compare.png",),
    ),
}


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _run(study: pcmb.Study, path: Path, provenance: dict[str, str]) -> pcmb.StudyResult:
    start = time.perf_counter()
    result = study.run(path, progress=False, provenance=provenance)
    _log(f"  {method_label(result)}: {time.perf_counter() - start:.1f} s -> {path}")
    return result


def run_case(name: str, case: Case, out: Path, *, quick: bool, jobs: int | None) -> dict:
    """Run one case; returns its summary (also written to ``summary.json``)."""
    config_path = ROOT / "configs" / case.config
    config = pcmb.load_config(config_path)
    study = pcmb.Study.from_config(config)
    if jobs is not None:
        study = study.replace(jobs=jobs)
    folder = out / name
    for stale in folder.glob("*.h5.journal"):
        shutil.rmtree(stale)  # a run killed earlier: start over rather than resume
    provenance = {"config": config.source_text or "", "config_sha256": config.sha256}
    samples = max(100, case.monte_carlo // QUICK_FACTOR) if quick else case.monte_carlo
    _log(f"{name}: {config_path.relative_to(ROOT)}")
    chaos = _run(study, folder / "chaos.h5", provenance)
    others = {
        "montecarlo": _run(
            study.replace(method="montecarlo", samples=samples, seed=1),
            folder / "montecarlo.h5",
            provenance,
        )
    }
    for order in case.other_orders:
        others[f"order{order}"] = _run(
            study.replace(order=order), folder / f"chaos_order{order}.h5", provenance
        )
    labels = [method_label(r) for r in others.values()]
    start = time.perf_counter()
    write_report(
        chaos, folder / "report", source=str(folder / "chaos.h5"), comparisons=list(others.values())
    )
    _log(f"  report: {time.perf_counter() - start:.1f} s -> {folder / 'report' / 'index.html'}")
    summary: dict[str, Any] = {
        "case": name,
        "config": case.config,
        "quick": quick,
        "runs": {
            method_label(r): {"seconds": r.seconds, "warnings": [str(w) for w in r.warnings]}
            for r in (chaos, *others.values())
        },
        "comparisons": {},
    }
    for label, other in zip(labels, others.values(), strict=True):
        found = compare(chaos, other)
        summary["comparisons"][label] = {
            output: {
                "mean_max": d.mean_max,
                "std_max": d.std_max,
                "mean_relative": d.mean_relative,
                "std_relative": d.std_relative,
                "mean_noise": d.mean_noise,
                "std_noise": d.std_noise,
                "worst_z": max(d.mean_z, d.std_z),
                "departure": d.departure,
                "verdict": d.verdict(),
            }
            for output, d in found.differences.items()
        }
        print(found.table(), end="\n\n")
    if case.extras is not None:
        runs = {method_label(chaos): chaos, **dict(zip(labels, others.values(), strict=True))}
        summary["extras"] = case.extras(runs, config)
        for key, value in summary["extras"].items():
            print(f"{name}: {key}: {value:.6g}")
    (folder / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=True) + "\n")
    return summary


def _copy_figures(name: str, case: Case, out: Path, docs: Path) -> None:
    docs.mkdir(parents=True, exist_ok=True)
    for figure in case.figures:
        shutil.copyfile(out / name / "report" / figure, docs / f"{name}_{figure}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case", choices=[*CASES, "all"], help="a paper case, or all of them")
    parser.add_argument("--quick", action="store_true", help="a tenth of the Monte Carlo runs")
    parser.add_argument("--jobs", type=int, help="worker processes (default: the config's)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "paper")
    parser.add_argument(
        "--docs", action="store_true", help="copy the figures docs/paper_cases.md shows"
    )
    args = parser.parse_args(argv)
    names = list(CASES) if args.case == "all" else [args.case]
    start = time.perf_counter()
    for name in names:
        run_case(name, CASES[name], args.out, quick=args.quick, jobs=args.jobs)
        if args.docs:
            _copy_figures(name, CASES[name], args.out, ROOT / "docs" / "figures")
    _log(f"done: {len(names)} case(s) in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
