"""Double-well errors against runs: one element, two elements cut at 0, and elements: auto.

    python scripts/figure_multi_element.py [docs/figures/multi_element_double_well.png]

Largest error over t in [0, 4] of the mean and of the std of x(t), x0 ~ U[-0.625, 0.375],
against the closed form (pcmb.references.double_well_moments); the model is the closed form
itself, so only the chaos error shows. Prints the table the figure is drawn from.
"""

from __future__ import annotations

import sys
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pcmb
from pcmb.references import double_well, double_well_moments

TIMES = np.linspace(0.0, 4.0, 401)
INPUTS = {"x0": pcmb.Uniform(-0.625, 0.375)}
MEAN, STD = double_well_moments(TIMES, -0.625, 0.375)


@pcmb.batched(outputs=("x",))
def well(params, times):
    return {"x": double_well(times, params["x0"])}


def errors(**method) -> tuple[int, float, float]:
    """Runs, mean error, std error of one study."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        result = pcmb.Study(well, INPUTS, TIMES, backend="inprocess", **method).run()
    mean = float(np.abs(result.mean("x") - MEAN).max())
    std = float(np.abs(result.std("x") - STD).max())
    return result.n_nodes, mean, std


def main(path: str) -> None:
    cases = {
        "one element (order N - 1)": [errors(order=n - 1, elements={}) for n in range(4, 129, 4)],
        "two elements at 0 (order N/2 - 1)": [
            errors(order=n // 2 - 1, elements={"x0": [0.0]}) for n in range(4, 129, 4)
        ],
        **{
            f"auto, order {order} (diagnostics.tolerance 1e-1..1e-6)": [
                errors(
                    order=order,
                    elements="auto",
                    max_elements=64,
                    diagnostics_tolerance=10.0**-k,
                    validation=0,
                )
                for k in range(1, 7)
            ]
            for order in (3, 5)
        },
    }
    figure, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for label, rows in cases.items():
        runs, mean, std = np.array(rows).T
        print(label)
        for row in rows:
            print(f"  {row[0]:4d} runs  mean error {row[1]:.2e}  std error {row[2]:.2e}")
        for ax, error in zip(axes, (mean, std), strict=True):
            ax.loglog(runs, np.maximum(error, 1e-16), "o-", label=label)
    for ax, what in zip(axes, ("mean", "std"), strict=True):
        ax.set_xlabel("model runs")
        ax.set_title(f"largest error of the {what} over t in [0, 4]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("error")
    axes[1].legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/figures/multi_element_double_well.png")
