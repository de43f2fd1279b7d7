"""Figures of merit derived from time outputs after the runs (the config's ``derived:``).

Each figure kind is one small function in :data:`FIGURES`, from a time output's runs
``(N, T)`` on the grid ``(T,)`` to one number per run ``(N,)``. A derived output is then a
scalar output like any other (:mod:`pcmb.axes`): it gets statistics, Sobol' indices, PDFs
and diagnostics. Definitions are in ``docs/config.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pcmb.errors import ConfigError, ConfigProblem

__all__ = ["FIGURES", "DerivedOutput", "Figure", "derive", "derived_problems", "parse_derived"]

_Function = Callable[..., NDArray[np.float64]]


@dataclass(frozen=True)
class Figure:
    """One figure kind: its function, what it is, and its options (name -> default,
    ``None``: required; name -> description).

    ``function(times, values, **options)`` maps (T,) and (N, T) to (N,).
    """

    function: _Function
    summary: str
    options: Mapping[str, float | None] = field(default_factory=dict)
    descriptions: Mapping[str, str] = field(default_factory=dict)


def max_abs(times: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) the largest |y| over the grid."""
    return np.max(np.abs(values), axis=1)


def rms(times: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) root mean square over [t_0, t_T]: sqrt of the trapezoid integral of y² over the
    duration."""
    return np.sqrt(np.trapezoid(values**2, times, axis=1) / (times[-1] - times[0]))


def at(times: NDArray[np.float64], values: NDArray[np.float64], time: float) -> NDArray[np.float64]:
    """(N,) y at ``time``, linear between the grid points around it."""
    j = int(np.clip(np.searchsorted(times, time, side="right") - 1, 0, times.size - 2))
    share = (time - times[j]) / (times[j + 1] - times[j])
    return values[:, j] + share * (values[:, j + 1] - values[:, j])


def settling_time(
    times: NDArray[np.float64], values: NDArray[np.float64], band: float
) -> NDArray[np.float64]:
    """(N,) the time the run last leaves the band |y - y_T| <= band |y_T| around its final
    value y_T; linear between the last grid point outside and the next; t_0 if never
    outside."""
    final = values[:, -1:]
    excess = np.abs(values - final) - band * np.abs(final)  # > 0: outside the band
    outside = excess > 0
    last = np.where(outside.any(axis=1), times.size - 1 - np.argmax(outside[:, ::-1], axis=1), -1)
    found = np.full(values.shape[0], times[0])
    rows = np.flatnonzero((last >= 0) & (last < times.size - 1))
    j = last[rows]
    before, after = excess[rows, j], excess[rows, j + 1]
    found[rows] = times[j] + before / (before - after) * (times[j + 1] - times[j])
    return np.where(np.isfinite(values).all(axis=1), found, np.nan)


#: Figure kind (the config key) -> :class:`Figure`.
FIGURES: dict[str, Figure] = {
    "max_abs": Figure(max_abs, "largest |y| over the time grid"),
    "rms": Figure(
        rms, "root mean square over [start, stop]: sqrt(trapezoid integral of y² / duration)"
    ),
    "at": Figure(
        at,
        "y at option `time`, linear between the grid points around it",
        {"time": None},
        {"time": "time of `at`, within the grid (required by `at`)"},
    ),
    "settling_time": Figure(
        settling_time,
        "settling time: the last time y is outside the band |y - y_T| <= band·|y_T| around "
        "its final value y_T = y(stop), linear between the grid points around that exit "
        "(start if never outside)",
        {"band": 0.02},
        {"band": "relative half-width of the band of `settling_time` (> 0; default 0.02)"},
    ),
}


@dataclass(frozen=True)
class DerivedOutput:
    """One ``derived:`` entry: figure ``kind`` of time output ``source`` with ``options``."""

    kind: str
    source: str
    options: Mapping[str, float] = field(default_factory=dict)

    def compute(self, times: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray:
        """(N, 1) the figure of each run (N, T) (NaN for NaN runs)."""
        with np.errstate(invalid="ignore"):
            return FIGURES[self.kind].function(times, values, **self.options)[:, None]


def parse_derived(section: Mapping[str, Any], key: str = "derived") -> dict[str, DerivedOutput]:
    """The ``derived:`` section as :class:`DerivedOutput` s.

    Raises
    ------
    ConfigError
        Every problem at its key (``derived.x1_peak.max_abs``, ``derived.x1_peak``...).
    """
    found, problems = {}, []
    for name, entry in section.items():
        where = f"{key}.{name}"
        if not isinstance(entry, Mapping):
            problems.append(ConfigProblem(where, f"expected a mapping, found {entry!r}"))
            continue
        kinds = [k for k in entry if k in FIGURES]
        if len(kinds) != 1:
            problems.append(
                ConfigProblem(
                    where,
                    f"needs exactly one figure kind of {', '.join(FIGURES)}; found "
                    f"{', '.join(map(str, kinds)) or 'none'}",
                )
            )
            continue
        kind = kinds[0]
        figure = FIGURES[kind]
        if not isinstance(entry[kind], str):
            problems.append(ConfigProblem(f"{where}.{kind}", "expected the name of a time output"))
        options: dict[str, float] = {}
        for option, default in figure.options.items():
            value = entry.get(option, default)
            if value is None:
                problems.append(ConfigProblem(f"{where}.{option}", f"required by {kind}"))
            elif isinstance(value, bool) or not isinstance(value, int | float):
                problems.append(
                    ConfigProblem(f"{where}.{option}", f"expected a number, found {value!r}")
                )
            else:
                options[option] = float(value)
        for other in entry:
            if other != kind and other not in figure.options:
                known = ", ".join(figure.options) or "none"
                problems.append(
                    ConfigProblem(
                        f"{where}.{other}", f"unknown option of {kind} (options: {known})"
                    )
                )
        if "band" in options and not options["band"] > 0:
            problems.append(ConfigProblem(f"{where}.band", f"must be > 0, found {options['band']}"))
        found[name] = DerivedOutput(kind, str(entry[kind]), options)
    if problems:
        raise ConfigError(problems)
    return found


def derived_problems(
    derived: Mapping[str, DerivedOutput],
    outputs: tuple[str, ...],
    on_time: tuple[str, ...],
    times: NDArray[np.float64],
    key: str = "derived",
) -> list[tuple[str, str]]:
    """``(key path, message)`` of derived outputs that name no time output, clash with an
    output, or ask for a time off the grid; ``outputs`` are the kept outputs and ``on_time``
    those of them on the time grid."""
    problems = []
    for name, entry in derived.items():
        where = f"{key}.{name}"
        if name in outputs:
            problems.append((where, f"{name!r} is already an output of the model"))
        if entry.source not in outputs:
            problems.append(
                (
                    f"{where}.{entry.kind}",
                    f"{entry.source!r} is not an output; outputs are {', '.join(outputs)}",
                )
            )
        elif entry.source not in on_time:
            problems.append((f"{where}.{entry.kind}", f"{entry.source!r} is not a time output"))
        if entry.kind in ("rms", "at") and times.size < 2:
            problems.append((where, f"{entry.kind} needs at least two time points"))
        instant = entry.options.get("time")
        if instant is not None and not times[0] <= instant <= times[-1]:
            problems.append(
                (f"{where}.time", f"{instant:g} is outside the grid [{times[0]:g}, {times[-1]:g}]")
            )
    return problems


def derive(
    derived: Mapping[str, DerivedOutput],
    times: NDArray[np.float64],
    values: Mapping[str, NDArray[np.float64]],
) -> dict[str, NDArray[np.float64]]:
    """Derived output name -> (N, 1) its figure of every run of ``values`` (N, T)."""
    return {name: entry.compute(times, values[entry.source]) for name, entry in derived.items()}
