"""What the intrusive methods (Galerkin, statistical linearization) share: no nodes, and the
model's polynomial form, found or refused with a message naming ``method.kind``."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet
from pcmb.designs.polynomial_form import PolynomialForm
from pcmb.errors import ConfigError, ConfigProblem

__all__ = ["WithoutNodes", "form_problems", "polynomial_form"]


class WithoutNodes:
    """The node side of an intrusive design: no runs, an empty node set, no weights.
    Subclasses set ``distributions`` (germ order)."""

    distributions: tuple[Distribution, ...]
    runs = 0

    def nodes(self) -> NodeSet:
        empty = np.zeros((0, len(self.distributions)))
        return NodeSet(self.distributions, empty, empty.copy())

    def weights(self, nodes: NodeSet) -> None:
        return None


def _form(
    model: object, inputs: Sequence[str], kind: str
) -> tuple[PolynomialForm | None, list[tuple[str, str]]]:
    label = type(model).__name__
    declare = getattr(model, "polynomial_form", None)
    if not callable(declare):
        return None, [
            (
                "method.kind",
                f"{kind} needs a model that declares its polynomial form (a "
                f"polynomial_form(inputs) method, see docs/models.md); {label} has none",
            )
        ]
    try:
        form = declare(tuple(inputs))
    except ValueError as error:
        return None, [
            (
                "method.kind",
                f"{kind}: {label} has no polynomial form in inputs {list(inputs)}: {error}",
            )
        ]
    if not isinstance(form, PolynomialForm):
        return None, [
            (
                "method.kind",
                f"{kind}: {label}.polynomial_form returned {type(form).__name__}, "
                "not a PolynomialForm",
            )
        ]
    if form.space.input_names != tuple(inputs):
        return None, [
            (
                "method.kind",
                f"{kind}: {label}.polynomial_form has inputs "
                f"{list(form.space.input_names)}, the study {list(inputs)}",
            )
        ]
    return form, []


def form_problems(
    model: object, inputs: Sequence[str], outputs: Sequence[str] | None, kind: str
) -> list[tuple[str, str]]:
    """``(key, message)`` of what keeps ``kind`` from this model: no polynomial form, inputs
    that do not enter polynomially, or outputs (``None``: all the model's) it lacks."""
    form, problems = _form(model, inputs, kind)
    if form is None:
        return problems
    wanted = tuple(getattr(model, "outputs", ())) if outputs is None else tuple(outputs)
    missing = [name for name in wanted if name not in form.outputs]
    if missing:
        return [
            (
                "model.outputs",
                f"{kind}: output(s) {missing} have no polynomial form in "
                f"{type(model).__name__} (it has {list(form.outputs)})",
            )
        ]
    return []


def polynomial_form(
    model: object, inputs: Sequence[str], outputs: Sequence[str], kind: str
) -> PolynomialForm:
    """The model's polynomial form in these inputs.

    Raises
    ------
    ConfigError
        What :func:`form_problems` finds.
    """
    form, problems = _form(model, inputs, kind)
    problems = problems or form_problems(model, inputs, outputs, kind)
    if form is None or problems:
        raise ConfigError([ConfigProblem(key, message) for key, message in problems])
    return form
