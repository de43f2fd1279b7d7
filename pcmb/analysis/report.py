"""Figures and an index page for a result file: simulations with error bars, to look at.

:func:`write_report` writes, per output, ``<output>_time.png`` (mean ± 1σ, quantile band,
nominal run, comparisons), ``_pdf.png``, ``_sobol.png``, ``_psd.png``, ``_psd_pdf.png`` and
``_compare.png`` where they apply, and an ``index.html`` with the key numbers and warnings.
The only module that imports matplotlib (object-oriented API and the Agg canvas).

Statistics that are not finite (NaN or inf: an output beyond the floating-point range when
squared, values the model returned) are never plotted: curves have gaps there, a panel with
nothing finite to show is left out, and each case is named in the figure's title and in the
index page's "Not drawn" list.
"""

from __future__ import annotations

import html
import io
import os
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.comparison import LEVEL, Comparison, compare, method_label
from pcmb.analysis.statistics import (
    Analysis,
    AnalysisSettings,
    Density,
    analyse,
    draws_are_runs,
    output_draws,
    psd_draws,
    psd_draws_are_runs,
    spectrum,
)
from pcmb.chaos.density import kernel_density
from pcmb.errors import MissingDependencyError, UsageError
from pcmb.result import SURROGATE_CAUTIONS, StudyResult
from pcmb.wording import plural

__all__ = [
    "DPI",
    "PANELS_PER_ROW",
    "ROW_HEIGHT",
    "UNRELIABLE_ALPHA",
    "UNRELIABLE_COLOR",
    "WIDTH",
    "figure_pixels",
    "save_png",
    "write_comparison_figures",
    "write_report",
]

#: Figure width and height of one row of panels, in inches, and resolution.
WIDTH, ROW_HEIGHT, DPI = 10.0, 4.5, 100
#: Panels side by side before a figure wraps to another row.
PANELS_PER_ROW = 3
#: PSD plots show frequencies up to where mean + std falls below this fraction of its peak.
_PSD_FLOOR = 1e-6
#: Characters of a legend's line: three columns of them fit the figure's width.
_LEGEND_CHARACTERS = 44
#: Characters of a title line of a figure of two panels side by side.
_HALF_TITLE_CHARACTERS = 48
#: Histogram bins of sampled comparisons.
_BINS = 40
#: The diagnostics' record that explains a shaded time range.
_FLAG = "chaos-unreliable"
#: ... and where its held-out check cannot tell (shown in the same section).
_UNDECIDED = "chaos-undecided"
#: Shading of the time range where the diagnostics call the chaos unreliable.
UNRELIABLE_COLOR, UNRELIABLE_ALPHA = "tab:red", 0.12
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def figure_pixels(panels: int) -> tuple[int, int]:
    """(width, height) in pixels of a figure with ``panels`` panels."""
    rows = -(-max(panels, 1) // PANELS_PER_ROW)
    return int(WIDTH * DPI), int(ROW_HEIGHT * rows * DPI)


def save_png(figure: Any, path: Path, dpi: int = DPI) -> Path:
    """Save a figure as a 256-colour PNG: a third of the size of Agg's RGBA output, and the
    difference is invisible on line plots."""
    from PIL import Image  # matplotlib's own dependency

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    image = Image.open(buffer).convert("RGB")
    image.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)
    return path


def _matplotlib() -> tuple[Any, Any]:
    """The Figure class and the Agg canvas, imported on first use.

    Raises
    ------
    MissingDependencyError
        If matplotlib is not installed (it comes with ``pcmb[plot]``).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise MissingDependencyError("matplotlib", "plot", "figures") from None
    return Figure, FigureCanvasAgg


#: Seconds per unit of the time units the report can rescale.
_SECONDS = {
    "s": 1.0,
    "sec": 1.0,
    "second": 1.0,
    "seconds": 1.0,
    "ms": 1e-3,
    "us": 1e-6,
    "µs": 1e-6,
    "min": 60.0,
    "h": 3600.0,
}
#: (longest horizon in seconds, seconds per unit, unit) the report shows times in: the first
#: whose horizon is above the run's, e.g. a 0.5 ms run in ms and a 3 h run in min.
_TIME_SCALES = (
    (1e-4, 1e-6, "µs"),
    (0.1, 1e-3, "ms"),
    (600.0, 1.0, "s"),
    (36_000.0, 60.0, "min"),
    (np.inf, 3600.0, "h"),
)


@dataclass(frozen=True)
class _Labels:
    """Texts with units where the analysis settings know them, and times in a readable unit
    (a 0.5 ms horizon in ms, not as 0.0001 s steps)."""

    settings: AnalysisSettings
    horizon: float = 0.0

    @property
    def _time_scale(self) -> tuple[float, str]:
        """(divisor, unit) of the times shown: a time t is shown as t / divisor unit."""
        unit = self.settings.time_unit
        if unit not in _SECONDS:
            return 1.0, unit
        seconds = self.horizon * _SECONDS[unit]
        _, per, shown = next(scale for scale in _TIME_SCALES if seconds < scale[0])
        return per / _SECONDS[unit], shown

    def times(self, values: ArrayLike) -> NDArray[np.float64]:
        """Times in the unit shown."""
        return np.asarray(values, dtype=float) / self._time_scale[0]

    def at_time(self, value: float) -> str:
        """``"0.5 ms"``: a time in the unit shown."""
        divisor, unit = self._time_scale
        return f"{value / divisor:.4g} {unit}".rstrip()

    def time(self) -> str:
        unit = self._time_scale[1]
        return f"time [{unit}]" if unit else "time"

    def frequency_unit(self) -> str:
        unit = self.settings.time_unit
        if _SECONDS.get(unit) == 1.0:
            return "Hz"
        return f"1/{unit}" if unit else "cycles per unit time"

    def frequency(self) -> str:
        return f"frequency [{self.frequency_unit()}]"

    def output(self, name: str) -> str:
        unit = self.settings.units.get(name, "")
        return f"{name} [{unit}]" if unit else name

    def value(self, name: str, value: float, digits: int = 4) -> str:
        """``"4.965 V"``: a value of an output with its unit."""
        return f"{value:.{digits}g} {self.settings.units.get(name, '')}".rstrip()

    def psd_unit(self, name: str) -> str:
        unit = self.settings.units.get(name, "")
        per = "Hz" if self.frequency_unit() == "Hz" else "frequency unit"
        return f"{unit}²/{per}" if unit else f"unit²/{per}"

    def psd(self, name: str) -> str:
        return f"PSD of {name} [{self.psd_unit(name)}]"

    def grid(self, result: StudyResult, name: str) -> NDArray[np.float64]:
        """The points output ``name`` is drawn on: its times in the unit shown, or its own
        axis."""
        grid = result.grid(name)
        return self.times(grid) if result.on_time(name) else grid

    def where(self, result: StudyResult, name: str, value: float) -> str:
        """``"t = 0.5 ms"``, ``"frequency = 10 Hz"``: a point of an output's axis."""
        axis = result.axis(name)
        if result.on_time(name):
            return f"{axis.name} = {self.at_time(value)}"
        return f"{axis.name} = {value:.4g} {axis.unit}".rstrip()


