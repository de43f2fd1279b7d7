"""How the arguments of :class:`~pcmb.study.Study` become its validated sections: a
section or a mapping of its config keys, refused at those keys, and the keyword arguments of
pcmb 0.x, accepted for one release with a ``DeprecationWarning``."""

from __future__ import annotations

import typing
import warnings
from collections.abc import Mapping
from typing import Any

from pydantic import TypeAdapter, ValidationError

from pcmb.config.messages import schema_problems
from pcmb.config.schema import DiagnosticsSpec, ExecutionSpec
from pcmb.config.types import Section
from pcmb.designs import MethodSection, MethodSpec
from pcmb.errors import ConfigProblem, UsageError

__all__ = ["DEPRECATED", "from_keywords", "keys_of", "usage_error", "validated_section"]


def usage_error(key: str, message: str) -> UsageError:
    """The refusal of a ``Study`` argument at its config ``key``."""
    return UsageError([ConfigProblem(key, message)], source="Study")


def keys_of(section: Section | Mapping[str, Any] | None) -> dict[str, Any]:
    """A section's keys (those set or not default), a mapping's copy, or nothing."""
    if section is None:
        return {}
    return section.model_dump(exclude_unset=True) if isinstance(section, Section) else dict(section)


def validated_section(key: str, root: Any, value: Any) -> Any:
    """The validated section at ``key`` (``root``: its class or union) of a section or its
    keys; a refusal is a UsageError at the section's keys."""
    try:
        return TypeAdapter(root).validate_python(value)
    except ValidationError as error:
        raise UsageError(schema_problems(error, root, prefix=(key,)), source="Study") from None


#: Order of a method of pcmb 0.x's keywords that takes one and was given neither order nor
#: level (their default then).
_KEYWORD_ORDER = 3
#: The keyword arguments of pcmb 0.x -> the (section, key) each now sets; accepted for one
#: release with a DeprecationWarning.
DEPRECATED: dict[str, tuple[str, str]] = {
    **{
        key: ("method", key)
        for member in typing.get_args(typing.get_args(MethodSpec)[0])
        for key in member.model_fields
        if key != "kind"
    },
    **{key: ("execution", key) for key in ExecutionSpec.model_fields if key != "address"},
    "diagnostics_tolerance": ("diagnostics", "tolerance"),
    "diagnosed": ("diagnostics", "outputs"),
}


def from_keywords(
    kind: str | None,
    execution: ExecutionSpec | Mapping[str, Any] | None,
    diagnostics: DiagnosticsSpec | Mapping[str, Any] | None,
    keywords: Mapping[str, Any],
    method: MethodSection | Mapping[str, Any] | None,
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The ``method``, ``execution`` and ``diagnostics`` keys that pcmb 0.x's keyword
    arguments (and ``method="<kind>"``) describe, on top of the given sections; the keys of
    ``method`` that a new kind does not take are dropped."""
    unknown = sorted(set(keywords) - set(DEPRECATED))
    if unknown:
        raise usage_error(unknown[0], f"unknown argument(s) {unknown}")
    warnings.warn(
        "Study's keyword arguments of pcmb 0.x (order=, samples=, jobs=, method='<kind>', ...) "
        "are deprecated: give method=, execution= and diagnostics= sections (or mappings of "
        "their config keys)",
        DeprecationWarning,
        stacklevel=3,
    )
    given: dict[str, dict[str, Any]] = {
        "method": {},
        "execution": keys_of(execution),
        "diagnostics": keys_of(diagnostics),
    }
    for key, value in keywords.items():
        section, name = DEPRECATED[key]
        if value is not None:  # None was "not set" in pcmb 0.x
            given[section][name] = value
    current = keys_of(method) if method is not None else {"kind": "collocation"}
    kind = kind or current["kind"]
    takes = type(validated_section("method", MethodSpec, {"kind": kind})).model_fields
    data = {key: value for key, value in current.items() if key in takes}
    data.update(given["method"], kind=kind)
    if "order" in takes and "order" not in data and "level" not in data:
        data["order"] = _KEYWORD_ORDER
    return data, given["execution"], given["diagnostics"]
