"""``pcmb report DIR/sweep.h5``: the sweep's chart, what reaching an accuracy costs and its
table on one HTML page that fits a 1,400 px window, with no machine paths."""

from __future__ import annotations

import html
import os
import re
from pathlib import Path

from pcmb.sweep.chart import draw_sweep, reference_name
from pcmb.sweep.table import COLUMNS, TARGETS, SweepTable, cheapest, reach_text

__all__ = ["write_sweep_report"]

#: Numbers stay whole; names and headers wrap after their separators rather than push the
#: table past the window.
_STYLE = (
    "body{font-family:sans-serif;max-width:1240px;margin:auto;padding:0 12px}"
    "table{border-collapse:collapse;max-width:100%;margin-bottom:1em;font-size:14px}"
    "td,th{padding:2px 6px;text-align:right}td{white-space:nowrap}"
    "td.name{white-space:normal;overflow-wrap:break-word;text-align:left}"
    "tr:nth-child(even){background:#f4f4f4}img{max-width:100%}"
)
#: Columns of names, which may wrap.
_NAMES = frozenset({"method", "setting", "output", "file"})


def _cell(value: object) -> str:
    return f"{value:.3g}" if isinstance(value, float) else _breakable(str(value))


def _breakable(text: str) -> str:
    """Escaped text that may wrap after ``_ - : ,`` (a name never breaks on its own)."""
    return re.sub(r"([_\-:,])", r"\1<wbr>", html.escape(text, quote=False))


def _reach_table(table: SweepTable) -> str:
    """Per output and method, the runs and seconds of the cheapest setting reaching each
    accuracy of :data:`pcmb.sweep.table.TARGETS` (what ``pcmb inspect`` prints)."""
    header = "".join(f"<th>std error {target:g}</th>" for target in TARGETS)
    rows = []
    for output in dict.fromkeys(row.output for row in table.rows):
        reached = {target: cheapest(table, output, target) for target in TARGETS}
        for method in reached[TARGETS[0]]:
            cells = "".join(f"<td>{reach_text(reached[t][method])}</td>" for t in TARGETS)
            rows.append(
                f"<tr><td>{html.escape(output)}</td><td>{html.escape(method)}</td>{cells}</tr>"
            )
    return f"<table><tr><th>output</th><th>method</th>{header}</tr>{''.join(rows)}</table>"


def write_sweep_report(
    table: SweepTable, directory: str | os.PathLike[str], *, source: str = ""
) -> list[Path]:
    """Write ``sweep.png`` and ``index.html`` (chart, runs to each accuracy, noise floors,
    every row) into ``directory``; the files written, ``index.html`` last.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing.
    """
    directory = Path(directory)
    chart = draw_sweep(table, directory / "sweep.png")
    name = html.escape(Path(source).name)
    floors = "".join(
        f"<li>{html.escape(output)}: mean {mean:.3g}, std {std:.3g}</li>"
        for output, (mean, std) in table.floors.items()
    )
    header = "".join(f"<th>{_breakable(name)}</th>" for name in COLUMNS)
    kinds = {name: ' class="name"' if name in _NAMES else "" for name in COLUMNS}
    rows = "".join(
        "<tr>"
        + "".join(f"<td{kinds[name]}>{_cell(getattr(row, name))}</td>" for name in COLUMNS)
        + "</tr>"
        for row in table.rows
    )
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>pcmb sweep {name}</title>
<style>{_STYLE}</style></head>
<body><h1>Sweep: error against cost</h1>
<p>{name}: errors of the mean and standard deviation, as the largest difference over time
divided by the reference's largest standard deviation, against
{html.escape(reference_name(table))}.</p>
<img src="{chart.name}" alt="error against model runs and wall seconds">
<h2>What reaching an accuracy costs</h2>
<p>The cheapest setting of each method whose std error (median over replicates) reaches
each accuracy:</p>
{_reach_table(table)}
<p>Noise floor of the reference (errors below it are not measured):</p><ul>{floors}</ul>
<h2>Every setting</h2>
<table><tr>{header}</tr>{rows}</table></body></html>
"""
    index = directory / "index.html"
    index.write_text(page, encoding="utf-8")
    return [chart, index]