class _Canvas:
    """Creates figures of the report's sizes and saves them in ``directory`` (made if needed,
    once matplotlib is found); collects notes on what could not be drawn."""

    def __init__(self, directory: str | os.PathLike[str]):
        self.directory = Path(directory)
        self.figure_class, self.canvas_class = _matplotlib()
        self.directory.mkdir(parents=True, exist_ok=True)
        self.written: list[Path] = []
        self.notes: list[str] = []

    def note(self, text: str) -> None:
        """Record what a figure leaves out (shown on the index page)."""
        self.notes.append(text)

    def figure(self, panels: int) -> tuple[Any, list[Any]]:
        width, height = figure_pixels(panels)
        figure = self.figure_class(figsize=(width / DPI, height / DPI), dpi=DPI)
        self.canvas_class(figure)
        figure.set_layout_engine("constrained")
        rows = -(-panels // PANELS_PER_ROW)
        columns = min(panels, PANELS_PER_ROW)
        axes = figure.subplots(rows, columns, squeeze=False).ravel()
        for extra in axes[panels:]:
            extra.set_visible(False)
        return figure, list(axes[:panels])

    def save(self, figure: Any, name: str) -> Path:
        """Save as a 256-colour PNG (:func:`save_png`)."""
        path = save_png(figure, self.directory / name)
        self.written.append(path)
        return path


@dataclass(frozen=True)
class _Other:
    """A comparison result with its label and color."""

    label: str
    result: StudyResult
    color: str


def _gaps(values: ArrayLike) -> NDArray[np.float64]:
    """The values with NaN where they are not finite: a line has a gap there."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values), values, np.nan)


def _not_finite(canvas: _Canvas, what: str, *arrays: ArrayLike) -> str:
    """A title note (and an index note) when some of the arrays' values are not finite."""
    bad = np.zeros(np.shape(arrays[0]), dtype=bool)
    for array in arrays:
        bad |= ~np.isfinite(np.asarray(array, dtype=float))
    if not bad.any():
        return ""
    canvas.note(f"{what}: not finite (NaN or inf) at {int(bad.sum())} of {bad.size} points")
    return f"\n(not finite at {int(bad.sum())} of {bad.size} points: not drawn there)"


def _extent(values: ArrayLike) -> tuple[float, float] | None:
    """(min, max) of the finite values, ``None`` without any."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    return (float(finite.min()), float(finite.max())) if finite.size else None


def _horizon(result: StudyResult) -> float:
    """The largest |t| of a result's times (what its time axes must show)."""
    return float(np.max(np.abs(result.times), initial=0.0))


def _legend(figure: Any, panels: Sequence[Any]) -> None:
    """One legend for the figure, below the panels: it never hides a curve, and long labels
    are wrapped so that it fits the figure's width.

    Every panel draws the same kinds of curves, so the labels are collected once.
    """
    entries: dict[str, Any] = {}
    for axes in panels:
        for handle, label in zip(*axes.get_legend_handles_labels(), strict=True):
            entries.setdefault(textwrap.fill(label, _LEGEND_CHARACTERS), handle)
    if entries:
        figure.legend(
            list(entries.values()),
            list(entries),
            loc="outside lower center",
            ncols=min(len(entries), 3),
            fontsize="small",
            frameon=False,
        )


def _unreliable(result: StudyResult, name: str) -> float | None:
    """The time from which the diagnostics call an output's chaos unreliable (``None``:
    reliable at every time, or not checked)."""
    found = result.diagnostics.get(name)
    return None if found is None or found.reliable else float(found.failing_from)


def _shade_unreliable(
    panels: Sequence[Any], result: StudyResult, name: str, labels: _Labels
) -> str:
    """Shade, on every panel of output ``name`` over its points, where the diagnostics call
    its chaos unreliable; the title line that says so, or ``""``."""
    unreliable = _unreliable(result, name)
    if unreliable is None:
        return ""
    grid = labels.grid(result, name)
    for axes in panels:
        axes.axvspan(
            grid[np.searchsorted(result.grid(name), unreliable)],
            grid[-1],
            color=UNRELIABLE_COLOR,
            alpha=UNRELIABLE_ALPHA,
            lw=0,
            label="chaos unreliable (see the index page)",
        )
    return f"\n(shaded: chaos unreliable from {labels.where(result, name, unreliable)})"


def _surrogate_note(result: StudyResult, name: str, labels: _Labels) -> str:
    """A title line naming where a ``surrogate-inaccurate`` record cautions the quantile bands
    and Sobol' indices of output ``name`` (drawn from the surrogate), or ``""``."""
    spans = [
        "everywhere"
        if w.time_range is None
        else f"from {labels.where(result, name, w.time_range[0])} to "
        f"{labels.where(result, name, w.time_range[1])}"
        for w in result.warnings_for(name)
        if w.code == "surrogate-inaccurate"
    ]
    return (
        f"\ncaution: surrogate-inaccurate {', '.join(spans)} (see the index page)" if spans else ""
    )


def _points_axis(axes: Any, result: StudyResult, name: str, labels: _Labels) -> None:
    """The x axis of an output's points: time, or its own axis (log where it is a frequency
    and positive)."""
    axis, grid = result.axis(name), labels.grid(result, name)
    if result.on_time(name):
        axes.set_xlabel(labels.time())
    else:
        axes.set_xlabel(f"{axis.name} [{axis.unit}]" if axis.unit else axis.name)
        if axis.is_frequency and grid[0] > 0:
            axes.set_xscale("log")
    axes.set_xlim(grid[0], grid[-1])


def _time_figure(
    canvas: _Canvas,
    result: StudyResult,
    name: str,
    analysis: Analysis,
    others: Sequence[_Other],
    labels: _Labels,
) -> Path | None:
    if result.axis(name) is None:
        return None  # a scalar: its PDF figure shows mean ± std
    figure, (axes,) = canvas.figure(1)
    times, mean, std = labels.grid(result, name), result.mean(name), result.std(name)
    note = _not_finite(canvas, f"{name}: mean or std", mean, std)
    with np.errstate(over="ignore", invalid="ignore"):
        low, high = _gaps(mean - std), _gaps(mean + std)
    axes.fill_between(times, low, high, color=_COLORS[0], alpha=0.3, lw=0, label="mean ± 1σ")
    axes.plot(times, _gaps(mean), color=_COLORS[0], lw=1.8, label=f"mean: {method_label(result)}")
    levels = analysis.settings.quantiles
    bands = analysis.outputs[name].quantiles
    names = f"quantiles {', '.join(f'{q:.0%}' for q in levels)}"
    for i, band in enumerate(bands):
        axes.plot(
            times, _gaps(band), color=_COLORS[0], lw=0.9, ls=":", label=names if i == 0 else None
        )
    if name in result.nominal:
        axes.plot(
            times, _gaps(result.nominal[name]), color="black", lw=1.2, ls="--", label="nominal run"
        )
    for other in others:
        o_mean, o_std = other.result.mean(name), other.result.std(name)
        with np.errstate(over="ignore", invalid="ignore"):
            o_low, o_high = _gaps(o_mean - o_std), _gaps(o_mean + o_std)
        axes.plot(times, _gaps(o_mean), color=other.color, lw=1.2, label=f"mean: {other.label}")
        axes.plot(times, o_high, color=other.color, lw=1.0, ls="-.", label=f"± 1σ: {other.label}")
        axes.plot(times, o_low, color=other.color, lw=1.0, ls="-.")
    note += _shade_unreliable([axes], result, name, labels)
    _points_axis(axes, result, name, labels)
    axes.set_ylabel(labels.output(name))
    axes.set_title(f"{name}: mean with error bars{note}{_surrogate_note(result, name, labels)}")
    _legend(figure, [axes])
    suffix = "time" if result.on_time(name) else result.axis(name).name
    return canvas.save(figure, f"{name}_{suffix}.png")


def _plot_density(axes: Any, density: Density, row: int, color: str, label: str) -> bool:
    """Draw one density (a line, or a vertical line for a point mass); False when it has
    nothing finite to draw."""
    value, table = density.value[row], density.density[row]
    if np.all(np.isnan(table)):
        if not np.isfinite(value[0]):
            return False
        axes.axvline(value[0], color=color, lw=2.0, label=f"{label} (point mass)")
    else:
        axes.plot(_gaps(value), _gaps(table), color=color, lw=1.8, label=label)
    return True


def _no_density(axes: Any, canvas: _Canvas, what: str) -> None:
    """Say on the panel and on the index page that a density had nothing finite to draw."""
    axes.text(0.5, 0.5, "no finite values", ha="center", va="center", transform=axes.transAxes)
    canvas.note(f"{what}: no finite values to draw")


def _bandwidth_note(density: Density, row: int) -> str:
    """The KDE's bandwidth on a line of its own (a panel is a third of the figure wide)."""
    h = density.bandwidth[row]
    return "" if np.isnan(h) else f"\n(KDE h = {h:.2g})"


def _plot_other_draws(
    axes: Any, draws: NDArray, is_runs: bool, other: _Other, *, nonnegative: bool, bandwidth: float
) -> None:
    """A sampled comparison as a histogram; a chaos comparison as its KDE with the same
    bandwidth as the result's, so that the two curves are smoothed alike."""
    draws = draws[np.isfinite(draws)]
    if draws.size == 0:
        return
    if is_runs:
        axes.hist(
            draws,
            bins=_BINS,
            density=True,
            histtype="step",
            color=other.color,
            lw=1.3,
            label=other.label,
        )
        return
    h = None if not np.isfinite(bandwidth) else bandwidth
    with np.errstate(over="ignore", invalid="ignore"):
        value, density, _ = kernel_density(draws, nonnegative=nonnegative, bandwidth=h)
    if np.all(np.isnan(density)):
        if np.isfinite(value[0]):
            axes.axvline(value[0], color=other.color, lw=1.3, ls="--", label=other.label)
        return
    axes.plot(value, density, color=other.color, lw=1.3, ls="--", label=other.label)


def _caution_note(result: StudyResult, name: str, at: float) -> str:
    """A title line naming the surrogate cautions (:data:`SURROGATE_CAUTIONS`) and the verdict's
    failure (``chaos-unreliable``: the surrogate fails there too) that cover the point ``at`` of
    output ``name``, or ``""``."""
    codes = dict.fromkeys(
        w.code
        for w in result.warnings_for(name)
        if (w.code in SURROGATE_CAUTIONS or w.code == _FLAG)
        and (w.time_range is None or w.time_range[0] <= at <= w.time_range[1])
    )
    return f"\ncaution: {', '.join(codes)} (see the index page)" if codes else ""


def _pdf_figure(
    canvas: _Canvas,
    result: StudyResult,
    name: str,
    analysis: Analysis,
    others: Sequence[_Other],
    labels: _Labels,
) -> Path:
    pdf = analysis.outputs[name].pdf
    figure, panels = canvas.figure(pdf.at.size)
    source = "surrogate" if not draws_are_runs(result, name) else "runs"
    axis, grid = result.axis(name), result.grid(name)
    for row, (axes, at) in enumerate(zip(panels, pdf.at, strict=True)):
        where = "" if axis is None else f" at {labels.where(result, name, at)}"
        if not _plot_density(axes, pdf, row, _COLORS[0], f"{method_label(result)}, {source}"):
            _no_density(axes, canvas, f"{name}: PDF{where}")
        for other in others:
            _, draws = output_draws(other.result, name, [at], analysis.settings)
            is_runs = draws_are_runs(other.result, name)
            h = pdf.bandwidth[row]
            _plot_other_draws(axes, draws[:, 0], is_runs, other, nonnegative=False, bandwidth=h)
        k = int(np.argmin(np.abs(grid - at)))
        if name in result.nominal and np.isfinite(result.nominal[name][k]):
            axes.axvline(result.nominal[name][k], color="black", ls="--", lw=1.0, label="nominal")
        if axis is None:  # a scalar: its mean ± std on its PDF
            mean, std = float(result.mean(name)[k]), float(result.std(name)[k])
            axes.axvline(mean, color=_COLORS[0], lw=1.2, label=f"mean {labels.value(name, mean)}")
            for edge in (mean - std, mean + std):
                label = f"± 1σ ({labels.value(name, std, 3)})" if edge < mean else None
                axes.axvline(edge, color=_COLORS[0], lw=1.0, ls=":", label=label)
        axes.set_xlabel(labels.output(name))
        axes.set_ylabel("probability density")
        axes.set_title(f"{name}{where}{_bandwidth_note(pdf, row)}{_caution_note(result, name, at)}")
    _legend(figure, panels)
    return canvas.save(figure, f"{name}_pdf.png")


def _sobol_figure(canvas: _Canvas, result: StudyResult, name: str, labels: _Labels) -> Path | None:
    if name not in result.expansions or len(result.input_names) < 2:
        return None  # with one input both indices are 1 wherever the output varies
    first, total = result.sobol_first(name), result.sobol_total(name)
    colors = [_COLORS[i % len(_COLORS)] for i in range(len(result.input_names))]
    if result.axis(name) is None:  # a scalar: bars per input
        figure, (axes,) = canvas.figure(1)
        at = np.arange(len(result.input_names))
        axes.bar(at - 0.2, first[:, 0], 0.4, color=colors, alpha=0.75, label="first order")
        axes.bar(at + 0.2, total[:, 0], 0.4, color=colors, hatch="//", label="total")
        axes.set_xticks(at, result.input_names)
        axes.set_ylabel("share of the variance")
        axes.set_ylim(0.0, 1.05)
        axes.set_title(f"{name}: Sobol' indices (plain: first order, hatched: total)")
        return canvas.save(figure, f"{name}_sobol.png")
    figure, (first_axes, total_axes) = canvas.figure(2)
    times = labels.grid(result, name)
    # Where the output does not vary the indices are NaN: nothing is stacked there.
    first_axes.stackplot(
        times, np.nan_to_num(first), labels=result.input_names, colors=colors, alpha=0.75
    )
    for k, input_name in enumerate(result.input_names):
        total_axes.plot(times, total[k], color=colors[k], lw=1.6, label=input_name)
    note = _shade_unreliable([first_axes, total_axes], result, name, labels)
    note += _surrogate_note(result, name, labels)
    note = "\n".join(textwrap.fill(line, _HALF_TITLE_CHARACTERS) for line in note.split("\n"))
    first_axes.set_title(f"{name}: first-order Sobol' indices (stacked){note}")
    total_axes.set_title(f"{name}: total Sobol' indices{note}")
    for axes in (first_axes, total_axes):
        _points_axis(axes, result, name, labels)
        axes.set_ylabel("share of the variance")
        axes.set_ylim(0.0, 1.05)
    _legend(figure, [first_axes, total_axes])
    return canvas.save(figure, f"{name}_sobol.png")


def _psd_limits(mean: NDArray, std: NDArray, frequency: NDArray, keep: Sequence[float]) -> tuple:
    """x limit where mean + std stays above _PSD_FLOOR of its peak, and y limits (from the
    finite values only)."""
    with np.errstate(over="ignore", invalid="ignore"):
        upper = np.where(np.isfinite(mean + std), mean + std, mean)
    upper = np.where(np.isfinite(upper), upper, np.nan)
    peak = float(np.nanmax(upper))
    above = np.flatnonzero(upper > _PSD_FLOOR * peak)
    keep = [f for f in keep if np.isfinite(f)]
    f_max = max([frequency[above[-1]] if above.size else frequency[-1], *keep])
    f_max = min(1.1 * f_max, frequency[-1]) if f_max > 0 else frequency[-1]
    return f_max, (_PSD_FLOOR * peak * 0.1, min(peak * 3.0, np.finfo(float).max))


def _psd_figure(
    canvas: _Canvas,
    result: StudyResult,
    name: str,
    analysis: Analysis,
    others: Sequence[_Other],
    labels: _Labels,
) -> Path | None:
    spec = analysis.outputs[name].spectrum
    if spec is None:
        return None
    finite = np.isfinite(spec.mean)
    if not np.any(spec.mean[finite] > 0):
        if not finite.all():
            canvas.note(f"{name}: PSD not drawn: its mean is not finite (NaN or inf)")
        return None
    figure, (axes,) = canvas.figure(1)
    note = _not_finite(canvas, f"{name}: PSD mean or std", spec.mean, spec.std)
    f_max, (low, high) = _psd_limits(spec.mean, spec.std, spec.frequency, spec.pdf.at)
    # A log axis cannot show mean - σ <= 0: the band is drawn from the floor.
    with np.errstate(over="ignore", invalid="ignore"):
        lower = _gaps(np.clip(spec.mean - spec.std, low, None))
        upper = _gaps(spec.mean + spec.std)
    axes.fill_between(
        spec.frequency,
        lower,
        upper,
        color=_COLORS[0],
        alpha=0.3,
        lw=0,
        label="mean ± 1σ (lower edge clipped at the axis)",
    )
    axes.plot(spec.frequency, _gaps(spec.mean), color=_COLORS[0], lw=1.6, label="mean PSD")
    if spec.nominal is not None:
        axes.plot(
            spec.frequency,
            _gaps(spec.nominal),
            color="black",
            ls="--",
            lw=1.1,
            label="nominal run PSD",
        )
    for other in others:
        theirs = spectrum(other.result, name, analysis.settings, frequencies=spec.pdf.at)
        axes.plot(
            theirs.frequency,
            _gaps(theirs.mean),
            color=other.color,
            lw=1.2,
            label=f"mean: {other.label}",
        )
        with np.errstate(over="ignore", invalid="ignore"):
            their_upper = _gaps(theirs.mean + theirs.std)
        axes.plot(
            theirs.frequency,
            their_upper,
            color=other.color,
            lw=0.9,
            ls="-.",
            label=f"mean + 1σ: {other.label}",
        )
    for f in spec.pdf.at[np.isfinite(spec.pdf.at)]:
        axes.axvline(f, color="grey", lw=0.8, ls=":")
    axes.set_yscale("log")
    axes.set_xlim(0.0, f_max)
    axes.set_ylim(low, high)
    axes.set_xlabel(labels.frequency())
    axes.set_ylabel(labels.psd(name))
    axes.set_title(
        f"{name}: power spectral density ({spec.window} window, one-sided); "
        f"dotted: frequencies of the PSD PDFs{note}"
    )
    _legend(figure, [axes])
    return canvas.save(figure, f"{name}_psd.png")


def _psd_pdf_figure(
    canvas: _Canvas,
    result: StudyResult,
    name: str,
    analysis: Analysis,
    others: Sequence[_Other],
    labels: _Labels,
) -> Path | None:
    spec = analysis.outputs[name].spectrum
    if spec is None or spec.pdf is None:
        return None
    figure, panels = canvas.figure(spec.pdf.at.size)
    source = "runs" if psd_draws_are_runs(result, name) else "surrogate"
    unit, per = labels.psd_unit(name), labels.frequency_unit()
    per = per if per == "Hz" else ""
    for row, (axes, at) in enumerate(zip(panels, spec.pdf.at, strict=True)):
        if not _plot_density(axes, spec.pdf, row, _COLORS[0], f"{method_label(result)}, {source}"):
            _no_density(axes, canvas, f"{name}: PDF of the PSD at {at:.4g} {per}".rstrip())
        for other in others:
            _, draws = psd_draws(other.result, name, [at], analysis.settings)
            is_runs = psd_draws_are_runs(other.result, name)
            h = spec.pdf.bandwidth[row]
            _plot_other_draws(axes, draws[:, 0], is_runs, other, nonnegative=True, bandwidth=h)
        if spec.nominal is not None:
            k = int(np.argmin(np.abs(spec.frequency - at)))
            if np.isfinite(spec.nominal[k]):
                axes.axvline(spec.nominal[k], color="black", ls="--", lw=1.0, label="nominal")
        axes.set_xlabel(f"PSD of {name} [{unit}]")
        axes.set_ylabel("probability density")
        axes.set_title(f"PDF of the PSD at {at:.4g} {per}{_bandwidth_note(spec.pdf, row)}")
        axes.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4))
        axes.xaxis.set_major_formatter("{x:.3g}")  # an offset text would sit on the label
    _legend(figure, panels)
    return canvas.save(figure, f"{name}_psd_pdf.png")


