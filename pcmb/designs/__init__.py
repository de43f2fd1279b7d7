"""Node designs: how a method makes its nodes and turns runs into coefficients.

:data:`DESIGNS` maps every ``method.kind`` to its design class (see
:class:`~pcmb.designs.base.NodeDesign`). A new method is one module here, one entry below and
its tests.
"""

from __future__ import annotations

from collections.abc import Mapping

from pcmb.chaos.inputs import Distribution
from pcmb.designs.base import (
    RECORDED_ONLY,
    MethodSettings,
    NodeDesign,
    Recovery,
    statistics_warnings,
)
from pcmb.designs.collocation import TensorCollocation
from pcmb.designs.sampling import Sampling

__all__ = [
    "DESIGNS",
    "RECORDED_ONLY",
    "MethodSettings",
    "NodeDesign",
    "Recovery",
    "make_design",
    "statistics_warnings",
]

#: ``method.kind`` -> design class; the config schema, ``pcmb validate`` and the docs read
#: their lists from here.
DESIGNS: dict[str, type[NodeDesign]] = {
    "collocation": TensorCollocation,
    "montecarlo": Sampling,
    "lhs": Sampling,
    "sobol": Sampling,
}


def make_design(inputs: Mapping[str, Distribution], settings: MethodSettings) -> NodeDesign:
    """The design registered for ``settings.kind``, built for these inputs.

    Raises
    ------
    ValueError
        An unknown kind, or settings the design cannot use (the message starts with the key).
    """
    design = DESIGNS.get(settings.kind)
    if design is None:
        known = ", ".join(DESIGNS)
        raise ValueError(f"method.kind: expected one of {known}, got {settings.kind!r}")
    return design(inputs, settings)
