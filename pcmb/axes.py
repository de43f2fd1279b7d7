"""The axis an output lives on: the study's time grid, an axis of its own, or none (a scalar).

A model's outputs are time series, ``(B, T)`` on the study's grid, unless it declares
otherwise through the optional ``output_axes`` attribute of the model protocol
(:class:`pcmb.adapters.protocol.Model`): output name -> :class:`OutputAxis` (returned as
``(B, K)`` on that axis) or ``None`` (a scalar per run, returned as ``(B,)``).

Inside pcmb every output is stored as ``(N, W)``: ``W = T`` on time, ``K`` on its own axis,
``1`` for a scalar; the result file drops the length-1 axis of a scalar.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FREQUENCY_UNITS", "TIME", "OutputAxis", "axis_problems"]

#: The name of the study's own axis.
TIME = "time"
#: Units that make an axis a frequency axis (drawn on log axes).
FREQUENCY_UNITS = frozenset({"Hz", "kHz", "MHz", "GHz", "rad/s", "1/s"})
#: Names an output axis cannot take: the other dimension scales of the result file.
_RESERVED = frozenset(
    {TIME, "node", "input", "term", "quantile", "element", "validation_run", "point"}
)


@dataclass(frozen=True, eq=False)
class OutputAxis:
    """An axis of an output's own (frequency of a sweep, position along a beam...).

    Attributes
    ----------
    name:
        Its name, the dimension's name in the result file (``"frequency"``).
    values:
        (K,) its points, strictly increasing and finite.
    unit:
        Unit text (``"Hz"``); a frequency unit (:data:`FREQUENCY_UNITS`) draws it on log
        axes.

    Raises
    ------
    ValueError
        An empty or reserved name, or values that are not a strictly increasing finite
        (K,) array.
    """

    name: str
    values: NDArray[np.float64]
    unit: str = ""

    def __init__(self, name: str, values: ArrayLike, unit: str = "") -> None:
        array = np.array(values, dtype=np.float64)
        array.flags.writeable = False
        if not isinstance(name, str) or not name.isidentifier() or name in _RESERVED:
            raise ValueError(
                f"axis name {name!r} must be an identifier other than {sorted(_RESERVED)}"
            )
        if array.ndim != 1 or array.size == 0 or not np.isfinite(array).all():
            raise ValueError(f"axis {name!r}: values must be a non-empty finite (K,) array")
        if np.any(np.diff(array) <= 0):
            raise ValueError(f"axis {name!r}: values must increase strictly")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "values", array)
        object.__setattr__(self, "unit", str(unit))

    @property
    def is_frequency(self) -> bool:
        """Whether the unit is a frequency (figures use log axes)."""
        return self.unit in FREQUENCY_UNITS

    def same(self, other: OutputAxis) -> bool:
        """Same name, unit and points."""
        return (
            self.name == other.name
            and self.unit == other.unit
            and np.array_equal(self.values, other.values)
        )


def axis_problems(axes: Mapping[str, OutputAxis | None], outputs: tuple[str, ...]) -> list[str]:
    """What is wrong with a model's ``output_axes``: entries naming no output, values that
    are not axes, or two axes of one name with different points."""
    problems = []
    seen: dict[str, OutputAxis] = {}
    for name, axis in axes.items():
        if name not in outputs:
            problems.append(f"output_axes names {name!r}, which is not an output")
        elif axis is not None and not isinstance(axis, OutputAxis):
            problems.append(f"output_axes[{name!r}] is a {type(axis).__name__}, not an OutputAxis")
        elif axis is not None:
            first = seen.setdefault(axis.name, axis)
            if not first.same(axis):
                problems.append(f"two different axes are named {axis.name!r}")
    return problems
