"""Range checks: a variance from the coefficients that is zero where the runs vary, and
surrogate samples far outside the range of the run values (:func:`range_checks`);
:func:`pdf_outside_runs` flags a PDF with mass beyond every run made.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.decay import Expansion
from pcmb.analysis.diagnostics.phrases import as_percent, time_count, time_span
from pcmb.analysis.statistics import draws_are_runs, nearest_indices
from pcmb.chaos.nodes import draw_germs
from pcmb.result import StudyResult, WarningRecord

#: Surrogate draws of the range check, and its seed.
RANGE_DRAWS, RANGE_SEED = 4096, 0
#: A surrogate draw is "far outside" beyond this fraction of the run values' range past
#: their smallest or largest value ...
RANGE_MARGIN = 0.25
#: ... and the range check warns where more than this share of the draws is.
RANGE_SHARE = 0.01
#: Draws of an output that no run ever made negative are also far outside below 0 by more
#: than this fraction of the range.
RANGE_BELOW_ZERO = 0.01
#: A PDF's mass counts as beyond the runs past this fraction of their range
#: (:func:`pdf_outside_runs`): between the nodes a smooth surrogate may pass them a little.
PDF_MARGIN = 0.05
#: Run values whose std is below this fraction of their RMS do not vary (round-off).
_ROUND_OFF = 1e-12


def out_of_range(
    expansion: Expansion,
    node_values: ArrayLike,
    draws: int = RANGE_DRAWS,
    seed: int = RANGE_SEED,
    node_germ: ArrayLike | None = None,
    margin: float = RANGE_MARGIN,
) -> NDArray[np.float64]:
    """(T,) share of surrogate draws far outside the range of the run values.

    With ``node_germ`` ((N, n) germ of the runs), only draws inside the box the runs span are
    counted: beyond it (the tails of an unbounded input) a smooth response leaves the runs'
    range by itself, which says nothing about the surrogate.

    "Far" is beyond ``margin`` times the range (max - min of the runs) past the
    smallest or largest run value; where the runs or the expansion do not vary beyond
    round-off (:meth:`~pcmb.chaos.expansion.ChaosExpansion.varies`) the share is 0. An
    output that is never negative in any run and at any time (a distance, an energy) is
    also held to be non-negative: draws below 0 by more than ``RANGE_BELOW_ZERO`` times the
    range count too.
    """
    germ, samples = _surrogate_draws(expansion, draws, seed)
    values = np.asarray(node_values, dtype=float)
    return _outside_sides(expansion, values, margin, samples, _in_box(germ, node_germ)).sum(axis=0)


def _surrogate_draws(
    expansion: Expansion, draws: int, seed: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(D, n) germ drawn from the inputs' distribution and (D, T) the surrogate there."""
    germ = draw_germs(expansion.distributions, draws, np.random.default_rng(seed))
    return germ, expansion.evaluate_germ(germ)


def _in_box(germ: NDArray[np.float64], node_germ: ArrayLike | None) -> NDArray[np.bool_]:
    """(D,) whether each draw lies inside the box the (N, n) ``node_germ`` spans (all of them
    without it)."""
    if node_germ is None:
        return np.ones(germ.shape[0], dtype=bool)
    box = np.asarray(node_germ, dtype=float)
    return np.all((germ >= box.min(axis=0)) & (germ <= box.max(axis=0)), axis=1)


def _outside_sides(
    expansion: Expansion,
    values: NDArray[np.float64],
    margin: float,
    samples: NDArray[np.float64],
    kept: NDArray[np.bool_],
) -> NDArray[np.float64]:
    """(2, T) the shares of :func:`out_of_range` below and above the (N, T) runs' range,
    among the (D, T) surrogate ``samples`` where ``kept``."""
    if not kept.any():
        return np.zeros((2, values.shape[1]))
    floor, ceiling = _far_bounds(values, margin)
    samples = samples[kept]
    sides = np.stack([(samples < floor).mean(axis=0), (samples > ceiling).mean(axis=0)])
    return np.where(expansion.varies() & (ceiling > floor), sides, 0.0)


