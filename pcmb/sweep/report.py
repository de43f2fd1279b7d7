"""``pcmb report DIR/sweep.h5``: the sweep's chart and its table on one HTML page."""

from __future__ import annotations

import html
import os
from pathlib import Path

from pcmb.sweep.chart import draw_sweep
from pcmb.sweep.table import COLUMNS, SweepTable

__all__ = ["write_sweep_report"]


def _cell(value: object) -> str:
    return f"{value:.3g}" if isinstance(value, float) else html.escape(str(value))


def write_sweep_report(
    table: SweepTable, directory: str | os.PathLike[str], *, source: str = ""
) -> list[Path]:
    """Write ``sweep.png`` and ``index.html`` (chart, noise floors, every row) into
    ``directory``; the files written, ``index.html`` last.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing.
    """
    directory = Path(directory)
    chart = draw_sweep(table, directory / "sweep.png")
    floors = "".join(
        f"<li>{html.escape(name)}: mean {mean:.3g}, std {std:.3g}</li>"
        for name, (mean, std) in table.floors.items()
    )
    header = "".join(f"<th>{name}</th>" for name in COLUMNS)
    rows = "".join(
        "<tr>" + "".join(f"<td>{_cell(getattr(row, name))}</td>" for name in COLUMNS) + "</tr>"
        for row in table.rows
    )
    page = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>pcmb sweep {html.escape(source)}</title>
<style>body{{font-family:sans-serif;margin:2em}} td,th{{padding:2px 8px;text-align:right}}
table{{border-collapse:collapse}} tr:nth-child(even){{background:#f4f4f4}}</style></head>
<body><h1>Sweep: error against cost</h1>
<p>{html.escape(source)}: errors of the mean and standard deviation, as the largest difference
over time divided by the reference's largest standard deviation, against
{html.escape(table.reference)}.</p>
<img src="{chart.name}" alt="error against model runs and wall seconds" style="max-width:100%">
<p>Noise floor of the reference (errors below it are not measured):</p><ul>{floors}</ul>
<table><tr>{header}</tr>{rows}</table></body></html>
"""
    index = directory / "index.html"
    index.write_text(page, encoding="utf-8")
    return [chart, index]
