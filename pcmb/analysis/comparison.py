"""How far apart two studies of the same model are (chaos against Monte Carlo, ...), in
units of the reference's largest std, of the sampling noise, or of the chaos tolerance
(``docs/architecture.md``).

*Against sampling noise* (either result from random sampling): at each time t the gap of the
means and the gap of the stds are divided by their standard errors (σ/√N for a mean,
σ√((κ−1)/4N) for a std, κ the kurtosis), giving 2T z-scores. The verdict is family-wise over
all of them: a max-statistic test at level :data:`LEVEL`, whose critical value is the
(1 − LEVEL) quantile of max_t |Z(t)| for the Gaussian vector Z that the z-scores follow when
both results sample the same law (central limit theorem for the means and, through the
influence function ((x − μ)² − σ²)/2σ, for the stds). Z's correlation across times and
between mean and std is that of the runs themselves, estimated from them, and the quantile
is drawn by a Gaussian multiplier bootstrap (:data:`DRAWS` draws, fixed seed). A max-statistic
rather than Bonferroni or Šidák: neighbouring times are strongly correlated, so T separate
tests at level LEVEL/T would be conservative by a factor up to T (an effective level far
below the stated one and a blunter test); the max-statistic holds the stated level whatever
the correlation. Two independent samples of the same law are then "beyond noise" with
probability about LEVEL, however many times the grid has.

*Against the chaos tolerance* (both results from quadrature, no sampling noise): the gaps
over the reference's largest std against ``diagnostics.tolerance`` of the files, the error
the chaos diagnostics accept.

Statistics that are not finite (NaN or inf) are left out of the maxima and RMS values and
counted (:attr:`OutputDifference.not_finite`); the verdict then says so. Nothing here
overflows for outputs whose own statistics are finite (runs are standardised per time before
any power is taken).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.diagnostics import TOLERANCE
from pcmb.chaos.expansion import power_of_two, sample_mean, unsafe_to_square
from pcmb.errors import UsageError
from pcmb.result import StudyResult

__all__ = [
    "DRAWS",
    "LEVEL",
    "Comparison",
    "OutputDifference",
    "compare",
    "method_label",
    "sampling_noise",
]

#: Family-wise level of the noise verdict: the chance that two samples of the same law are
#: called "beyond noise" (at any time).
LEVEL = 0.05
#: Multiplier-bootstrap draws of the null maximum (the (1 - LEVEL) quantile is then known to
#: about ±0.5 % in level) and their seed.
DRAWS, _SEED = 2000, 0
#: Runs of a result used to estimate the correlation of its noise across times (all of its
#: runs give the standard errors): bounds the cost at draws × runs × 2T.
_CORRELATION_RUNS = 1000
#: Differences below this fraction of the reference's largest std are round-off.
_ROUND_OFF = 1e-9


def method_label(result: StudyResult) -> str:
    """A short description of how a result was computed, e.g. ``collocation, tensor order 5
    (216 runs)``."""
    return f"{result.design.label} ({int(np.sum(result.ok))} runs)"


def _sampled(result: StudyResult, name: str) -> NDArray[np.float64] | None:
    """(N, T) the runs of a sampling result (``None`` for a quadrature grid or < 2 runs)."""
    if result.weights is not None or np.sum(result.ok) < 2:
        return None
    return result.values[name][result.ok]


def _standardised(runs: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, T) runs centred and divided by their RMS deviation at each time (0 where they do
    not vary): scale-free, so powers of them neither overflow nor underflow."""
    centred = runs - sample_mean(runs)
    top = np.max(np.abs(centred), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = np.where(top > 0, centred / top, 0.0)
        unit -= unit.mean(axis=0)
        rms = np.sqrt(np.mean(unit**2, axis=0))
        return np.where(rms > 0, unit / rms, 0.0)


def sampling_noise(
    result: StudyResult, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(T,) standard errors of a result's mean and std: zero for a collocation grid."""
    runs = _sampled(result, name)
    if runs is None:
        zero = np.zeros(result.values[name].shape[1])
        return zero, zero
    count = runs.shape[0]
    kurtosis = np.mean(_standardised(runs) ** 4, axis=0)
    std = result.std(name)
    return std / np.sqrt(count), std * np.sqrt(np.maximum(kurtosis - 1.0, 0.0) / (4 * count))


def _critical(results: Sequence[StudyResult], name: str, finite: NDArray[np.bool_]) -> float:
    """(1 - LEVEL) quantile of max |Z| over the mean and std z-scores at the finite times,
    when every sampling result among ``results`` samples the same law (NaN without any).

    Each sampling result adds its noise as Σ_i g_i ψ_i / N over its runs, g_i standard
    normal and ψ_i a run's influence on the mean and std (in units of their std, weighted
    by its std over the largest std of the results at that time, so that nothing
    overflows); Z is that sum over its own standard deviation.
    """
    stds = [r.std(name)[finite] for r in results]
    largest = np.max(stds, axis=0)
    blocks = []
    for result, std in zip(results, stds, strict=True):
        runs = _sampled(result, name)
        if runs is None:
            continue
        unit = _standardised(runs[:_CORRELATION_RUNS, finite])
        square = unit**2
        influence = np.hstack([unit, (square - square.mean(axis=0)) / 2])
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(largest > 0, std / largest, 0.0)
        # var(Σ g_i ψ_i) = M · var(ψ): over √(M N) this is the noise of an N-run mean.
        blocks.append(influence * np.tile(weight, 2) / np.sqrt(unit.shape[0] * runs.shape[0]))
    if not blocks:
        return float("nan")
    spread = np.sqrt(sum(np.sum(block**2, axis=0) for block in blocks))
    spread = np.where(spread > 0, spread, np.inf)  # no noise there: Z = 0
    generator = np.random.default_rng(_SEED)
    maxima = []
    for size in np.diff(np.r_[0:DRAWS:500, DRAWS]):
        total = sum(generator.standard_normal((size, b.shape[0])) @ b for b in blocks)
        maxima.append(np.max(np.abs(total) / spread, axis=1, initial=0.0))
    return float(np.quantile(np.concatenate(maxima), 1.0 - LEVEL))


def _tolerance(results: Sequence[StudyResult], name: str) -> float:
    """The smallest ``diagnostics.tolerance`` the results store for an output (the chaos
    diagnostics' default when none does)."""
    stored = [r.diagnostics[name].tolerance for r in results if name in r.diagnostics]
    return min(stored, default=TOLERANCE)


@dataclass(frozen=True)
class OutputDifference:
    """Differences of one output's statistics over time, other minus reference.

    Attributes
    ----------
    mean_max, mean_rms:
        max_t and RMS_t of |mean_other - mean_reference|.
    std_max, std_rms:
        The same for the standard deviations.
    scale:
        max_t of the reference's standard deviation.
    mean_noise, std_noise:
        max_t of the combined sampling standard error of the two means (of the two
        standard deviations); zero when both results come from collocation grids.
    mean_z, std_z:
        max_t of |difference(t)| / standard error(t): how many standard errors the worst
        time is off (NaN without sampling noise; infinite where a difference meets no noise).
    critical:
        The family-wise critical value of mean_z and std_z at level :data:`LEVEL` (NaN
        without sampling noise).
    tolerance:
        Without sampling noise: the accepted difference relative to ``scale`` (the files'
        ``diagnostics.tolerance``); NaN with sampling noise.
    departure:
        The first time at which the mean or the std leaves the noise (a z-score above
        ``critical``) or, without sampling noise, differs by more than ``tolerance`` times
        ``scale``; NaN if it never does. Against a sampled twin it depends on the twin's
        size: more runs resolve smaller differences, so the departure comes earlier.
    runs:
        Runs of each sampling result compared (empty without sampling noise).
    not_finite:
        Number of times at which a mean or std of either result is not finite (NaN or inf);
        the other attributes are computed over the remaining times.
    """

    mean_max: float
    mean_rms: float
    std_max: float
    std_rms: float
    scale: float
    mean_noise: float
    std_noise: float
    mean_z: float
    std_z: float
    critical: float
    tolerance: float
    departure: float
    runs: tuple[int, ...] = ()
    not_finite: int = 0

    @property
    def mean_relative(self) -> float:
        """mean_max / scale (NaN when the reference does not vary)."""
        return self.mean_max / self.scale if self.scale > 0 else float("nan")

    @property
    def std_relative(self) -> float:
        """std_max / scale (NaN when the reference does not vary)."""
        return self.std_max / self.scale if self.scale > 0 else float("nan")

    @property
    def resolution(self) -> float:
        """The largest difference, relative to ``scale``, that can pass as sampling noise:
        critical × the largest standard error over scale (NaN without sampling noise)."""
        noise = max(self.mean_noise, self.std_noise)
        return self.critical * noise / self.scale if self.scale > 0 else float("nan")

    def verdict(self) -> str:
        """Whether the differences are explained by sampling noise or the chaos tolerance.

        ``"within noise"`` when the mean and std z-scores stay below ``critical`` at every
        time, ``"beyond noise"`` otherwise; without sampling noise ``"within tolerance"``
        or ``"beyond tolerance"``; ``"not finite at K times"`` when statistics are NaN or
        inf at some times.
        """
        if self.not_finite:
            return f"not finite at {self.not_finite} times"
        kind = "noise" if self.runs else "tolerance"
        return f"{'within' if np.isnan(self.departure) else 'beyond'} {kind}"

    def departure_note(self) -> str:
        """When the two part and what that time means ("" when they never do)."""
        if np.isnan(self.departure):
            return ""
        if not self.runs:
            return (
                f"departs at t = {self.departure:.4g} (difference above the chaos tolerance "
                f"{self.tolerance:g} of the largest std)"
            )
        twin = " and ".join(f"{count}" for count in self.runs)
        return (
            f"departs at t = {self.departure:.4g} (resolution of a Monte Carlo twin of {twin} "
            f"runs: differences up to {self.resolution:.2g} of the largest std pass as noise; "
            "more runs resolve smaller ones, and the departure comes earlier)"
        )


@dataclass(frozen=True)
class Comparison:
    """Statistics of ``other`` against ``reference``, per output (in the reference's order)."""

    reference: str
    other: str
    differences: dict[str, OutputDifference]

    def table(self) -> str:
        """The differences as a fixed-width text table, then when each output departs."""
        lines = [
            f"reference  {self.reference}",
            f"other      {self.other}",
            f"{'output':<12}{'|Δmean| max':>13}{'rms':>11}{'rel':>9}{'noise':>11}"
            f"{'|Δstd| max':>13}{'rms':>11}{'rel':>9}{'noise':>11}{'worst z':>9}{'crit z':>8}"
            f"{'departs':>9}  verdict",
        ]
        for name, d in self.differences.items():
            lines.append(
                f"{name:<12}{d.mean_max:>13.4g}{d.mean_rms:>11.4g}{d.mean_relative:>9.3g}"
                f"{d.mean_noise:>11.4g}{d.std_max:>13.4g}{d.std_rms:>11.4g}"
                f"{d.std_relative:>9.3g}{d.std_noise:>11.4g}{max(d.mean_z, d.std_z):>9.3g}"
                f"{d.critical:>8.3g}{d.departure:>9.3g}  {d.verdict()}"
            )
        lines += [
            f"{name}: {d.departure_note()}"
            for name, d in self.differences.items()
            if d.departure_note()
        ]
        return "\n".join(lines)


def _z_scores(
    gap: NDArray[np.float64], noise: NDArray[np.float64], scale: float
) -> NDArray[np.float64] | None:
    """(T,) gap / noise; gaps at round-off level where there is no noise (e.g. a fixed
    initial state) count as zero. ``None`` when there is no noise at all."""
    if not np.any(noise > 0):
        return None
    gap = np.where(gap <= _ROUND_OFF * scale, 0.0, gap)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(gap == 0.0, 0.0, gap / noise)


def _largest(values: NDArray[np.float64]) -> float:
    """max of the values (NaN when there are none)."""
    return float(np.max(values)) if values.size else float("nan")


def _rms(values: NDArray[np.float64]) -> float:
    """sqrt(mean(values²)), of values divided by a power of two near their largest magnitude
    where their squares would overflow or underflow (NaN when there are none)."""
    if not values.size:
        return float("nan")
    if not unsafe_to_square(values):
        return float(np.sqrt(np.mean(values**2)))
    scale = power_of_two(np.max(np.abs(values)))
    return float(np.sqrt(np.mean((values / scale) ** 2)) * scale)


def _departure(times: NDArray[np.float64], excess: NDArray[np.float64], limit: float) -> float:
    """The first time at which ``excess`` passes ``limit`` (NaN if never)."""
    outside = np.flatnonzero(excess > limit)
    return float(times[outside[0]]) if outside.size else float("nan")


def _check_grids(reference: StudyResult, other: StudyResult) -> None:
    a, b = reference.times, other.times
    if a.shape != b.shape or not np.allclose(a, b, rtol=1e-9, atol=1e-12 * np.ptp(a)):
        raise UsageError(
            f"the results have different time grids ({a[0]}..{a[-1]}, {a.size} points vs "
            f"{b[0]}..{b[-1]}, {b.size} points): compare studies run on the same grid"
        )


def _check_axes(reference: StudyResult, other: StudyResult, name: str) -> None:
    """Output ``name`` must lie on the same points in both (time, one axis, or a scalar)."""
    a, b = reference.axis(name), other.axis(name)
    if reference.on_time(name) and other.on_time(name):
        return
    if a is None and b is None:
        return
    if a is None or b is None or not a.same(b):
        raise UsageError(
            f"output {name!r} lies on different axes in the two results: compare studies "
            "whose outputs have the same points"
        )


def common_outputs(results: Sequence[StudyResult]) -> list[str]:
    """Outputs present in every result, in the first one's order.

    Raises
    ------
    UsageError
        If there is none.
    """
    names = [n for n in results[0].outputs if all(n in r.outputs for r in results[1:])]
    if not names:
        raise UsageError("the results share no output: nothing to compare")
    return names


def compare(
    reference: StudyResult,
    other: StudyResult,
    *,
    labels: tuple[str, str] | None = None,
) -> Comparison:
    """Differences of mean and std over time, per output both results have, with a verdict:
    against the sampling noise (family-wise over time) when either result samples, else
    against the files' chaos tolerance (module docstring).

    Parameters
    ----------
    reference, other:
        Two results on the same time grid.
    labels:
        Names for the two (default: :func:`method_label`).

    Returns
    -------
    Comparison

    Raises
    ------
    UsageError
        If the time grids differ or no output is shared.
    """
    _check_grids(reference, other)
    differences = {}
    pair = (reference, other)
    for name in common_outputs(pair):
        _check_axes(reference, other, name)
        statistics = [r.mean(name) for r in pair]
        statistics += [r.std(name) for r in pair]
        finite = np.logical_and.reduce([np.isfinite(s) for s in statistics])
        with np.errstate(over="ignore", invalid="ignore"):
            mean_gap = np.abs(other.mean(name) - reference.mean(name))
            std_gap = np.abs(other.std(name) - reference.std(name))
            noise = [sampling_noise(r, name) for r in pair]
            mean_noise = np.hypot(noise[0][0], noise[1][0])
            std_noise = np.hypot(noise[0][1], noise[1][1])
        if not finite.all():  # leave those times out of every figure below
            mean_gap, std_gap = mean_gap[finite], std_gap[finite]
            mean_noise, std_noise = mean_noise[finite], std_noise[finite]
        scale = _largest(reference.std(name)[finite])
        mean_z = _z_scores(mean_gap, mean_noise, scale)
        std_z = _z_scores(std_gap, std_noise, scale)
        times = reference.grid(name)[finite]
        if mean_z is not None and std_z is not None:  # sampling noise: the family-wise test
            runs = tuple(int(np.sum(r.ok)) for r in pair if _sampled(r, name) is not None)
            critical, tolerance = _critical(pair, name, finite), float("nan")
            departure = _departure(times, np.maximum(mean_z, std_z), critical)
        else:  # two quadratures: the gaps against the chaos tolerance
            runs, critical, tolerance = (), float("nan"), _tolerance(pair, name)
            gap = np.maximum(mean_gap, std_gap)
            with np.errstate(divide="ignore", invalid="ignore"):
                relative = np.where(gap <= _ROUND_OFF * scale, 0.0, gap / scale)
            departure = _departure(times, relative, tolerance)
        differences[name] = OutputDifference(
            mean_max=_largest(mean_gap),
            mean_rms=_rms(mean_gap),
            std_max=_largest(std_gap),
            std_rms=_rms(std_gap),
            scale=scale,
            mean_noise=_largest(mean_noise),
            std_noise=_largest(std_noise),
            mean_z=float("nan") if mean_z is None else _largest(mean_z),
            std_z=float("nan") if std_z is None else _largest(std_z),
            critical=critical,
            tolerance=tolerance,
            departure=departure,
            runs=runs,
            not_finite=int(np.sum(~finite)),
        )
    names = labels or (method_label(reference), method_label(other))
    return Comparison(names[0], names[1], differences)
