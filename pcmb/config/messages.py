"""Located problems: pydantic errors as ``key.path: expected ..., found ...`` with their lines.

Key paths are found by walking the schema's annotations along an error's location, so union
member tags are dropped where they stand and keys are kept, whatever their names.
"""

from __future__ import annotations

import re
import types
import typing
from collections.abc import Iterable, Mapping, Sequence
from typing import Annotated, Any

from pydantic import BaseModel, Tag, ValidationError
from pydantic.fields import FieldInfo

from pcmb.errors import ConfigProblem
from pcmb.wording import did_you_mean, plural

__all__ = [
    "INVALID",
    "SETTING_ERROR",
    "KeyPath",
    "format_path",
    "line_of",
    "located",
    "parse_path",
    "schema_problems",
]

KeyPath = tuple[str | int, ...]

#: Stands for a value already reported as a problem (by the YAML reader).
INVALID: Any = object()

#: The pydantic error type (``PydanticCustomError``) of a section's objection to one of its
#: own keys, raised where the whole section is known: ctx ``key`` (a key path inside the
#: section, ``"covariance.length"``) and ``message``; the problem is located at that key.
SETTING_ERROR = "setting_error"


def format_path(path: Sequence[str | int]) -> str:
    """``("inputs", "k", 0)`` -> ``"inputs.k[0]"``."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) and not isinstance(part, bool) else f".{part}"
    return text.lstrip(".")


def parse_path(text: str) -> KeyPath:
    """``"inputs.k[0]"`` -> ``("inputs", "k", 0)``."""
    return tuple(
        int(index) if index else key for key, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", text)
    )


def line_of(path: KeyPath, lines: Mapping[KeyPath, int]) -> int | None:
    """Line of the key at ``path``, or of its nearest ancestor present in the file."""
    for end in range(len(path), -1, -1):
        if path[:end] in lines:
            return lines[path[:end]]
    return None


def located(found: Iterable[tuple[str, str]], lines: Mapping[KeyPath, int]) -> list[ConfigProblem]:
    """(key path, message) pairs as problems with the line of their key."""
    return [ConfigProblem(p, m, line_of(parse_path(p), lines)) for p, m in found]


# --------------------------------------------------------------------------- the schema walk


def _unwrap(annotation: Any) -> tuple[Any, list[Any]]:
    """The annotation without ``Annotated`` layers, and their metadata."""
    metadata: list[Any] = []
    while typing.get_origin(annotation) is Annotated:
        annotation, *more = typing.get_args(annotation)
        metadata += more
    return annotation, metadata


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _field(model: type[BaseModel], name: Any) -> Any:
    """A model field's annotation, with its FieldInfo kept (it holds the discriminator)."""
    field = model.model_fields.get(name) if isinstance(name, str) else None
    return None if field is None else Annotated[field.annotation, field]


def _discriminator(metadata: Sequence[Any]) -> str | None:
    """The key a union is discriminated by (``None`` for a callable discriminator)."""
    for item in metadata:
        found = item.discriminator if isinstance(item, FieldInfo) else item
        if isinstance(found, str):
            return found
    return None


def _member_tags(union: Any, metadata: Sequence[Any]) -> list[tuple[str, Any]]:
    """(tag, member) of a discriminated union, in order; empty for a plain union."""
    key = _discriminator(metadata)
    tagged = []
    for member in typing.get_args(union):
        inner, member_metadata = _unwrap(member)
        tags = [m.tag for m in member_metadata if isinstance(m, Tag)]
        if not tags and key and isinstance(inner, type) and issubclass(inner, BaseModel):
            field = inner.model_fields.get(key)
            if field is not None and typing.get_origin(field.annotation) is typing.Literal:
                tags = [str(t) for t in typing.get_args(field.annotation)]
        tagged += [(tag, member) for tag in tags]
    return tagged


def _step(annotation: Any, element: Any) -> tuple[Any, bool]:
    """The annotation one location element below, and whether the element is a union tag."""
    while True:
        inner, metadata = _unwrap(annotation)
        if not _is_union(inner):
            break
        for tag, member in _member_tags(inner, metadata):
            if tag == element:
                return member, True
        members = [a for a in typing.get_args(inner) if a is not type(None)]
        if len(members) != 1:
            return None, False
        annotation = members[0]  # an optional value: look inside
    if isinstance(inner, type) and issubclass(inner, BaseModel):
        return _field(inner, element), False
    origin = typing.get_origin(inner)
    if origin is dict:
        return typing.get_args(inner)[1], False
    if origin is list:
        return typing.get_args(inner)[0], False
    return None, False


def _walk(root: Any, loc: Sequence[Any]) -> tuple[KeyPath, Any]:
    """The key path of an error location (union tags dropped) and the annotation there."""
    path: list[str | int] = []
    annotation = root
    for element in loc:
        if element == "[key]":  # pydantic's mark of a bad dict key: the key is already there
            continue
        if annotation is not None:
            annotation, is_tag = _step(annotation, element)
            if is_tag:
                continue
        elif isinstance(element, str) and ":" in element:  # a key-tagged union's member tag
            continue
        path.append(element)
    return tuple(path), annotation


def _allowed_keys(root: Any, loc: Sequence[Any]) -> list[str]:
    """Keys of the config section at a location."""
    _, annotation = _walk(root, loc)
    while annotation is not None:
        inner, _ = _unwrap(annotation)
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return list(inner.model_fields)
        if not _is_union(inner):
            return []
        members = [a for a in typing.get_args(inner) if a is not type(None)]
        annotation = members[0] if len(members) == 1 else None
    return []


