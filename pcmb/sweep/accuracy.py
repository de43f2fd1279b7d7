"""Errors of a method's statistics against a reference, and the reference's own noise floor.

Every error is relative to the largest standard deviation of the reference over time:
``err_mean = max_t |mean(t) - mean_ref(t)| / max_t std_ref(t)`` (the same for the std), and
the RMS over time of the same curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.comparison import sampling_noise
from pcmb.result import StudyResult

__all__ = ["Errors", "errors", "noise_floor", "result_errors"]


@dataclass(frozen=True)
class Errors:
    """The errors of one output.

    Attributes
    ----------
    mean_curve, std_curve:
        (T,) |Δmean(t)| and |Δstd(t)| over the reference's largest std.
    mean, std:
        Their maxima over time (NaN when a statistic is not finite somewhere).
    mean_rms, std_rms:
        Their RMS over time.
    """

    mean_curve: NDArray[np.float64]
    std_curve: NDArray[np.float64]
    mean: float
    std: float
    mean_rms: float
    std_rms: float


def _scale(reference_std: NDArray[np.float64]) -> float:
    scale = float(np.max(reference_std))
    return scale if scale > 0 else float("nan")


def _max(curve: NDArray[np.float64]) -> float:
    return float(np.max(curve)) if np.all(np.isfinite(curve)) else float("nan")


def _rms(curve: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(curve**2))) if np.all(np.isfinite(curve)) else float("nan")


def errors(
    mean: NDArray[np.float64],
    std: NDArray[np.float64],
    reference_mean: NDArray[np.float64],
    reference_std: NDArray[np.float64],
) -> Errors:
    """Errors of ``mean`` and ``std`` (T,) against the reference's (T,).

    Differences are divided by the largest reference std before anything is squared, so
    outputs near 1e200 give finite errors; a reference that does not vary gives NaN.
    """
    scale = _scale(np.asarray(reference_std, dtype=float))
    with np.errstate(over="ignore", invalid="ignore"):
        mean_curve = np.abs(np.asarray(mean) - reference_mean) / scale
        std_curve = np.abs(np.asarray(std) - reference_std) / scale
    return Errors(
        mean_curve, std_curve, _max(mean_curve), _max(std_curve), _rms(mean_curve), _rms(std_curve)
    )


def result_errors(result: StudyResult, reference: StudyResult, output: str) -> Errors:
    """:func:`errors` of one output of two results on the same time grid."""
    return errors(
        result.mean(output), result.std(output), reference.mean(output), reference.std(output)
    )


def noise_floor(reference: StudyResult, output: str) -> tuple[float, float]:
    """The largest standard error of the reference's mean and std over its largest std:
    errors below it cannot be measured (0 for a quadrature reference)."""
    mean_noise, std_noise = sampling_noise(reference, output)
    scale = _scale(reference.std(output))
    return float(np.max(mean_noise) / scale), float(np.max(std_noise) / scale)
