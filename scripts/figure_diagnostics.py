"""The diagnostics' estimate against the true error: failing and fixed cases side by side.

    python scripts/figure_diagnostics.py [docs/figures/diagnostics.png]

Three studies of the double well (x0 ~ U[-0.625, 0.375], whose response jumps with the sign
of x0) and one smooth response, each with its own 32 held-out runs:

- one element of order 7 (the config's order, 8 runs): flagged;
- two elements cut at x0 = 0, order 3 each (8 runs too): the remedy, not flagged;
- one element of order 3 (4 runs): flagged earlier;
- y = sin(k t), k ~ U[1, 2], order 4: resolved until its error reaches the tolerance.

For each, over time and in units of the output's largest std: the true errors of the mean
and the std (the larger; a 400-point Gauss rule of the exact response on each element), the
held-out estimate of it with ± its standard error, the surrogate's true pointwise RMS error,
the spectral decay (weighted over the elements), the tolerance and the flagged time. Prints
the flagged time against the time the true error crosses the tolerance.
"""

from __future__ import annotations

import sys
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pcmb
from pcmb.analysis.diagnostics import TOLERANCE, verdict
from pcmb.references import double_well

WELL_TIMES = np.linspace(0.0, 4.0, 201)
SINE_TIMES = np.linspace(0.0, 10.0, 201)
WELL_INPUT = {"x0": pcmb.Uniform(-0.625, 0.375)}


@pcmb.batched(outputs=("y",))
def well(params, times):
    return {"y": double_well(times, params["x0"])}


@pcmb.batched(outputs=("y",))
def sine(params, times):
    return {"y": np.sin(params["k"][:, None] * times)}


#: Panel title -> (model, inputs, times, study options, exact response (t, x (N,)) -> (N, T)).
CASES = {
    "double well, one element, order 7 (8 runs)": (
        well,
        WELL_INPUT,
        WELL_TIMES,
        {"order": 7},
        double_well,
    ),
    "two elements at x0 = 0, order 3 (8 runs)": (
        well,
        WELL_INPUT,
        WELL_TIMES,
        {"order": 3, "elements": {"x0": [0.0]}},
        double_well,
    ),
    "double well, one element, order 3 (4 runs)": (
        well,
        WELL_INPUT,
        WELL_TIMES,
        {"order": 3},
        double_well,
    ),
    "sin(k t), order 4 (5 runs)": (
        sine,
        {"k": pcmb.Uniform(1.0, 2.0)},
        SINE_TIMES,
        {"order": 4},
        lambda t, k: np.sin(k[:, None] * t),
    ),
}


def _truth(result: pcmb.StudyResult, exact, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T,) true errors, unscaled: of the mean and std (the larger), and of the surrogate
    (RMS); by a 400-point Gauss rule of the exact response on each element (one input,
    uniform)."""
    expansion = result.expansions["y"]
    partition = result.partition
    if partition is None:
        edges, shares = [expansion.distributions[0].physical.support()], [1.0]
    else:
        edges, shares = partition.bounds[:, 0], partition.probability
    nodes, rule = np.polynomial.legendre.leggauss(400)
    mean, second, squares = (np.zeros(times.size) for _ in range(3))
    for (low, high), share in zip(edges, shares, strict=True):
        params = low + (high - low) * (nodes + 1) / 2
        weights = rule / 2 * share  # a uniform input is uniform on each element
        values = exact(times, params)
        mean += weights @ values
        second += weights @ values**2
        squares += weights @ (expansion(params[:, None]) - values) ** 2
    std = np.sqrt(np.maximum(second - mean**2, 0.0))
    statistics = np.fmax(abs(result.mean("y") - mean), abs(result.std("y") - std))
    return statistics, np.sqrt(squares)


def main(path: str = "docs/figures/diagnostics.png") -> None:
    figure, axes = plt.subplots(2, 2, figsize=(11, 7.5), constrained_layout=True)
    for axis, (label, (model, inputs, times, options, exact)) in zip(
        axes.flat, CASES.items(), strict=True
    ):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pcmb.PcmbWarning)
            result = pcmb.Study(model, inputs, times, backend="inprocess", **options).run()
        found = result.diagnostics["y"]
        scale, checked, flagged = found.scale, found.holdout, found.failing_from
        statistics, pointwise = _truth(result, exact, times)
        axis.semilogy(times, statistics / scale, "k", label="true error of mean and std")
        axis.semilogy(times, checked.statistics, "C0", label=f"its estimate ({checked.count} runs)")
        axis.fill_between(
            times,
            np.maximum(checked.statistics - checked.spread, 1e-12),
            checked.statistics + checked.spread,
            color="C0",
            alpha=0.15,
            lw=0,
            label="± its standard error",
        )
        axis.semilogy(times, pointwise / scale, color="0.5", ls="--", label="surrogate's error")
        axis.semilogy(times, found.decay, "C2:", label="spectral decay")
        axis.axhline(TOLERANCE, color="C3", lw=0.8, label="tolerance")
        if np.isnan(flagged):
            axis.set_title(f"{label}: not flagged", fontsize=10)
        else:
            axis.axvspan(flagged, times[-1], color="C3", alpha=0.08)
            axis.set_title(f"{label}: flagged from t = {flagged:.3g}", fontsize=10)
        axis.set_ylim(1e-8, 3)
        axis.set_xlabel("time")
        axis.set_ylabel("error / largest std")
        true_crossing = verdict(times, statistics / scale)
        print(f"{label}: flagged {flagged:.4g}, true crossing {true_crossing:.4g}")
    axes[0, 0].legend(fontsize=7, loc="lower right")
    figure.savefig(path, dpi=100)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(*sys.argv[1:])
