"""Node designs: how a method makes its nodes and turns runs into coefficients.

:data:`DESIGNS` maps every ``method.kind`` to its design class (see
:class:`~pcmb.designs.base.NodeDesign`). A new method is one module here, one entry below and
its tests.
"""

from __future__ import annotations

import typing
from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import Field, TypeAdapter

from pcmb.chaos.inputs import Distribution
from pcmb.designs.adaptive import AdaptiveCollocation, AdaptiveReport
from pcmb.designs.anisotropic import AnisotropicTensor
from pcmb.designs.base import (
    RECORDED_ONLY,
    IntrusiveDesign,
    MethodSection,
    MethodSettings,
    MomentReport,
    NodeDesign,
    Recovery,
    statistics_warnings,
)
from pcmb.designs.collocation import GRIDS, TensorCollocation
from pcmb.designs.galerkin import Galerkin
from pcmb.designs.halton import HaltonSampling
from pcmb.designs.linearization import Linearization
from pcmb.designs.multi_element import ElementReport, MultiElementCollocation
from pcmb.designs.refine import OrderRefinement, RefinementReport
from pcmb.designs.regression import RegressionReport, SparseRegression
from pcmb.designs.sampling import Sampling
from pcmb.designs.smolyak import SparseCollocation
from pcmb.result import DesignReport

__all__ = [
    "DESIGNS",
    "GRIDS",
    "METHOD_KINDS",
    "RECORDED_ONLY",
    "REPORTS",
    "IntrusiveDesign",
    "MethodSection",
    "MethodSettings",
    "MethodSpec",
    "NodeDesign",
    "Recovery",
    "design_key",
    "make_design",
    "method_section",
    "section_key",
    "statistics_warnings",
]

#: Design key -> design class: ``method.kind``, or ``collocation:<grid>`` for a collocation
#: grid other than the tensor one, ``collocation:elements`` for multi-element collocation or
#: ``collocation:refine`` for ``order: auto``, ``adaptive:tensor`` for an adaptive tensor grid
#: (``basis: tensor``) (see :func:`design_key`). The config schema,
#: ``pcmb validate`` and the docs read their lists from here.
DESIGNS: dict[str, type[NodeDesign] | type[IntrusiveDesign]] = {
    "collocation": TensorCollocation,
    "collocation:smolyak": SparseCollocation,
    "collocation:elements": MultiElementCollocation,
    "collocation:refine": OrderRefinement,
    "montecarlo": Sampling,
    "lhs": Sampling,
    "sobol": Sampling,
    "regression": SparseRegression,
    "adaptive": AdaptiveCollocation,
    "adaptive:tensor": AnisotropicTensor,
    "halton": HaltonSampling,
    # Intrusive methods (pcmb.designs.base.IntrusiveDesign): no nodes; solved from the
    # model's polynomial form in a worker.
    "galerkin": Galerkin,
    "linearization": Linearization,
}
#: Report key -> what a design concludes beyond its expansions (a
#: :class:`~pcmb.result.DesignReport`), which the result file, ``pcmb inspect`` and the report
#: leave to it: a design with a report of its own adds it here.
REPORTS: dict[str, type[DesignReport]] = {
    report.key: report
    for report in (RegressionReport, AdaptiveReport, RefinementReport, ElementReport, MomentReport)
}
#: ``method.kind`` values.
METHOD_KINDS = tuple(dict.fromkeys(key.partition(":")[0] for key in DESIGNS))
#: The ``method:`` section: one member per design family (each design's ``Settings``), tagged
#: by ``kind``, each with only its own keys.
MethodSpec = Annotated[
    typing.Union[tuple(dict.fromkeys(design.Settings for design in DESIGNS.values()))],  # noqa: UP007
    Field(discriminator="kind"),
]
_METHOD = TypeAdapter(MethodSpec)


def method_section(data: Mapping[str, Any] | MethodSection) -> MethodSection:
    """The ``method:`` section of this data (a section is returned as it is).

    Raises
    ------
    pydantic.ValidationError
        Data no section takes (:func:`pcmb.config.messages.schema_problems` locates it).
    """
    return data if isinstance(data, MethodSection) else _METHOD.validate_python(data)


def section_key(section: MethodSection) -> str:
    """The :data:`DESIGNS` key of a ``method:`` section, e.g. ``collocation:smolyak``."""
    order = getattr(section, "order", None)
    return design_key(section.settings("auto" if order == "auto" else None))


def design_key(settings: MethodSettings) -> str:
    """The :data:`DESIGNS` key of these settings."""
    if settings.kind == "collocation":
        if settings.elements is not None:
            return "collocation:elements"
        if settings.grid != "tensor":
            return f"collocation:{settings.grid}"
        if settings.orders == "auto":
            return "collocation:refine"
    if settings.kind == "adaptive" and settings.basis == "tensor":
        return "adaptive:tensor"
    return settings.kind


def make_design(inputs: Mapping[str, Distribution], settings: MethodSettings) -> NodeDesign:
    """The design registered for these settings, built for these inputs.

    Raises
    ------
    ValueError
        Settings the design cannot use on these inputs (the message starts with the key); the
        keys themselves were checked by their section (:data:`MethodSpec`).
    """
    if settings.elements is not None and settings.grid != "tensor":
        raise ValueError(
            "method.elements: multi-element collocation uses tensor grids (grid: tensor)"
        )
    key = design_key(settings)
    if settings.orders == "auto" and key != "collocation:refine":
        raise ValueError(
            "method.order: auto refines single-element tensor collocation (kind collocation, "
            "grid tensor, no elements)"
        )
    return DESIGNS[key](inputs, settings)
