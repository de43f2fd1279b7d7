"""Statistical linearization misses the nonlinear response that chaos catches (Part II Table 1).

    python scripts/figure_linearization.py [docs/figures/linearization_vs_chaos.png]

Two cubic cases, each run by Monte Carlo, collocation, stochastic Galerkin and statistical
linearization through the public API (the configs' own model, inputs and grid):

- the cubic oscillator under the two-mode Gaussian forcing (configs/oscillator_kl.yaml):
  E[x²] over time, and at t = 200 (stationary);
- the quarter car with its cubic spring (configs/quarter_car.yaml, uniform inputs): the std of
  the body displacement x1 over time.

Prints a markdown table: E[y²] at the last time and its error, and the largest std error over
time, of each method against the reference (Monte Carlo of 3000 runs with its standard error
for the oscillator, whose max-over-time std error is dominated by that noise; collocation of
order 8 for the quarter car), with model runs and seconds.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pcmb

ROOT = Path(__file__).resolve().parents[1]


def run(study: pcmb.Study) -> tuple[pcmb.StudyResult, float]:
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)  # the diagnostics' verdicts
        result = study.run(progress=False)
    return result, time.perf_counter() - start


def variants(study: pcmb.Study, galerkin: dict, collocation: dict, reference: dict) -> dict:
    """Label -> study: the reference, collocation, Galerkin and linearization."""
    return {
        "reference": study.replace(**reference),
        "collocation": study.replace(**collocation),
        "Galerkin": study.replace(method="galerkin", **galerkin),
        "linearization": study.replace(method="linearization", basis=None, validation=0),
    }


def main(out: str) -> None:
    oscillator = pcmb.Study.from_config(pcmb.load_config(ROOT / "configs/oscillator_kl.yaml"))
    quarter_car = pcmb.Study.from_config(pcmb.load_config(ROOT / "configs/quarter_car.yaml"))
    cases = {
        ("cubic oscillator", "x"): variants(
            oscillator.replace(outputs=["x"], analysis=None),
            galerkin={"order": 3, "basis": "total"},
            collocation={"order": 3},
            reference={"method": "montecarlo", "samples": 3000, "seed": 3, "basis": None},
        ),
        ("quarter car", "x1"): variants(
            quarter_car.replace(outputs=["x1"], analysis=None),
            galerkin={"order": 4, "basis": "tensor"},
            collocation={"order": 4},
            reference={"order": 8},
        ),
    }
    figure, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    rows = []
    styles = {
        "reference": ("black", "-", 2.5),
        "collocation": ("tab:blue", "--", 1.5),
        "Galerkin": ("tab:green", ":", 2.0),
        "linearization": ("tab:red", "-", 1.5),
    }
    for axis, ((case, output), studies) in zip(axes, cases.items(), strict=True):
        results = {label: run(study) for label, study in studies.items()}
        reference = results["reference"][0]
        scale = reference.std(output).max()
        for label, (result, seconds) in results.items():
            mean, std = result.mean(output), result.std(output)
            second = std**2 + mean**2
            shown = second if case == "cubic oscillator" else std
            color, line, width = styles[label]
            setting = result.design.label
            name = setting if setting.lower().startswith(label.lower()) else f"{label}, {setting}"
            axis.plot(result.times, shown, color=color, ls=line, lw=width, label=name)
            error = np.abs(std - reference.std(output)).max() / scale
            end = reference.mean(output)[-1] ** 2 + reference.std(output)[-1] ** 2
            rows.append(
                (
                    case,
                    label,
                    result.design.label,
                    result.n_nodes,
                    seconds,
                    second[-1],
                    second[-1] / end - 1,
                    error,
                    _standard_error(result, output),
                )
            )
        axis.set_xlabel("t")
        axis.set_ylabel(f"E[{output}²]" if case == "cubic oscillator" else f"std of {output} (m)")
        axis.set_title(case)
        axis.legend(fontsize=8)
    axes[0].set_xlim(100, 200)
    axes[0].set_ylim(0.5, 0.9)
    figure.tight_layout()
    figure.savefig(out, dpi=110)
    print(
        "| case | method | setting | runs | seconds | E[y²] at the end | its error | "
        "std error (max over t) |"
    )
    print("|---|---|---|---|---:|---:|---:|---:|")
    for case, label, setting, runs, seconds, second, relative, error, noise in rows:
        if label == "reference":
            shown = f"{second:.4g}" + (f" ± {noise:.2g}" if noise else "")
            print(f"| {case} | {label} | {setting} | {runs} | {seconds:.1f} | {shown} | | |")
            continue
        print(
            f"| {case} | {label} | {setting} | {runs} | {seconds:.1f} | {second:.4g} | "
            f"{relative:+.1%} | {error:.3g} |"
        )


def _standard_error(result: pcmb.StudyResult, output: str) -> float:
    """Standard error of E[y²] at the last time of a sampled result (0 for others)."""
    if result.design.samples is None or result.n_nodes < 2:
        return 0.0
    squares = result.values[output][result.ok, -1] ** 2
    return float(squares.std(ddof=1) / np.sqrt(squares.size))


if __name__ == "__main__":
    main(
        sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "docs/figures/linearization_vs_chaos.png")
    )