def _far_bounds(values: NDArray[np.float64], margin: float) -> tuple[NDArray, NDArray]:
    """(T,) bounds below and above which a value is far outside the (N, T) runs ``values``
    (:func:`out_of_range`)."""
    low, high = np.nanmin(values, axis=0), np.nanmax(values, axis=0)
    reach = margin * (high - low)
    floor = low - reach
    if np.nanmin(values) >= 0:
        floor = np.maximum(floor, -RANGE_BELOW_ZERO * (high - low))
    return floor, high + reach


def _table_mass_beyond(
    value: NDArray[np.float64], density: NDArray[np.float64], floor: float, ceiling: float
) -> NDArray[np.float64]:
    """(2,) mass of a tabulated density (linear between its points) below ``floor`` and
    above ``ceiling``, over its whole mass."""

    def mass(start: float, stop: float) -> float:
        inner = value[(value > start) & (value < stop)]
        points = np.concatenate([[start], inner, [stop]])
        return float(np.trapezoid(np.interp(points, value, density), points))

    whole = float(np.trapezoid(density, value))
    below = mass(value[0], floor) if floor > value[0] else 0.0
    above = mass(ceiling, value[-1]) if ceiling < value[-1] else 0.0
    return np.array([below, above]) / whole


def pdf_outside_runs(result: StudyResult) -> tuple[WarningRecord, ...]:
    """``pdf-outside-runs`` records (notes): a PDF stored at one of ``analysis.pdf_times`` with
    more of its mass than :func:`_pdf_allowance` on one side beyond the range of every run
    made (design, held-out and nominal) by more than ``PDF_MARGIN`` of that range. The mass
    is the stored density's (its kernel may smear the draws past a hard bound) or, where
    larger, the share of the surrogate's draws inside the box the design's nodes span
    (:func:`out_of_range`); the record names the cause: the surrogate inside that box, its
    draws from outside it, or the kernel."""
    analysis, ok = result.analysis, result.ok
    if analysis is None or not ok.any():
        return ()
    records = []
    for name, expansion in result.expansions.items():
        if name not in analysis.outputs or draws_are_runs(result, name):
            continue
        runs = [result.values[name][ok]]
        if result.held_out is not None:
            runs.append(result.held_out.values[name][result.held_out.ok])
        if name in result.nominal:
            runs.append(np.reshape(result.nominal[name], (1, -1)))
        made = finite_rows(np.vstack(runs))
        pdf = analysis.outputs[name].pdf
        points = nearest_indices(result.grid(name), pdf.at)
        germ, samples = _surrogate_draws(expansion, RANGE_DRAWS, RANGE_SEED)
        drawn = _outside_sides(expansion, made, PDF_MARGIN, samples, _in_box(germ, result.germ[ok]))
        anywhere = _outside_sides(expansion, made, PDF_MARGIN, samples, _in_box(germ, None))
        floor, ceiling = _far_bounds(made, PDF_MARGIN)
        allowed = _pdf_allowance(made.shape[0])
        axis = result.axis(name)
        where = "" if axis is None else f"{axis.name} = "
        for row, (t, k) in enumerate(zip(pdf.at, points, strict=True)):
            stored = np.zeros(2)
            if np.isfinite(pdf.bandwidth[row]) and ceiling[k] > floor[k]:
                stored = _table_mass_beyond(pdf.value[row], pdf.density[row], floor[k], ceiling[k])
            if max(stored.max(), drawn[:, k].max()) <= allowed:
                continue
            if drawn[:, k].max() > allowed:
                cause = "the surrogate overshoots (see its held-out error)"
            elif 2 * anywhere[:, k].sum() >= stored.sum():
                cause = (
                    "the surrogate's draws go there from outside the box the design's nodes "
                    "span, where it extrapolates and no run checks it"
                )
            else:
                smears = f"its kernel (bandwidth {pdf.bandwidth[row]:.3g}) smears"
                cause = f"{smears} the draws past them"
            records.append(
                WarningRecord(
                    "pdf-outside-runs",
                    f"the PDF at {where}{t:g} puts {as_percent(stored.sum())} of its mass "
                    f"({as_percent(drawn[:, k].sum())} of the surrogate's draws) beyond "
                    f"[{np.min(made[:, k]):.4g}, {np.max(made[:, k]):.4g}], the range of all "
                    f"{made.shape[0]} runs made (design, held-out and nominal), by more than "
                    f"{as_percent(PDF_MARGIN)} of that range: no run went there, {cause}",
                    name,
                    (float(t), float(t)) if result.on_time(name) else None,
                )
            )
    return tuple(records)