def _compare_figure(
    canvas: _Canvas,
    result: StudyResult,
    name: str,
    others: Sequence[_Other],
    comparisons: Sequence[Comparison],
    labels: _Labels,
) -> Path | None:
    if not others or result.axis(name) is None:
        return None  # a scalar's differences are in the index page's table
    figure, (mean_axes, std_axes) = canvas.figure(2)
    times = labels.grid(result, name)
    own = method_label(result)
    mean_axes.plot(times, _gaps(result.mean(name)), color=_COLORS[0], lw=1.8, label=own)
    std_axes.plot(times, _gaps(result.std(name)), color=_COLORS[0], lw=1.8, label=own)
    for other in others:
        mean_axes.plot(
            times, _gaps(other.result.mean(name)), color=other.color, ls="--", label=other.label
        )
        std_axes.plot(
            times, _gaps(other.result.std(name)), color=other.color, ls="--", label=other.label
        )
    # The worst comparison; a NaN difference (statistics not finite) counts as the worst.
    worst = max(
        comparisons, key=lambda c: np.nan_to_num(c.differences[name].mean_max, nan=np.inf)
    ).differences[name]
    mean_axes.set_title(f"mean of {name} (largest |Δ| {labels.value(name, worst.mean_max, 3)})")
    std_axes.set_title(f"std of {name} (largest |Δ| {labels.value(name, worst.std_max, 3)})")
    mean_axes.set_ylabel(labels.output(name))
    std_axes.set_ylabel(labels.output(name))
    for axes in (mean_axes, std_axes):
        _points_axis(axes, result, name, labels)
    _legend(figure, [mean_axes, std_axes])
    return canvas.save(figure, f"{name}_compare.png")


