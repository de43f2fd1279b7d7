"""``sweep.png``: error against model runs and against wall seconds, log-log.

One row of two panels per output. Each method is one colour: the std error as a solid line
with markers, the mean error dotted; each line is labelled at its end, so no legend lookup is
needed. Replicates of a seeded method draw their median with a min-max bar. A sampled
reference's noise floor is a grey dashed line: errors below it are not measured.
"""

from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from pcmb.errors import MissingDependencyError
from pcmb.sweep.table import SweepTable

__all__ = ["draw_sweep", "plotting", "reference_name", "sweep_figure"]

#: Errors below this are drawn at it (exact results on a log axis).
FLOOR = 1e-16
_COLORS = (
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:red",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
    "tab:gray",
    "black",
    "darkgoldenrod",
    "navy",
    "lime",
)


def plotting() -> tuple[Any, Any]:
    """matplotlib's Figure class and Agg canvas.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing (``pcmb[plot]``).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise MissingDependencyError("matplotlib", "plot", "sweep charts") from None
    return Figure, FigureCanvasAgg


def _figure(outputs: int) -> tuple[Any, Any]:
    Figure, FigureCanvasAgg = plotting()
    figure = Figure(figsize=(12.0, 4.2 * outputs), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.subplots(outputs, 2, squeeze=False)


def _series(table: SweepTable, output: str, method: str, x: str) -> dict[str, np.ndarray]:
    """Per setting of a method, in the order of the table (rising cost): the cost (median
    over replicates) and the errors' median, minimum and maximum over replicates."""
    groups: dict[str, list[int]] = defaultdict(list)
    for index, row in enumerate(table.rows):
        if row.output == output and row.method == method:
            groups[row.setting].append(index)
    cost = np.array([np.median([getattr(table.rows[i], x) for i in g]) for g in groups.values()])
    found: dict[str, np.ndarray] = {"cost": cost}
    for kind in ("err_std", "err_mean"):
        values = [np.array([getattr(table.rows[i], kind) for i in g]) for g in groups.values()]
        found[kind] = np.array([np.median(v) for v in values])
        found[f"{kind}_low"] = np.array([np.min(v) for v in values])
        found[f"{kind}_high"] = np.array([np.max(v) for v in values])
    return found


def _panel(axes: Any, table: SweepTable, output: str, x: str, methods: list[str]) -> None:
    for color, method in zip(_COLORS * (len(methods) // len(_COLORS) + 1), methods, strict=False):
        series = _series(table, output, method, x)
        drawn = series["cost"] > 0  # an intrusive method makes no runs: seconds panel only
        series = {key: value[drawn] for key, value in series.items()}
        if not series["cost"].size:
            continue
        cost = series["cost"]
        std = np.maximum(series["err_std"], FLOOR)
        bars = np.vstack(
            [
                std - np.maximum(series["err_std_low"], FLOOR),
                np.maximum(series["err_std_high"], FLOOR) - std,
            ]
        )
        axes.errorbar(
            cost,
            std,
            yerr=bars if np.any(bars > 0) else None,
            color=color,
            marker="o",
            ms=4,
            lw=1.6,
            capsize=2,
        )
        axes.plot(cost, np.maximum(series["err_mean"], FLOOR), color=color, ls=":", lw=1.2)
        finite = np.isfinite(std)
        if finite.any():
            last = np.flatnonzero(finite)[-1]
            axes.annotate(
                method,
                (cost[last], std[last]),
                xytext=(4, 0),
                textcoords="offset points",
                color=color,
                fontsize=8,
                va="center",
            )
    floor = table.floors.get(output)
    if floor is not None and floor[1] > 0:
        axes.axhline(floor[1], color="0.5", ls="--", lw=1)
        axes.annotate(
            "reference noise (std)",
            (0.01, floor[1]),
            xycoords=("axes fraction", "data"),
            xytext=(0, 3),
            textcoords="offset points",
            color="0.4",
            fontsize=8,
        )
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.margins(x=0.12)  # room for the labels at the lines' ends
    for axis in (axes.xaxis, axes.yaxis):
        _readable_log_ticks(axis)
    axes.grid(True, which="major", alpha=0.3)
    axes.set_xlabel("model runs" if x == "runs" else "wall seconds of the study")
    axes.set_ylabel(f"{output}: error / largest reference std")


def _readable_log_ticks(axis: Any) -> None:
    """Labels on a log axis that never overlap, at any span: labelled ticks at 1, 2 and 5
    times the powers of ten (every digit within one decade) and no minor labels, where
    matplotlib's default labels the minor ticks of a narrow span into each other."""
    from matplotlib.ticker import LogFormatterSciNotation, LogLocator, NullFormatter

    low, high = sorted(axis.get_view_interval())
    decades = np.log10(high / low) if low > 0 else np.inf
    if decades >= 2:
        return  # labels at powers of ten only: matplotlib's default
    subs = (1.0, 2.0, 5.0) if decades >= 1 else tuple(range(1, 10))
    axis.set_major_locator(LogLocator(base=10.0, subs=subs))
    axis.set_major_formatter(LogFormatterSciNotation(labelOnlyBase=False))
    axis.set_minor_formatter(NullFormatter())


def reference_name(table: SweepTable) -> str:
    """What the errors are measured against, with the reference's file name only (no
    machine paths on a page)."""
    source, bracket, rest = table.reference.partition(" (")
    return f"{Path(source).name}{bracket}{rest}"


def sweep_figure(table: SweepTable) -> Any:
    """The chart of ``table`` as a matplotlib figure.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing (``pcmb[plot]``).
    """
    outputs = list(dict.fromkeys(row.output for row in table.rows))
    methods = list(dict.fromkeys(row.method for row in table.rows))
    figure, axes = _figure(max(len(outputs), 1))
    for row, output in enumerate(outputs):
        for column, x in enumerate(("runs", "seconds")):
            _panel(axes[row, column], table, output, x, methods)
        axes[row, 0].set_title(
            f"{output}: std error (solid) and mean error (dotted) against {reference_name(table)}",
            fontsize=9,
            loc="left",
        )
    return figure


def draw_sweep(table: SweepTable, path: str | os.PathLike[str]) -> Path:
    """Draw ``table`` into the PNG ``path``; returns it.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing (``pcmb[plot]``).
    """
    figure = sweep_figure(table)
    from pcmb.analysis.report import save_png

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_png(figure, path, dpi=100)
