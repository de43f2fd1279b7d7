"""The diagnosis of one output (:func:`diagnose`), and of every output (:func:`diagnose_all`).

Its estimated error is the larger of the estimated errors of the mean and the std at each time
(the decay where there are no held-out runs), its verdict the first time that exceeds the
tolerance by more than its noise, explained in a ``chaos-unreliable`` record with a remedy that
fits the failure; where the noise is too large to tell, a ``chaos-undecided`` record says how
many more held-out runs would (:func:`more_runs`). Where the design's runs are all equal while
the held-out runs vary, the design saw none of the spread (nodes symmetric about a kink) and the
verdict fails there, unless the held-out check says the error holds within the tolerance;
without held-out runs, runs all equal at every time are reported (``runs-all-equal``, or
``output-constant`` when the nominal run equals them too). A surrogate whose pointwise error
exceeds the tolerance while its statistics hold gets a ``surrogate-inaccurate`` record: the
PDFs, quantiles and Sobol' indices drawn from it are less accurate than the error bars.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import HeldOutCheck, holdout_error
from pcmb.analysis.diagnostics.decay import Expansion, largest_std, spectral_decay
from pcmb.analysis.diagnostics.draws import (
    FIRST_BATCH,
    HeldOut,
    coverage_error,
    judging_weights,
    unseen_region_error,
)
from pcmb.analysis.diagnostics.line import line_check
from pcmb.analysis.diagnostics.phrases import as_percent, time_count, time_span
from pcmb.analysis.diagnostics.placed import placed_check
from pcmb.analysis.diagnostics.ranges import finite_rows, out_of_range, range_checks, runs_vary
from pcmb.analysis.diagnostics.remedies import element_errors, error_at_ends, remedy_for
from pcmb.analysis.diagnostics.verdict import TOLERANCE, flag_margin, verdict
from pcmb.axes import OutputAxis
from pcmb.chaos.elements import PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.result import WarningRecord

#: Codes of the warning records the diagnostics make.
CODES = frozenset(
    {
        "chaos-unreliable",
        "chaos-undecided",
        "surrogate-inaccurate",
        "variance-nonpositive",
        "surrogate-out-of-range",
        "runs-all-equal",
        "output-constant",
    }
)
#: Runs needed beyond this many times those made: more held-out runs decide only slowly, and
#: the ``chaos-undecided`` record says what makes the noise smaller instead.
SLOW_DECISION = 10


@dataclass(frozen=True)
class OutputDiagnostics:
    """How far one output's chaos expansion can be trusted, time by time.

    Attributes
    ----------
    output:
        The output's name.
    scale:
        Its largest standard deviation over time, the unit of every indicator.
    decay:
        (T,) :func:`spectral_decay`, a share of the largest variance.
    holdout:
        The held-out check (:class:`HeldOutCheck`), ``None`` without held-out runs.
    out_of_range:
        (T,) :func:`out_of_range`, a share of surrogate draws.
    estimate:
        (T,) the estimated error: the larger of the held-out estimates of the errors of the
        mean and the std (:attr:`HeldOutCheck.statistics`), or the decay without held-out runs.
    estimated_by:
        Where ``estimate`` comes from: ``"held-out"`` (runs drawn at random), ``"placed"``
        (runs placed to extend the design's nodes), ``"design"`` (no held-out runs: the
        design's own estimate, where it bounds the decay) or ``"decay"``.
    noise:
        (T,) how far the estimate may be off at the held-out check's confidence
        (:attr:`HeldOutCheck.noise`; 0 for the decay).
    undecided:
        (T,) the times before ``failing_from`` where the estimate lies within its noise of
        the tolerance: more held-out runs would tell.
    tolerance:
        The accepted error, relative to the scale.
    failing_from:
        :func:`verdict` of the estimate: the first time it exceeds the tolerance by more than
        its noise, or where the design's runs are all equal while the held-out runs vary and
        do not show the error within the tolerance; NaN if never.
    warnings:
        ``chaos-unreliable`` (when ``failing_from`` is a time), ``chaos-undecided`` (where
        the noise is too large to tell) and the range checks' records (:func:`range_checks`).
    """

    output: str
    scale: float
    decay: NDArray[np.float64]
    holdout: HeldOutCheck | None
    out_of_range: NDArray[np.float64]
    estimate: NDArray[np.float64]
    estimated_by: str
    noise: NDArray[np.float64]
    undecided: NDArray[np.bool_]
    tolerance: float
    failing_from: float
    warnings: tuple[WarningRecord, ...]

    @property
    def reliable(self) -> bool:
        """Whether no time is flagged (the estimate never exceeds the tolerance by more than
        its noise)."""
        return bool(np.isnan(self.failing_from))

    @property
    def vouched(self) -> bool:
        """Whether the check vouches for every time: none flagged, none undecided."""
        return self.reliable and not self.undecided.any()


def diagnose(
    output: str,
    expansion: Expansion,
    node_values: ArrayLike,
    times: ArrayLike,
    holdout: tuple[ArrayLike, ArrayLike] | None = None,
    tolerance: float = TOLERANCE,
    node_germ: ArrayLike | None = None,
    axis: str = "t",
    nominal: ArrayLike | None = None,
    budgets: Collection[str] = (),
    holdout_germ: ArrayLike | None = None,
    weights: ArrayLike | None = None,
    placed: bool = False,
    design_error: float | None = None,
    stratified: bool = True,
    design_understates: float = 1.0,
) -> OutputDiagnostics:
    """Every check of one output's expansion, its verdict and its warnings.

    Parameters
    ----------
    output:
        The output's name.
    expansion:
        Its (S, T) expansion.
    node_values:
        (N, T) the runs it was recovered from.
    times:
        (T,) the grid.
    holdout:
        ``(predicted, observed)``, each (K, T): the surrogate and the model at K inputs
        drawn at random from the inputs' distribution (not the nodes), or ``None``.
    tolerance:
        Accepted error relative to the output's largest standard deviation.
    node_germ:
        (N, n) germ of the runs, which bounds where the range check looks (see
        :func:`out_of_range`) and which the remedy's interpolant goes through.
    axis:
        Name of the axis ``times`` are points of, for the message (``"t"``; ``""`` for a
        scalar output, whose ``times`` is ``[0.]``: ``failing_from`` is then 0 when it fails,
        NaN when it passes).
    nominal:
        (T,) the run at the nominal parameters, or ``None``: without held-out runs, whether
        it differs from design runs that are all equal tells a design that missed the spread
        (``runs-all-equal``, a warning) from an output that looks constant
        (``output-constant``, a note).
    budgets:
        Codes of the design's budget records (``order-budget``, ``element-budget``): the
        refinements that ran out, which the remedy does not ask for again.
    holdout_germ:
        (K, n) germ of the held-out runs, a Latin hypercube: it tells the remedy where along
        each input the surrogate's error sits (:func:`error_at_ends`), and the check's
        standard errors (:func:`_standard_error`; default: taken as independent draws).
    weights:
        (K,) importance weights of the held-out runs (:func:`held_out_draws`; default: 1).
    placed:
        Whether the held-out runs extend the nodes of a one-input expansion
        (:func:`held_out_placed`), or of several inputs along one
        (:func:`~pcmb.analysis.diagnostics.line.held_out_line`): judged by :func:`placed_check`
        or :func:`~pcmb.analysis.diagnostics.line.line_check` instead.
    stratified:
        Whether the drawn held-out runs are one Latin hypercube, whose standard errors
        :func:`_standard_error` reads from neighbouring pairs; several batches joined are
        taken as independent draws (paired across two hypercubes drawn apart, neighbours
        understated the spread; a second batch that completes the first's hypercube,
        :func:`~pcmb.analysis.diagnostics.draws.held_out_unit`, is not always exact).
    design_error:
        The design's own calibrated estimate of this output's statistics' error
        (:meth:`pcmb.result.DesignReport.statistics_error`), or ``None``: without held-out
        runs, where it meets the tolerance it bounds the decay's reading.
    design_understates:
        How many times below the truth ``design_error`` was measured to fall at worst
        (:attr:`pcmb.result.DesignReport.UNDERSTATES`): where the decay disagrees, a time
        is vouched for only where that many times the estimate meets the tolerance, and
        undecided where it does not.
    """
    times = np.asarray(times, dtype=float)
    std = expansion.std()
    scale = largest_std(std)
    runs = finite_rows(node_values)
    equal = ~runs_vary(runs, times.size)
    # Where the design's runs are all equal and the held-out runs are not, the design saw
    # none of the spread (nodes symmetric about a kink): no expansion can learn it.
    blind = np.zeros(times.size, dtype=bool)
    germ = None
    if holdout is not None:  # the held-out runs that did not fail
        predicted, observed = (np.atleast_2d(np.asarray(a, dtype=float)) for a in holdout)
        kept = np.isfinite(observed).all(axis=1)
        predicted, observed = predicted[kept], observed[kept]
        germ = None if holdout_germ is None else np.asarray(holdout_germ, dtype=float)[kept]
        weights = None if weights is None else np.asarray(weights, dtype=float)[kept]
        blind = equal & runs_vary(observed, times.size)
        if not scale > 0 and blind.any():  # the held-out runs' spread is the only scale
            size = float(np.max(np.abs(observed)))  # scaled before squaring: outputs near 1e200
            scale = size * float(np.max(np.std(observed / size, axis=0)))
    decay = spectral_decay(expansion, scale)
    checked = None
    if holdout is not None and placed and len(expansion.distributions) > 1:
        checked = line_check(expansion, node_germ, germ, predicted, observed, scale)
    elif holdout is not None and placed:
        checked = placed_check(expansion, node_germ, node_values, germ, observed, scale)
    elif holdout is not None:
        judged, paired = judging_weights(expansion, scale, weights, germ)
        paired = paired if stratified else None
        checked = holdout_error(
            predicted, observed, expansion.mean(), std, scale, weights=judged, germ=paired
        )
        # Draws that missed the tails carrying the variance saw none of the error there.
        unseen = coverage_error(expansion, predicted, observed, weights, scale)
        checked = checked.widened(unseen, scale)
    # The held-out runs measure the errors of the statistics themselves; the decay only hints
    # at them (it is large for a response that is exactly a polynomial of the expansion's
    # order), so it decides only where there are no held-out runs.
    estimate = decay if checked is None else checked.statistics
    estimated_by = "decay" if checked is None else "placed" if placed else "held-out"
    # Without them, a design that measured its own convergence (an adaptive grid, order:
    # auto) outweighs the decay, which reads an exact polynomial's top terms (or a sparse
    # set's edge) as a tail.
    noise = (
        np.zeros(times.size)
        if checked is None
        else np.where(np.isnan(checked.noise), np.inf, checked.noise)
    )
    if checked is None and design_error is not None and design_error <= tolerance:
        estimate = np.minimum(decay, design_error)
        if np.any(design_error < decay):
            estimated_by = "design"
        # Where the decay disagrees, the truth may be up to its calibration's factor above
        # the design's estimate: undecided there unless that factor meets the tolerance too.
        noise = np.where(decay > tolerance, (design_understates - 1.0) * design_error, 0.0)
    failing_from = verdict(
        times, estimate, tolerance, noise if checked is None else flag_margin(checked, tolerance)
    )
    # A blind time fails unless the held-out runs, which saw the spread there, say it holds
    # beyond their noise (a switch the nodes have not reached yet, its spread still small).
    blind &= estimate + noise > tolerance
    if checked is not None and not placed:
        # No time is called reliable on draws that may have missed where the error lives.
        unseen = unseen_region_error(predicted, observed, weights, scale, checked.confidence)
        noise = np.fmax(noise, unseen)
    if blind.any():
        failing_from = float(np.fmin(failing_from, times[blind][0]))
    # Without held-out runs, design runs all equal at every time say nothing: where the
    # nominal run differs the design missed the spread (it fails), else none can tell.
    missed, spread = (
        _all_equal(output, runs, times, nominal)
        if holdout is None and runs.shape[0] > 1 and equal.all()
        else (None, False)
    )
    if spread:
        failing_from = float(times[0])
    share = out_of_range(expansion, node_values, node_germ=node_germ)
    records = range_checks(output, expansion, node_values, times, share)
    holding = ~(times >= failing_from)  # every time where the verdict never fails
    undecided = ((estimate + noise > tolerance) | (spread is None)) & holding
    if checked is not None:
        records.extend(_inaccurate(output, checked, times, tolerance, holding, undecided))
    if missed is not None:
        records.append(missed)
    if not np.isnan(failing_from):
        failing = times >= failing_from
        where = f" from {axis} = {failing_from:.4g}" if axis else ""
        evidence = _evidence(decay, checked, failing)
        place, by_element = None, ""
        if germ is not None:
            place = error_at_ends(germ, observed, predicted, failing)
            if isinstance(expansion, PiecewiseExpansion):
                by_element = element_errors(expansion, germ, place.residual, failing)
        if blind.any():
            evidence = (
                f"the design's {runs.shape[0]} runs are all equal at {time_count(blind)} while the "
                f"{checked.count} held-out runs vary there, which no expansion can learn "
                f"from; {evidence}"
            )
        elif spread:
            evidence = (
                f"the design's {runs.shape[0]} runs are all equal at every time while the "
                "nominal run differs, which no expansion can learn from"
            )
        # The remedy reads the times from where the estimate passes the tolerance, which
        # the flag, waiting for the noise, may follow late.
        passing = times >= times[np.argmax((estimate > tolerance) | failing)]
        design = None
        if node_germ is not None:
            design = tuple(np.asarray(a, dtype=float) for a in (node_germ, node_values))
        remedy = remedy_for(expansion, estimate, passing, share, budgets, place, by_element, design)
        message = f"polynomial chaos unreliable{where} ({evidence}); consider {remedy}"
        span = (failing_from, float(times[-1]))
        records.insert(0, WarningRecord("chaos-unreliable", message, output, span))
    found = OutputDiagnostics(
        output,
        scale,
        decay,
        checked,
        share,
        estimate,
        estimated_by,
        noise,
        undecided,
        tolerance,
        failing_from,
        (),
    )
    if found.undecided.any():
        records.append(_undecided(found, times, axis))
    if axis != "t":  # a record's time_range is in time: off time, the message says where
        records = [dataclasses.replace(record, time_range=None) for record in records]
    return dataclasses.replace(found, warnings=tuple(records))


def more_runs(found: OutputDiagnostics) -> int:
    """How many held-out runs, beyond those made, would decide every undecided time of
    ``found`` but those whose estimate is within a tenth of the tolerance of it (0 when none is
    undecided, at least 1 otherwise): the sampling noise (the check's) falls as 1/√K, the rule
    of three's floor (where ``noise`` is above it:
    :func:`~pcmb.analysis.diagnostics.draws.unseen_region_error`) as 1/K. Too few runs to
    measure any noise (one): the first batch."""
    if not found.undecided.any() or found.holdout is None:  # no check to extend
        return 0
    count = found.holdout.count
    needed = _runs_needed(found)
    if not np.isfinite(needed):
        return max(FIRST_BATCH - count, 1)
    return max(int(np.ceil(needed)) - count, 1)


def _runs_needed(found: OutputDiagnostics) -> float:
    """Held-out runs in all whose noise would decide every undecided time of ``found``, those
    within a tenth of the tolerance of it to that tenth (:func:`more_runs`)."""
    undecided = found.undecided
    margin = np.abs(found.estimate - found.tolerance)[undecided]
    margin = np.maximum(margin, found.tolerance / 10)
    sampling = found.holdout.noise[undecided]
    sampling = np.where(np.isnan(sampling), np.inf, sampling)
    unseen = np.where(found.noise[undecided] > sampling, found.noise[undecided], 0.0)
    return found.holdout.count * float(np.max(np.fmax((sampling / margin) ** 2, unseen / margin)))


def _undecided(found: OutputDiagnostics, times: NDArray[np.float64], axis: str) -> WarningRecord:
    """The ``chaos-undecided`` record: where the held-out check cannot tell whether the
    statistics hold, the estimate at the worst such time and the runs that would decide, or,
    where the runs made resolve every such time to a tenth of the tolerance, that the
    estimate sits at the tolerance itself."""
    undecided = found.undecided
    worst = int(np.flatnonzero(undecided)[np.argmax(found.estimate[undecided])])
    holdout = found.holdout
    where = f" at {axis} = {times[worst]:.4g}" if axis else ""
    if holdout is None:
        return WarningRecord(
            "chaos-undecided",
            f"without held-out runs, the design's own estimate of the error of mean and std, "
            f"{as_percent(found.estimate[worst])}{where}, meets the tolerance "
            f"{as_percent(found.tolerance)} of the largest std at {time_count(undecided)} but "
            f"not by the factor it was measured to understate the truth by, while the "
            f"coefficients' decay says {as_percent(found.decay[worst])}; held-out runs "
            "(method.validation) would decide",
            found.output,
            time_span(times, undecided),
        )
    count = holdout.count
    if _runs_needed(found) <= count:
        decide = (
            "its estimate lies within a tenth of the tolerance of it there, at the tolerance "
            "itself, which more held-out runs resolve only slowly"
        )
    else:
        more = more_runs(found)
        decide = f"about {more} more held-out runs would decide (method.validation: {count + more})"
        if more > SLOW_DECISION * count:
            decide += (
                "; so many because the noise is the spread of the surrogate's own error, "
                "which a finer design (a higher order, or elements) makes smaller"
            )
    return WarningRecord(
        "chaos-undecided",
        f"the held-out check cannot tell whether mean and std hold within the tolerance "
        f"{as_percent(found.tolerance)} of the largest std at {time_count(undecided)}: estimated "
        f"error {as_percent(found.estimate[worst])} ± {as_percent(found.noise[worst])}{where} "
        f"({as_percent(holdout.confidence)} confidence, {count} held-out runs); {decide}",
        found.output,
        time_span(times, undecided),
    )


def _evidence(
    decay: NDArray[np.float64], holdout: HeldOutCheck | None, failing: NDArray[np.bool_]
) -> str:
    """The indicators where the verdict fails, e.g. "mean off by an estimated 12 % of the
    largest std (± 2 % from 32 held-out runs), surrogate error 25 % of std, decay 5.6 %"."""
    found = [f"decay {as_percent(np.nanmax(decay[failing]))}"]
    if holdout is None:
        return ", ".join(found)
    worst = int(np.flatnonzero(failing)[np.nanargmax(holdout.statistics[failing])])
    which = "mean" if holdout.mean_error[worst] >= holdout.std_error[worst] else "std"
    judged = (
        f"{which} off by an estimated {as_percent(holdout.statistics[worst])} of the largest "
        f"std (± {as_percent(holdout.spread[worst])} from {holdout.count} held-out runs)"
    )
    surrogate = f"surrogate error {as_percent(np.nanmax(holdout.error[failing]))} of std"
    return ", ".join([judged, surrogate, *found])


def _all_equal(
    output: str,
    runs: NDArray[np.float64],
    times: NDArray[np.float64],
    nominal: ArrayLike | None,
) -> tuple[WarningRecord, bool | None]:
    """The record of an output whose (N, T) runs are all equal at every time and that no
    held-out run checks: ``output-constant`` when the nominal run equals them too, else
    ``runs-all-equal``; and whether the nominal run saw a spread the design missed (``None``:
    nothing else was run to tell)."""
    span = time_span(times, np.ones(times.size, dtype=bool))
    unchecked = "no held-out run checks it (method.validation is 0)"
    if nominal is not None and np.size(nominal) == runs.shape[1]:
        with_nominal = np.vstack([runs, np.reshape(nominal, (1, -1))])
        if np.all(np.isfinite(with_nominal)) and not runs_vary(with_nominal, times.size).any():
            constant = WarningRecord(
                "output-constant",
                f"all {runs.shape[0]} runs of the design and the nominal run are equal at "
                f"every time: the output looks constant, and {unchecked}",
                output,
                span,
            )
            return constant, False
        seen, spread = "the nominal run differs, so the design missed the spread", True
    else:
        seen, spread = "nothing else was run to compare", None
    record = WarningRecord(
        "runs-all-equal",
        f"all {runs.shape[0]} runs of the design are equal at every time: its std 0 says "
        f"nothing about the spread (nodes placed symmetric about a kink see none); {seen}, "
        f"and {unchecked}",
        output,
        span,
    )
    return record, spread


def _inaccurate(
    output: str,
    holdout: HeldOutCheck,
    times: NDArray[np.float64],
    tolerance: float,
    holding: NDArray[np.bool_],
    undecided: NDArray[np.bool_],
) -> list[WarningRecord]:
    """A ``surrogate-inaccurate`` record where the surrogate's pointwise error exceeds the
    tolerance at the times where the statistics hold (``holding``: before the verdict fails),
    saying so of the ``undecided`` ones among them."""
    above = (holdout.error > tolerance) & holding
    if not above.any():
        return []
    statistics = (
        f"its mean and std are not flagged there (undecided at {time_count(above & undecided)})"
        if (above & undecided).any()
        else "its mean and std hold there"
    )
    return [
        WarningRecord(
            "surrogate-inaccurate",
            f"the surrogate is off by up to {as_percent(np.nanmax(holdout.error[above]))} of std "
            f"at {holdout.count} held-out runs ({time_count(above)}) while {statistics} (estimated "
            f"error at most {as_percent(np.nanmax(holdout.statistics[above]))}): PDFs, quantiles "
            "and Sobol' indices drawn from it are less accurate than its error bars",
            output,
            time_span(times, above),
        )
    ]


def diagnose_all(
    expansions: Mapping[str, object],
    germ: NDArray[np.float64],
    values: Mapping[str, NDArray[np.float64]],
    ok: NDArray[np.bool_],
    times: ArrayLike,
    held_out: HeldOut | None,
    tolerance: float = TOLERANCE,
    axes: Mapping[str, OutputAxis | None] | None = None,
    nominal: Mapping[str, NDArray[np.float64]] | None = None,
    budgets: Collection[str] = (),
    design_error: Mapping[str, float | None] | None = None,
    design_understates: float = 1.0,
) -> dict[str, OutputDiagnostics]:
    """:func:`diagnose` every output with a chaos expansion (one element or several), each on
    its own points: ``times``, or per ``axes`` (:class:`pcmb.result.StudyResult`) the points
    of its axis or ``[0.]`` for a scalar.

    ``germ`` and ``values`` are the (N, n) and (N, T) runs of the design and ``ok`` the (N,)
    nodes that succeeded; the held-out check uses the successful held-out runs; ``nominal``
    holds the run at the nominal parameters (output name -> (T,)), when one succeeded;
    ``budgets`` the codes of the design's budget records and ``design_error`` its own
    estimate of each output's statistics' error (output name -> :func:`diagnose`'s
    ``design_error``; an output not in it has none), understated by at most
    ``design_understates``.
    """
    found = {}
    for name, expansion in expansions.items():
        if not isinstance(expansion, ChaosExpansion | PiecewiseExpansion):
            continue
        holdout = None
        if held_out is not None and held_out.ok.any():
            predicted = expansion.evaluate_germ(held_out.germ[held_out.ok])
            holdout = (predicted, held_out.values[name][held_out.ok])
        grid, label = times, "t"
        if axes is not None and name in axes:
            axis = axes[name]
            grid, label = (np.zeros(1), "") if axis is None else (axis.values, axis.name)
        found[name] = diagnose(
            name,
            expansion,
            values[name][ok],
            grid,
            holdout,
            tolerance,
            germ[ok],
            label,
            None if nominal is None else nominal.get(name),
            budgets,
            None if holdout is None else held_out.germ[held_out.ok],
            None if holdout is None else held_out.weights[held_out.ok],
            held_out is not None and held_out.placed,
            None if design_error is None else design_error.get(name),
            held_out is None or held_out.batches == 1,
            design_understates,
        )
    return found