#: The page's style: fits a 1,400 px window (figures are 1,000 px wide), tables wrap their
#: cells rather than overflow, warnings red, information grey, a sound verdict green, cautions
#: on what is drawn from the surrogate amber.
_STYLE = (
    "body{font-family:sans-serif;max-width:1040px;margin:auto;padding:0 12px}"
    "table{border-collapse:collapse;max-width:100%}th,td{border:1px solid #ccc;"
    "padding:3px 8px;text-align:left;overflow-wrap:anywhere}td.num{text-align:right}"
    "pre{max-width:100%;overflow-x:auto}img{max-width:100%}.warn{color:#a00}"
    ".info{color:#555}.ok{color:#060}.caution{color:#a60}"
)


def _runs_text(result: StudyResult) -> str:
    """The runs made: design nodes (by status), held-out runs, the nominal run."""
    status = np.bincount(result.status.astype(int), minlength=3)
    held_out = result.held_out
    parts = [
        f"{plural(result.n_nodes, 'design node')} ({status[1]} ok, {status[2]} failed, "
        f"{status[0]} pending)",
        "no held-out runs"
        if held_out is None
        else f"{len(held_out.ok)} held-out ({int(held_out.ok.sum())} ok)",
    ]
    if result.nominal_params:
        nominal = ", ".join(f"{k} = {v:.6g}" for k, v in result.nominal_params.items())
        parts.append(f"nominal run at {nominal}{'' if result.nominal else ' (failed)'}")
    return "; ".join(filter(None, (*parts, result.fitted_runs)))


