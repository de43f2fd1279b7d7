"""Value types, limits and base classes shared by the config sections (schema and adapters)."""

from __future__ import annotations

import types
import typing
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
)
from pydantic_core import PydanticCustomError

if TYPE_CHECKING:
    from pcmb.adapters.protocol import ModelFactory

__all__ = [
    "MAX_RUNS",
    "MAX_VALUES",
    "ModelSection",
    "Name",
    "NameList",
    "NonNegativeInt",
    "NonNegativeReal",
    "OrderSpec",
    "Points",
    "PositiveInt",
    "PositiveReal",
    "Probability",
    "Real",
    "Section",
    "count",
    "reject_text_and_bool",
    "selecting_key",
    "tagged_by_key",
    "unique",
]

#: Largest number of model runs (collocation nodes or samples) a config may ask for.
MAX_RUNS = 10_000_000
#: Largest number of stored values per output (runs x time points): 8 GB of float64.
MAX_VALUES = 1_000_000_000


def reject_text_and_bool(expected: str) -> Callable[[Any], Any]:
    """A before-validator: numbers must be written as numbers, not ``"1.5"`` or ``true``."""

    def check(value: Any) -> Any:
        if isinstance(value, bool | str):
            raise PydanticCustomError("wrong_type", "expected {expected}", {"expected": expected})
        return value

    return check


def _identifier(value: str) -> str:
    if not value.isidentifier():
        raise ValueError(f"expected a name made of letters, digits and _, found {value!r}")
    return value


def unique(values: list[Any]) -> list[Any]:
    """An after-validator: no value listed twice."""
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"listed twice: {', '.join(map(str, repeated))}")
    return values


def _past_start(stop: float, info: ValidationInfo) -> float:
    start = info.data.get("start")
    if start is not None and not stop > start:
        raise ValueError(f"expected stop > start = {start!r}, found {stop!r}")
    return stop


def count(**bounds: int) -> Any:
    """An integer type with bounds; the bounds come before the validator so that they
    stay plain JSON Schema keywords (minimum, maximum)."""
    return Annotated[int, Field(**bounds), BeforeValidator(reject_text_and_bool("an integer"))]


Real = Annotated[float, BeforeValidator(reject_text_and_bool("a number"))]
PositiveReal = Annotated[float, Field(gt=0), BeforeValidator(reject_text_and_bool("a number"))]
NonNegativeReal = Annotated[float, Field(ge=0), BeforeValidator(reject_text_and_bool("a number"))]
#: The end of a section's span: a number past its ``start`` (a field declared before it).
Stop = Annotated[Real, AfterValidator(_past_start)]
Probability = Annotated[float, Field(gt=0, lt=1), BeforeValidator(reject_text_and_bool("a number"))]
NonNegativeInt = count(ge=0)
PositiveInt = count(ge=1)
Points = count(ge=2, le=MAX_RUNS)
Name = Annotated[str, AfterValidator(_identifier)]
NameList = Annotated[list[Name], Field(min_length=1), AfterValidator(unique)]


class Section(BaseModel):
    """Base of every config section: unknown keys are errors, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class ModelSection(Section, ABC):
    """Base of every ``model:`` section, one per adapter kind (:mod:`pcmb.adapters.registry`).

    A subclass declares ``kind: Literal["<kind>"]`` (the union tag) and ``params`` (nominal
    values), and says how to build its factory and which outputs it keeps.
    """

    @abstractmethod
    def factory(self, base_dir: Path) -> ModelFactory:
        """The picklable factory of the model; relative paths resolve against ``base_dir``."""

    @property
    @abstractmethod
    def output_names(self) -> tuple[str, ...] | None:
        """Outputs to keep (``None``: every output of the model)."""

    @property
    def nominal_names(self) -> frozenset[str]:
        """Inputs this section gives a nominal value or a binding to."""
        return frozenset(self.params)  # type: ignore[attr-defined]


def selecting_key(section: type[BaseModel]) -> str:
    """The key whose presence picks ``section`` among the members of a
    :func:`tagged_by_key` union: its first required key."""
    return next(name for name, info in section.model_fields.items() if info.is_required())


def _first_key(variant: Any) -> str:
    """A section's selecting key; for a union of sections, that of its first member (a union
    picked by a value, such as ``dist``, has it first in every member)."""
    while typing.get_origin(variant) is Annotated:
        variant = typing.get_args(variant)[0]
    if typing.get_origin(variant) in (typing.Union, types.UnionType):
        return _first_key(typing.get_args(variant)[0])
    return selecting_key(variant)


def tagged_by_key(*variants: Any, error: str) -> Any:
    """A union whose member is chosen by which one of the members' selecting keys (their
    first required keys) is present.

    A member is a section, or a union of sections that share their first key. A mapping
    with none or several of the keys is no member (``error`` says what is expected). Tags
    contain a colon, so they can never be confused with a key of the config.
    """
    first_keys = {_first_key(v): v for v in variants}

    def tag(value: Any) -> str | None:
        if isinstance(value, BaseModel):
            return f"key:{_first_key(type(value))}"
        if isinstance(value, Mapping):
            present = [k for k in first_keys if k in value]
            return f"key:{present[0]}" if len(present) == 1 else None
        return None

    members = tuple(Annotated[v, Tag(f"key:{k}")] for k, v in first_keys.items())
    return Annotated[
        typing.Union[members],  # noqa: UP007 (a runtime tuple of members)
        Discriminator(tag, custom_error_type="no_variant", custom_error_message=error),
    ]


def _order_tag(value: Any) -> str:
    if isinstance(value, str):
        return "order:auto"
    return "order:mapping" if isinstance(value, Mapping) else "order:int"


# Tagged by the value's type, so an error names the form the user wrote (an int, a mapping or
# auto) instead of listing how the value fails every form.
OrderSpec = Annotated[
    Annotated[NonNegativeInt, Tag("order:int")]
    | Annotated[dict[Name, NonNegativeInt], Tag("order:mapping")]
    | Annotated[Literal["auto"], Tag("order:auto")],
    Discriminator(_order_tag),
]