def _union_tags(root: Any, loc: Sequence[Any]) -> list[str]:
    """Member tags of the discriminated union at a location."""
    _, annotation = _walk(root, loc)
    while annotation is not None:
        inner, metadata = _unwrap(annotation)
        if not _is_union(inner):
            return []
        tags = _member_tags(inner, metadata)
        if tags:
            return [tag for tag, _ in tags]
        members = [a for a in typing.get_args(inner) if a is not type(None)]
        annotation = members[0] if len(members) == 1 else None
    return []


def _owners(root: Any, loc: Sequence[Any]) -> tuple[str, str, list[str]] | None:
    """For a key that a member of a discriminated union refuses (``loc`` ends with the
    member's tag and the key): the discriminator, the member's tag and the tags of the
    members that take the key; ``None`` elsewhere or when no member takes it."""
    if len(loc) < 2:
        return None
    _, annotation = _walk(root, loc[:-2])
    while annotation is not None:
        inner, metadata = _unwrap(annotation)
        if not _is_union(inner):
            return None
        tags = _member_tags(inner, metadata)
        if tags:
            break
        members = [a for a in typing.get_args(inner) if a is not type(None)]
        annotation = members[0] if len(members) == 1 else None
    else:
        return None
    key, tag = _discriminator(metadata), loc[-2]
    takers = [t for t, member in tags if loc[-1] in getattr(_unwrap(member)[0], "model_fields", {})]
    if key is None or tag not in dict(tags) or not takers:
        return None
    return key, str(tag), takers


# --------------------------------------------------------------------------- messages

_EXPECTED = {
    "int_type": "expected an integer",
    "int_parsing": "expected an integer",
    "int_from_float": "expected an integer",
    "float_type": "expected a number",
    "float_parsing": "expected a number",
    "finite_number": "expected a finite number",
    "string_type": "expected a string",
    "bool_type": "expected true or false",
    "dict_type": "expected a mapping",
    "model_type": "expected a mapping",
    "model_attributes_type": "expected a mapping",
    "list_type": "expected a list",
}
_BOUNDS = {
    "greater_than_equal": (">=", "ge"),
    "greater_than": (">", "gt"),
    "less_than_equal": ("<=", "le"),
    "less_than": ("<", "lt"),
}


def _show(value: Any) -> str:
    """How a found value is named in a message."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list | tuple):
        return "a list"
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"the text {text}" if isinstance(value, str) else text


def _then(hint: str) -> str:
    """A hint appended to a message, if there is one."""
    return f"; {hint}" if hint else ""


def _message(error: Mapping[str, Any], root: Any) -> tuple[str, str | None]:
    """Message of one pydantic error, and the key path to append to its location (if
    any)."""
    kind, ctx, found = error["type"], error.get("ctx", {}), _show(error["input"])
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        key = str(ctx["discriminator"]).strip("'")
        tags = _union_tags(root, error["loc"])
        expected = ", ".join(tags)
        if kind == "union_tag_not_found":
            return f"required key is missing (one of {expected})", key
        hint = did_you_mean(str(ctx["tag"]), tags)
        return f"expected one of {expected}, found {_show(ctx['tag'])}{_then(hint)}", key
    if kind == "missing":
        # pydantic's own 'missing' has no context; the validators' ones explain the need.
        return (error["msg"] if ctx else "required key is missing"), None
    if kind == "extra_forbidden":
        owners = _owners(root, error["loc"])
        if owners is not None:
            discriminator, tag, takers = owners
            return (
                f"not a setting of {discriminator} {tag} (it belongs to {', '.join(takers)})",
                None,
            )
        key = str(error["loc"][-1])
        allowed = _allowed_keys(root, error["loc"][:-1])
        listing = f" (allowed: {', '.join(allowed)})" if allowed else ""
        return f"unknown key{listing}{_then(did_you_mean(key, allowed))}", None
    if kind == "value_error":
        return str(ctx.get("error", error["msg"])), None
    if kind == SETTING_ERROR:
        return str(ctx["message"]), str(ctx["key"])
    if kind == "literal_error":
        return f"expected {ctx['expected']}, found {found}", None
    if kind in _BOUNDS:
        symbol, name = _BOUNDS[kind]
        return f"expected a value {symbol} {ctx[name]}, found {found}", None
    if kind == "too_short":
        least = plural(ctx["min_length"], "entry", "entries")
        return f"expected at least {least}, found {ctx['actual_length']}", None
    if kind in _EXPECTED:
        return f"{_EXPECTED[kind]}, found {found}", None
    text = str(error["msg"])
    return f"{text[:1].lower()}{text[1:]}, found {found}", None


def schema_problems(
    exc: ValidationError,
    root: Any,
    lines: Mapping[KeyPath, int] | None = None,
    prefix: KeyPath = (),
) -> list[ConfigProblem]:
    """The problems of a pydantic validation error, located.

    Parameters
    ----------
    exc:
        The error of validating data against ``root``.
    root:
        The model class or type validated (e.g. ``StudyConfig``).
    lines:
        Line of every key path, from the YAML reader.
    prefix:
        Key path of ``root`` in the config (``("model",)`` for an adapter's own section).
    """
    problems = []
    for error in exc.errors():
        if error["input"] is INVALID:
            continue  # already reported while reading the YAML
        message, extra_key = _message(error, root)
        path, _ = _walk(root, error["loc"])
        path = (*prefix, *path, *(parse_path(extra_key) if extra_key is not None else ()))
        problems.append(ConfigProblem(format_path(path), message, line_of(path, lines or {})))
    return problems
