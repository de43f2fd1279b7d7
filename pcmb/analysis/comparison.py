"""How far apart two studies of the same model are (chaos against Monte Carlo, ...), in
units of the reference's largest std and of the sampling noise (``docs/architecture.md``).

Statistics that are not finite (NaN or inf) are left out of the maxima and RMS values and
counted (:attr:`OutputDifference.not_finite`); the verdict then says so. Nothing here
overflows for outputs whose own statistics are finite (powers are taken of scaled values).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.expansion import sample_mean, unsafe_to_square
from pcmb.errors import UsageError
from pcmb.result import StudyResult

__all__ = ["NOISE_FACTOR", "Comparison", "OutputDifference", "compare", "method_label"]

#: A difference is "within noise" below this many standard errors. The largest of T noisy
#: time points exceeds 4 standard errors with probability about T · 6e-5 (under 2 % for
#: 300 independent points; neighbouring times are correlated, so fewer really count).
NOISE_FACTOR = 4.0
#: Differences below this fraction of the reference's largest std are round-off.
_ROUND_OFF = 1e-9
#: Magnitudes whose 4th powers may overflow (1e75⁴ = 1e300) or, inverted, underflow.
_FOURTH = 1e75


def method_label(result: StudyResult) -> str:
    """A short description of how a result was computed, e.g. ``collocation, tensor order 5
    (216 runs)``."""
    return f"{result.design.label} ({int(np.sum(result.ok))} runs)"


def _noise(result: StudyResult, name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(T,) standard errors of a result's mean and std: zero for a collocation grid."""
    if result.weights is None:
        runs = result.values[name][result.ok]
        count = runs.shape[0]
        if count >= 2:
            centred = runs - sample_mean(runs)
            # The kurtosis does not depend on the scale: where 4th powers would overflow or
            # underflow, they are taken of the values divided by a power of two near their
            # largest magnitude (exact, so the digits are those of the plain arithmetic).
            top = np.max(np.abs(centred), axis=0)
            risky = np.isfinite(top) & ((top > _FOURTH) | ((top < 1.0 / _FOURTH) & (top > 0)))
            if risky.any():
                top = np.where(risky, top, 1.0)
                centred = centred / np.where(risky, np.ldexp(1.0, np.frexp(top)[1] - 1), 1.0)
            second = np.mean(centred**2, axis=0)
            with np.errstate(divide="ignore", invalid="ignore"):
                kurtosis = np.where(second > 0, np.mean(centred**4, axis=0) / second**2, 1.0)
            std = result.std(name)
            return std / np.sqrt(count), std * np.sqrt(
                np.maximum(kurtosis - 1.0, 0.0) / (4 * count)
            )
    zero = np.zeros(result.times.size)
    return zero, zero


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
    departure:
        The first time at which the mean or the std leaves NOISE_FACTOR standard errors
        (NaN without sampling noise or if it never does): how long the two agree.
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
    departure: float
    not_finite: int = 0

    @property
    def mean_relative(self) -> float:
        """mean_max / scale (NaN when the reference does not vary)."""
        return self.mean_max / self.scale if self.scale > 0 else float("nan")

    @property
    def std_relative(self) -> float:
        """std_max / scale (NaN when the reference does not vary)."""
        return self.std_max / self.scale if self.scale > 0 else float("nan")

    def verdict(self) -> str:
        """Whether the differences are explained by sampling noise.

        ``"within noise"`` when the mean and the std differences stay below NOISE_FACTOR
        standard errors at every time, ``"beyond noise"`` otherwise, ``"no sampling noise"``
        when both results come from collocation grids (then read the relative columns),
        ``"not finite at K times"`` when statistics are NaN or inf at some times.
        """
        if self.not_finite:
            return f"not finite at {self.not_finite} times"
        if np.isnan(self.mean_z):
            return "no sampling noise"
        within = self.mean_z <= NOISE_FACTOR and self.std_z <= NOISE_FACTOR
        return "within noise" if within else "beyond noise"


@dataclass(frozen=True)
class Comparison:
    """Statistics of ``other`` against ``reference``, per output (in the reference's order)."""

    reference: str
    other: str
    differences: dict[str, OutputDifference]

    def table(self) -> str:
        """The differences as a fixed-width text table."""
        lines = [
            f"reference  {self.reference}",
            f"other      {self.other}",
            f"{'output':<12}{'|Δmean| max':>13}{'rms':>11}{'rel':>9}{'noise':>11}"
            f"{'|Δstd| max':>13}{'rms':>11}{'rel':>9}{'noise':>11}{'worst z':>9}{'departs':>9}"
            "  verdict",
        ]
        for name, d in self.differences.items():
            lines.append(
                f"{name:<12}{d.mean_max:>13.4g}{d.mean_rms:>11.4g}{d.mean_relative:>9.3g}"
                f"{d.mean_noise:>11.4g}{d.std_max:>13.4g}{d.std_rms:>11.4g}"
                f"{d.std_relative:>9.3g}{d.std_noise:>11.4g}"
                f"{max(d.mean_z, d.std_z):>9.3g}{d.departure:>9.3g}  {d.verdict()}"
            )
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
    scale = np.ldexp(1.0, np.frexp(np.max(np.abs(values)))[1] - 1)
    return float(np.sqrt(np.mean((values / scale) ** 2)) * scale)


def _departure(times: NDArray[np.float64], *scores: NDArray[np.float64] | None) -> float:
    if scores[0] is None:
        return float("nan")
    outside = np.flatnonzero(np.maximum.reduce(scores) > NOISE_FACTOR)
    return float(times[outside[0]]) if outside.size else float("nan")


def _check_grids(reference: StudyResult, other: StudyResult) -> None:
    a, b = reference.times, other.times
    if a.shape != b.shape or not np.allclose(a, b, rtol=1e-9, atol=1e-12 * np.ptp(a)):
        raise UsageError(
            f"the results have different time grids ({a[0]}..{a[-1]}, {a.size} points vs "
            f"{b[0]}..{b[-1]}, {b.size} points): compare studies run on the same grid"
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
    """Differences of mean and std over time, per output both results have.

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
    for name in common_outputs([reference, other]):
        statistics = [r.mean(name) for r in (reference, other)]
        statistics += [r.std(name) for r in (reference, other)]
        finite = np.logical_and.reduce([np.isfinite(s) for s in statistics])
        with np.errstate(over="ignore", invalid="ignore"):
            mean_gap = np.abs(other.mean(name) - reference.mean(name))
            std_gap = np.abs(other.std(name) - reference.std(name))
            noise = [_noise(r, name) for r in (reference, other)]
            mean_noise = np.hypot(noise[0][0], noise[1][0])
            std_noise = np.hypot(noise[0][1], noise[1][1])
        if not finite.all():  # leave those times out of every figure below
            mean_gap, std_gap = mean_gap[finite], std_gap[finite]
            mean_noise, std_noise = mean_noise[finite], std_noise[finite]
        scale = _largest(reference.std(name)[finite])
        mean_z = _z_scores(mean_gap, mean_noise, scale)
        std_z = _z_scores(std_gap, std_noise, scale)
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
            departure=_departure(reference.times[finite], mean_z, std_z),
            not_finite=int(np.sum(~finite)),
        )
    names = labels or (method_label(reference), method_label(other))
    return Comparison(names[0], names[1], differences)