def _inputs_table(result: StudyResult) -> list[str]:
    """Every input's law with its parameters, range, mean and std."""
    rows = ["<table>", "<tr><th>input</th><th>law</th><th>range</th><th>mean</th><th>std</th></tr>"]
    for name, law in zip(result.input_names, result.distributions, strict=True):
        low, high = (float(x) for x in law.physical.support())
        cells = (
            name,
            law.law,
            f"{low:.4g} .. {high:.4g}",
            f"{law.expectation():.4g}",
            f"{float(law.physical.std()):.4g}",
        )
        rows.append(
            "<tr>"
            + "".join(
                f"<td{' class=num' if i > 1 else ''}>{html.escape(c)}</td>"
                for i, c in enumerate(cells)
            )
            + "</tr>"
        )
    return [*rows, "</table>"]


#: How the verdict names where an output's estimate comes from (``estimated_by``).
_ESTIMATED_BY = {
    "held-out": "held-out runs drawn at random",
    "placed": "held-out runs placed to extend the design's nodes",
    "design": "no held-out runs: estimated from the design's own estimate",
    "decay": "no held-out runs: estimated from the spectral decay",
}


def _verdict(result: StudyResult, name: str, labels: _Labels) -> tuple[str, str]:
    """(CSS class, text) of the diagnostics' verdict on an output, with its numbers: the
    estimates of a sound output; the range, the shading and the diagnostics' explanation
    (which holds the numbers) of an unreliable one."""
    found = result.diagnostics.get(name)
    if found is None:
        return "info", "not checked (no chaos expansion)"
    tolerance = f"tolerance {found.tolerance:g} of the largest std{result.checked_fit(name)}"
    if not found.reliable:
        axis = result.axis(name)
        where = "" if axis is None else f" from {labels.where(result, name, found.failing_from)}"
        shaded = f"shaded in {'the time plot' if result.on_time(name) else 'its figures'}"
        why = " ".join(w.message for w in result.warnings_for(name) if w.code == _FLAG)
        return "warn", f"unreliable{where} ({shaded}; {tolerance}): {why}"
    if not found.vouched:
        why = " ".join(w.message for w in result.warnings_for(name) if w.code == _UNDECIDED)
        return "warn", f"undecided ({tolerance}): {why}"
    error = float(np.nanmax(found.estimate, initial=0.0))
    numbers = [f"error up to {error:.2g} of the largest std ({tolerance})"]
    source = _ESTIMATED_BY[found.estimated_by]
    if found.holdout is None:
        numbers.append(source)
    else:
        surrogate = float(np.nanmax(found.holdout.error, initial=0.0))
        numbers.append(f"{found.holdout.count} {source}, surrogate error up to {surrogate:.2g}")
    numbers.append(f"decay up to {float(np.nanmax(found.decay, initial=0.0)):.2g}")
    axis = result.axis(name)
    where = "" if axis is None else f" at every {'time' if result.on_time(name) else axis.name}"
    return "ok", f"reliable{where}, {'; '.join(numbers)}"