def _pdf_allowance(runs: int) -> float:
    """The share of a PDF's mass on one side beyond the range of ``runs`` runs that is not
    noted: ``RANGE_SHARE`` plus 1/(runs + 1), the mass a correct PDF leaves beyond the largest
    of ``runs`` exchangeable draws of its output on average."""
    return RANGE_SHARE + 1.0 / (runs + 1)


def range_checks(
    output: str,
    expansion: Expansion,
    node_values: ArrayLike,
    times: ArrayLike,
    out_of_range_share: NDArray[np.float64] | None = None,
) -> list[WarningRecord]:
    """Warnings where the expansion's values cannot be right, whatever its convergence.

    - ``variance-nonpositive``: the variance from the coefficients is zero (or not finite)
      where the runs vary — the basis misses what varies (e.g. a total basis that drops
      the interaction the output consists of).
    - ``surrogate-out-of-range``: more than ``RANGE_SHARE`` of the surrogate's draws lie
      far outside the run values (:func:`out_of_range`): its PDF puts mass where no run
      went (Gibbs or Runge overshoot of a steep response).

    Parameters
    ----------
    output:
        The output's name, for the records.
    expansion:
        Its (S, T) expansion.
    node_values:
        (N, T) the runs it was recovered from (non-finite rows are ignored).
    times:
        (T,) the grid.
    out_of_range_share:
        (T,) :func:`out_of_range` when already computed.
    """
    values = finite_rows(node_values)
    times = np.asarray(times, dtype=float)
    varies = runs_vary(values, times.size)
    records = []
    std = expansion.std()  # overflow-safe, where the variance of 1e200 would not be
    empty = varies & ~(np.isfinite(std) & (std > 0))
    if empty.any():
        records.append(
            WarningRecord(
                "variance-nonpositive",
                f"the variance from the chaos coefficients is zero or not finite at "
                f"{time_count(empty)} where the runs vary: the basis misses the variation",
                output,
                time_span(times, empty),
            )
        )
    share = out_of_range(expansion, values) if out_of_range_share is None else out_of_range_share
    far = share > RANGE_SHARE
    if far.any():
        records.append(
            WarningRecord(
                "surrogate-out-of-range",
                f"up to {as_percent(share.max())} of the surrogate's values lie far outside the "
                f"range of the runs (at {time_count(far)}): its PDF has mass where no run went",
                output,
                time_span(times, far),
            )
        )
    return records


def finite_rows(values: ArrayLike) -> NDArray[np.float64]:
    """The (N, T) runs without the rows holding a value that is not finite (failed runs)."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    return values[np.isfinite(values).all(axis=1)]


def runs_vary(values: NDArray[np.float64], points: int) -> NDArray[np.bool_]:
    """(T,) where (N, T) finite runs differ by more than round-off (never with one run)."""
    if values.shape[0] < 2:
        return np.zeros(points, dtype=bool)
    # Ranges, not squares: outputs near 1e200 must not overflow.
    return np.ptp(values, axis=0) > _ROUND_OFF * np.max(np.abs(values), axis=0)
