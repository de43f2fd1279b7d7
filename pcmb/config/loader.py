"""The config's YAML: a safe loader, YAML 1.2 plain scalars, duplicate keys, key lines.

The only module that imports the YAML library. :func:`parse_yaml` turns text into plain data,
the line of every key path, and the problems found (every one, not just the first).
"""

from __future__ import annotations

import math
import re
import typing
from typing import Any

import yaml

from pcmb.config.messages import INVALID, KeyPath, format_path
from pcmb.errors import ConfigError, ConfigProblem

__all__ = ["MAX_YAML_NODES", "parse_yaml"]

#: Largest number of YAML nodes in a document (guards against alias bombs).
MAX_YAML_NODES = 100_000


class _Loader(yaml.SafeLoader):
    """A safe loader whose plain scalars follow the YAML 1.2 core schema."""

    # Own resolver table (PyYAML copies the parent's only when this attribute is missing).
    yaml_implicit_resolvers: typing.ClassVar[dict[str, list[Any]]] = {}


def _construct_int(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int:
    text = str(loader.construct_scalar(node))
    sign = -1 if text.startswith("-") else 1
    digits = text.lstrip("+-")
    base = {"0o": 8, "0x": 16}.get(digits[:2].lower(), 10)
    return sign * int(digits[2:] if base != 10 else digits, base)


def _construct_float(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> float:
    text = str(loader.construct_scalar(node))
    special = {".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, ".nan": math.nan}
    key = text.lower()
    return special[key] if key in special else float(text)


# YAML 1.2 core schema; "" (the empty scalar) resolves to null.
for _tag, _pattern, _first in [
    ("null", r"~|null|Null|NULL|", ["~", "n", "N", ""]),
    ("bool", r"true|True|TRUE|false|False|FALSE", "tTfF"),
    ("int", r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+", "-+0123456789"),
    (
        "float",
        r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?"
        r"|[-+]?\.(inf|Inf|INF)|\.nan|\.NaN|\.NAN",
        "-+.0123456789",
    ),
]:
    _Loader.add_implicit_resolver(
        f"tag:yaml.org,2002:{_tag}", re.compile(rf"^(?:{_pattern})$"), list(_first)
    )
_Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_Loader.add_constructor("tag:yaml.org,2002:float", _construct_float)

_SCALAR_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("str", "int", "float", "bool", "null")}


class _YamlReader:
    """Turns a composed YAML node tree into plain data, recording the line of every key.

    Duplicate keys, unsupported tags, complex keys and recursive aliases become problems.
    """

    def __init__(self, loader: _Loader):
        self.loader = loader
        self.lines: dict[KeyPath, int] = {}
        self.problems: list[ConfigProblem] = []
        self._active: set[int] = set()
        self._count = 0

    def _report(self, path: KeyPath, message: str, node: yaml.Node) -> object:
        self.problems.append(ConfigProblem(format_path(path), message, node.start_mark.line + 1))
        return INVALID

    def read(self, node: yaml.Node, path: KeyPath = ()) -> Any:
        self.lines.setdefault(path, node.start_mark.line + 1)
        self._count += 1
        if self._count > MAX_YAML_NODES:
            raise _TooLarge
        if isinstance(node, yaml.ScalarNode):
            if node.tag not in _SCALAR_TAGS:
                return self._report(path, f"unsupported YAML tag {node.tag}", node)
            try:
                return self.loader.construct_object(node)
            except (ValueError, yaml.YAMLError) as exc:
                text = node.value if len(node.value) <= 40 else node.value[:37] + "..."
                kind = node.tag.rsplit(":", 1)[-1]
                return self._report(path, f"cannot read {text!r} as {kind}: {exc}", node)
        if id(node) in self._active:
            return self._report(path, "an alias refers to its own ancestor", node)
        expected = "map" if isinstance(node, yaml.MappingNode) else "seq"
        if node.tag != f"tag:yaml.org,2002:{expected}":
            return self._report(path, f"unsupported YAML tag {node.tag}", node)
        self._active.add(id(node))
        try:
            if isinstance(node, yaml.SequenceNode):
                return [self.read(item, (*path, i)) for i, item in enumerate(node.value)]
            return self._read_mapping(node, path)
        finally:
            self._active.discard(id(node))

    def _read_mapping(self, node: yaml.MappingNode, path: KeyPath) -> dict[Any, Any]:
        result: dict[Any, Any] = {}
        first_line: dict[Any, int] = {}
        for key_node, value_node in node.value:
            line = key_node.start_mark.line + 1
            key = self.read(key_node, path) if isinstance(key_node, yaml.ScalarNode) else None
            if key is INVALID:
                continue
            if not isinstance(key, str | int | float | bool) or key != key:  # NaN is no key
                self._report(path, "keys must be plain names", key_node)
                continue
            if key in first_line:
                self._report(
                    (*path, key),
                    f"duplicate key {key!r} "
                    f"(first at line {first_line[key]}, again at line {line})",
                    key_node,
                )
                continue
            first_line[key] = line
            self.lines[(*path, key)] = line
            result[key] = self.read(value_node, (*path, key))
        return result


class _TooLarge(Exception):
    """The document expands to more than MAX_YAML_NODES nodes."""


def parse_yaml(text: str, source: str) -> tuple[Any, dict[KeyPath, int], list[ConfigProblem]]:
    """Parse one YAML document into plain data, key lines and problems.

    Raises
    ------
    ConfigError
        Syntax errors, several documents, an empty document, an oversized document.
    """
    try:
        loader = _Loader(text)  # the reader already rejects unprintable characters
        try:
            node = loader.get_single_node()
            if node is None:
                raise ConfigError("the file is empty: expected a mapping of settings", source)
            reader = _YamlReader(loader)
            data = reader.read(node)
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        context = exc.context or ""
        if exc.context_mark is not None and exc.problem_mark is not None and context:
            context += f" (from line {exc.context_mark.line + 1})"
        detail = " ".join(part for part in (context, exc.problem or "") if part)
        line = None if mark is None else mark.line + 1
        raise ConfigError(
            [ConfigProblem("", f"YAML syntax error: {detail}", line)], source
        ) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        problem = ConfigProblem("", f"YAML error: {exc.reason} (found U+{code:04X})", line)
        raise ConfigError([problem], source) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"YAML error: {exc}", source) from None
    except _TooLarge:
        raise ConfigError(f"the document has more than {MAX_YAML_NODES} nodes", source) from None
    except RecursionError:
        raise ConfigError("the document is nested too deeply", source) from None
    return data, reader.lines, reader.problems