def _record_lists(result: StudyResult) -> list[str]:
    """The warning records by severity: warnings in red, information apart (not red); the
    diagnostics' verdict is in its own section."""
    warnings = [w for w in result.alerts if w.code not in (_FLAG, _UNDECIDED)]
    information = [w for w in result.warnings if result.is_note(w)]
    parts: list[str] = []
    for title, records, kind in (
        ("Warnings", warnings, "warn"),
        ("Information", information, "info"),
    ):
        if records:
            parts.append(f"<h2>{title}</h2><ul>")
            parts += [f'<li class="{kind}">{html.escape(str(w))}</li>' for w in records]
            parts.append("</ul>")
    return parts


def _key_numbers(
    result: StudyResult,
    comparisons: Sequence[Comparison],
    others: Sequence[_Other],
    labels: _Labels,
) -> list[str]:
    """The table of each output's mean range and largest std (with units), and the
    differences to each comparison."""
    e = html.escape
    header = "<tr><th>output</th><th>mean range</th><th>largest std</th>"
    header += "".join(
        f"<th>vs {e(o.label)}: max |Δmean| (rel)</th><th>max |Δstd| (rel)</th>"
        "<th>departs at</th><th>verdict</th>"
        for o in others
    )
    parts = ["<h2>Key numbers</h2>", "<table>", header + "</tr>"]
    for name in result.outputs:
        mean, std = result.mean(name), result.std(name)
        mean_range, std_range = _extent(mean), _extent(std)
        mean_text = (
            "not finite"
            if mean_range is None
            else f"{mean_range[0]:.4g} .. {labels.value(name, mean_range[1])}"
        )
        std_text = "not finite" if std_range is None else labels.value(name, std_range[1])
        if mean_range is not None and not np.isfinite(mean).all():
            mean_text += " (not finite at some times)"
        if std_range is not None and not np.isfinite(std).all():
            std_text += " (not finite at some times)"
        cells = [
            f"<td>{e(name)}</td>",
            f'<td class="num">{e(mean_text)}</td>',
            f'<td class="num">{e(std_text)}</td>',
        ]
        for comparison in comparisons:
            d = comparison.differences.get(name)
            if d is None:
                cells.append("<td></td><td></td><td></td><td>not in both</td>")
                continue
            departs = "" if np.isnan(d.departure) else labels.where(result, name, d.departure)
            mean_text = f"{labels.value(name, d.mean_max, 3)} ({d.mean_relative:.2g})"
            std_text = f"{labels.value(name, d.std_max, 3)} ({d.std_relative:.2g})"
            cells += [
                f'<td class="num">{e(mean_text)}</td>',
                f'<td class="num">{e(std_text)}</td>',
                f'<td class="num">{e(departs)}</td>',
                f"<td>{e(d.verdict())}</td>",
            ]
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table>")
    if comparisons:
        parts.append(
            "<p>rel: relative to the largest standard deviation of this result. departs at: "
            "the first time the mean or std leaves the sampling noise (a family-wise test "
            f"over all times at level {LEVEL:g}) or, between two chaos results, differs by "
            "more than the chaos tolerance; against a Monte Carlo twin it depends on the "
            "twin's size (see the resolution under each table). verdict: whether they stay "
            "within it at every time.</p>"
        )
        parts += [f"<pre>{e(c.table())}</pre>" for c in comparisons]
    return parts


