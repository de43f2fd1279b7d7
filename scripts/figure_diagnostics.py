"""The diagnostics' estimate against the true error, on a failing and on a smooth case.

    python scripts/figure_diagnostics.py [docs/figures/diagnostics.png]

Left: the double well (x0 ~ U[-0.625, 0.375], order 7), whose response jumps with the sign
of x0. Right: the sin response y = sin(k t) with k ~ U[1, 2] at order 6, which chaos resolves.
For each, over time and in units of the output's largest std: the true RMS error of the
surrogate (a 400-point Gauss quadrature of the exact response), the held-out estimate (16
runs) with its 90 % upper bound, the spectral decay, the tolerance, and the flagged time.
Prints the flagged time and the time the true error crosses the tolerance.
"""

from __future__ import annotations

import sys
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pcmb
from pcmb.chaos.nodes import TensorGrid
from pcmb.references import double_well


@pcmb.batched(outputs=("y",))
def well(params, times):
    return {"y": double_well(times, params["x0"])}


@pcmb.batched(outputs=("y",))
def sine(params, times):
    return {"y": np.sin(params["k"][:, None] * times)}


CASES = {
    "double well, order 7": (
        well,
        {"x0": pcmb.Uniform(-0.625, 0.375)},
        np.linspace(0.0, 4.0, 201),
        7,
        lambda t, x: double_well(t, x),
    ),
    "sin(k t), order 6": (
        sine,
        {"k": pcmb.Uniform(1.0, 2.0)},
        np.linspace(0.0, 10.0, 201),
        6,
        lambda t, k: np.sin(k[:, None] * t),
    ),
}


def crossing(times: np.ndarray, error: np.ndarray, tolerance: float) -> float:
    above = np.flatnonzero(error > tolerance)
    return float(times[above[0]]) if above.size else float("nan")


def main(path: str = "docs/figures/diagnostics.png") -> None:
    figure, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for axis, (label, (model, inputs, times, order, exact)) in zip(
        axes, CASES.items(), strict=True
    ):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pcmb.PcmbWarning)
            result = pcmb.Study(model, inputs, times, order=order, backend="inprocess").run()
        found = result.diagnostics["y"]
        expansion = result.expansions["y"]
        fine = TensorGrid(expansion.distributions, (399,))
        difference = expansion.evaluate_germ(fine.nodes) - exact(times, fine.params[:, 0])
        truth = np.sqrt(fine.weights @ difference**2) / found.scale
        axis.semilogy(times, truth, "k", label="true error")
        axis.semilogy(times, found.holdout.error, "C0", label="held-out estimate (16 runs)")
        axis.semilogy(times, found.holdout.upper, "C0:", label="its 90 % upper bound")
        axis.semilogy(times, found.decay, "C2--", label="spectral decay")
        axis.axhline(found.tolerance, color="C3", lw=0.8, label="tolerance")
        if found.reliable:
            axis.set_title(f"{label}: not flagged")
        else:
            axis.axvspan(found.failing_from, times[-1], color="C3", alpha=0.08)
            axis.set_title(f"{label}: flagged from t = {found.failing_from:.3g}")
        axis.set_ylim(1e-8, 10)
        axis.set_xlabel("time")
        axis.set_ylabel("error / largest std")
        true_crossing = crossing(times, truth, found.tolerance)
        print(f"{label}: flagged {found.failing_from:.4g}, true crossing {true_crossing:.4g}")
    axes[0].legend(fontsize=8, loc="lower right")
    figure.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(*sys.argv[1:])
