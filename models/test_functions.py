"""Scalar test functions of uncertainty quantification, as pcmb models of one number per run.

``Ishigami`` (Ishigami & Homma 1990; three inputs on [-π, π], closed-form moments and Sobol'
indices in ``pcmb.references.ishigami_moments``) and ``Borehole`` (Harper & Gupta 1983; eight
inputs, ``pcmb.references.borehole_bounds``). Each returns its output ``y`` as shape (B,): a
scalar per run (``output_axes``), not a time series.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from pcmb.references import borehole, borehole_bounds, ishigami

BOREHOLE_INPUTS = ("rw", "r", "Tu", "Hu", "Tl", "Hl", "L", "Kw")


def _stacked(params, nominal, names):
    """(B, len(names)) the inputs in order, nominal values where a name is not varied."""
    size = max(np.size(v) for v in params.values()) if params else 1
    return np.column_stack(
        [np.broadcast_to(np.asarray(params.get(n, nominal[n]), float), (size,)) for n in names]
    )


class Ishigami:
    """y = sin x1 + a sin² x2 + b x3⁴ sin x1."""

    outputs: ClassVar = ("y",)
    output_axes: ClassVar = {"y": None}

    def __init__(self, a=7.0, b=0.1, x1=0.0, x2=0.0, x3=0.0):
        self.a, self.b = a, b
        self.parameters = {"x1": x1, "x2": x2, "x3": x3}

    def simulate(self, params, times):
        x = _stacked(params, self.parameters, ("x1", "x2", "x3"))
        return {"y": ishigami(x, self.a, self.b)}


class Borehole:
    """The flow through a borehole, m³/year; nominal values at the middle of the ranges."""

    outputs: ClassVar = ("y",)
    output_axes: ClassVar = {"y": None}

    def __init__(self, **nominal):
        middle = {
            n: sum(bounds) / 2 for n, bounds in zip(BOREHOLE_INPUTS, borehole_bounds(), strict=True)
        }
        self.parameters = {**middle, **nominal}

    def simulate(self, params, times):
        return {"y": borehole(_stacked(params, self.parameters, BOREHOLE_INPUTS))}