def _index_page(
    result: StudyResult,
    source: str,
    others: Sequence[_Other],
    comparisons: Sequence[Comparison],
    figures: dict[str, list[Path]],
    directory: Path,
    labels: _Labels,
    spectra: Sequence[str],
    notes: Sequence[str] = (),
) -> str:
    e = html.escape
    grid = labels.times(result.times)
    rows = [
        ("file", Path(source).name),
        ("method", method_label(result)),
        ("runs", _runs_text(result)),
        ("wall time of the runs", f"{result.seconds:.3g} s"),
        ("time", f"{grid[0]:.4g} .. {labels.at_time(result.times[-1])}, {grid.size} points"),
    ]
    if result.report is not None:
        rows += result.report.summary(result)
    rows.append(("spectra", ", ".join(spectra) or "none (analysis.psd)"))
    rows += [
        ("compared with", f"{other.label}, {other.result.seconds:.3g} s of runs")
        for other in others
    ]
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>pcmb report: {e(result.name)}</title>",
        f"<style>{_STYLE}</style>",
        "</head><body>",
        f"<h1>{e(result.name)}</h1>",
        "<table>",
        *(f"<tr><th>{e(key)}</th><td>{e(value)}</td></tr>" for key, value in rows),
        "</table>",
        "<h2>Inputs</h2>",
        *_inputs_table(result),
        "<h2>Diagnostics</h2>",
        "<ul>",
    ]
    for name in result.outputs:
        kind, verdict = _verdict(result, name, labels)
        parts.append(f'<li class="{kind}"><b>{e(name)}</b>: {e(verdict)}</li>')
    parts.append("</ul>")
    parts += _record_lists(result)
    if notes:
        parts.append("<h2>Not drawn</h2><ul>")
        parts += [f'<li class="warn">{e(note)}</li>' for note in notes]
        parts.append("</ul>")
    parts += _key_numbers(result, comparisons, others, labels)
    for name, paths in figures.items():
        parts.append(f"<h2>{e(name)}</h2>")
        unreliable = _unreliable(result, name)
        if unreliable is not None:
            where = (
                ""
                if result.axis(name) is None
                else f" from {labels.where(result, name, unreliable)}"
            )
            parts.append(
                f'<p class="warn">Shaded: chaos unreliable{e(where)} (see Diagnostics).</p>'
            )
        cautions = [str(w) for w in result.warnings_for(name) if w.code in SURROGATE_CAUTIONS]
        if cautions:
            parts.append(
                '<p class="caution">Caution on the PDFs, quantile bands and Sobol\' indices '
                f"drawn from the surrogate: {e('; '.join(cautions))}</p>"
            )
        for path in paths:
            relative = os.path.relpath(path, directory)
            parts.append(f'<p><img src="{e(relative)}" alt="{e(path.stem)}"></p>')
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _others(
    result: StudyResult, comparisons: Sequence[StudyResult], labels: Sequence[str] | None
) -> tuple[list[_Other], list[Comparison]]:
    """The comparison results with labels and colors, and their differences to ``result``."""
    names = list(labels) if labels is not None else [method_label(c) for c in comparisons]
    if len(names) != len(comparisons):
        raise UsageError(f"{len(comparisons)} comparisons but {len(names)} labels")
    others = [
        _Other(label, other, _COLORS[1 + i % (len(_COLORS) - 1)])
        for i, (label, other) in enumerate(zip(names, comparisons, strict=True))
    ]
    found = [compare(result, o.result, labels=(method_label(result), o.label)) for o in others]
    return others, found


def _shared(
    name: str, others: Sequence[_Other], found: Sequence[Comparison]
) -> tuple[list[_Other], list[Comparison]]:
    """The comparisons that have output ``name``."""
    pairs = [(o, c) for o, c in zip(others, found, strict=True) if name in o.result.outputs]
    return [o for o, _ in pairs], [c for _, c in pairs]


def _draw(canvas: _Canvas, name: str, kind: str, figure: Any, *args: Any) -> Path | None:
    """``figure(canvas, *args)``; a figure matplotlib cannot draw (values at the edge of the
    floating-point range, e.g. near 1e308, overflow its axis arithmetic) is left out with a
    note on the index page instead of stopping the report."""
    try:
        return figure(canvas, *args)
    except (ValueError, OverflowError) as error:
        canvas.note(f"{name}: {kind} figure not drawn: {type(error).__name__}: {error}")
        return None


def write_comparison_figures(
    reference: StudyResult,
    comparisons: Sequence[StudyResult],
    directory: str | os.PathLike[str],
    *,
    labels: Sequence[str] | None = None,
) -> list[Path]:
    """Write ``<output>_compare.png`` (means and stds overlaid) for every shared output;
    raises as :func:`write_report` does."""
    canvas = _Canvas(directory)
    others, found = _others(reference, comparisons, labels)
    settings = reference.analysis.settings if reference.analysis else AnalysisSettings()
    for name in reference.outputs:
        shared, matched = _shared(name, others, found)
        if shared:
            text = _Labels(settings, _horizon(reference))
            _draw(
                canvas, name, "comparison", _compare_figure, reference, name, shared, matched, text
            )
    return canvas.written


def write_report(
    result: StudyResult,
    directory: str | os.PathLike[str],
    *,
    source: str = "",
    comparisons: Sequence[StudyResult] = (),
    labels: Sequence[str] | None = None,
) -> list[Path]:
    """Write the figures and ``index.html`` of a result into ``directory``.

    Parameters
    ----------
    result:
        The study to show (its stored analysis, else a default one).
    directory:
        Created if needed; existing figures of the same names are replaced.
    source:
        Where the result came from (shown on the page).
    comparisons:
        Results of the same model on the same time grid (e.g. a Monte Carlo run), overlaid.
    labels:
        Names of the comparisons (default: how each was computed).

    Returns
    -------
    list of Path
        The files written, ``index.html`` last.

    Raises
    ------
    MissingDependencyError
        If matplotlib is missing.
    UsageError
        If a comparison has another time grid or no shared output.
    """
    canvas = _Canvas(directory)
    analysis = result.analysis or analyse(result)
    others, found = _others(result, comparisons, labels)
    text = _Labels(analysis.settings, _horizon(result))
    figures: dict[str, list[Path]] = {}
    spectra = [name for name in result.outputs if analysis.outputs[name].spectrum is not None]
    for name in result.outputs:
        shared, matched = _shared(name, others, found)
        drawn = [
            _draw(canvas, name, "time", _time_figure, result, name, analysis, shared, text),
            _draw(canvas, name, "PDF", _pdf_figure, result, name, analysis, shared, text),
            _draw(canvas, name, "Sobol'", _sobol_figure, result, name, text),
        ]
        if name in spectra:
            drawn += [
                _draw(canvas, name, "PSD", _psd_figure, result, name, analysis, shared, text),
                _draw(
                    canvas, name, "PSD PDF", _psd_pdf_figure, result, name, analysis, shared, text
                ),
            ]
        drawn.append(
            _draw(canvas, name, "comparison", _compare_figure, result, name, shared, matched, text)
        )
        figures[name] = [path for path in drawn if path is not None]
    index = canvas.directory / "index.html"
    index.write_text(
        _index_page(
            result, source, others, found, figures, canvas.directory, text, spectra, canvas.notes
        ),
        encoding="utf-8",
    )
    return [*canvas.written, index]
