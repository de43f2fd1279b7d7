"""``docs/config.md``: generated from the schema, current, and complete."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pcmb.adapters.registry import ADAPTERS
from pcmb.config import config_json_schema, load_config
from pcmb.config.reference import EXAMPLE, config_reference, undescribed_keys
from pcmb.designs import METHOD_KINDS
from pcmb.run.backends import BACKENDS

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "config.md"
REGENERATE = "python -m pcmb.config.reference > docs/config.md"


@pytest.fixture(scope="module")
def page() -> str:
    return config_reference()


def _normalised(text: str) -> str:
    """Placeholders of mapping keys and list indices, whatever their names."""
    return re.sub(r"\[[^\]`]*\]", "[*]", re.sub(r"<[^>`]*>", "<*>", text))


# --------------------------------------------------------------------------- an independent walk


def _leaf_paths(schema: dict[str, Any]) -> set[str]:
    """Every leaf key path of a JSON Schema: ``a.b``, ``a.<*>.b`` (mapping values) and
    ``a[*].b`` (list entries), through ``$ref``, ``anyOf``, ``oneOf`` and ``allOf``."""
    defs = schema.get("$defs", {})

    def resolve(node: Any) -> Any:
        while isinstance(node, dict) and "$ref" in node:
            node = defs[node["$ref"].rsplit("/", 1)[-1]]
        return node

    def branches(node: Any) -> Iterator[dict[str, Any]]:
        node = resolve(node)
        if not isinstance(node, dict):
            return
        yield node
        for key in ("anyOf", "oneOf", "allOf"):
            for member in node.get(key, []):
                yield from branches(member)

    def structured(node: Any) -> bool:
        for branch in branches(node):
            if branch.get("properties"):
                return True
            for inner in (branch.get("additionalProperties"), branch.get("items")):
                if isinstance(inner, dict) and structured(inner):
                    return True
        return False

    leaves: set[str] = set()

    def walk(node: Any, path: str) -> None:
        if path and not structured(node):
            leaves.add(path)
            return
        for branch in branches(node):
            for key, sub in branch.get("properties", {}).items():
                walk(sub, f"{path}.{key}" if path else key)
            for suffix, inner in (("<*>", "additionalProperties"), ("[*]", "items")):
                value = branch.get(inner)
                if isinstance(value, dict) and structured(value):
                    walk(value, f"{path}.{suffix}" if suffix == "<*>" else path + suffix)

    walk(schema, "")
    return leaves


def _enum(schema: dict[str, Any], section: str, key: str) -> list[Any]:
    """The values a section's key admits (``enum`` or ``const``, through ``anyOf``)."""
    node = schema["$defs"][section]["properties"][key]
    found: list[Any] = []
    for member in [node, *node.get("anyOf", [])]:
        found += member.get("enum", [])
        if "const" in member:
            found.append(member["const"])
    return found


# --------------------------------------------------------------------------- the tests


def test_the_page_is_current(page):
    assert PAGE.is_file(), f"docs/config.md is missing: run `{REGENERATE}`"
    assert PAGE.read_text(encoding="utf-8") == page, (
        f"docs/config.md is out of date with the config schema: run `{REGENERATE}`"
    )


def test_the_page_says_how_it_is_made(page):
    assert REGENERATE in "\n".join(page.splitlines()[:5])


def test_the_walk_finds_leaves_through_refs_unions_mappings_and_lists():
    schema = {
        "$defs": {"B": {"properties": {"x": {"type": "number"}}}},
        "properties": {
            "a": {"anyOf": [{"$ref": "#/$defs/B"}, {"type": "null"}]},
            "m": {"additionalProperties": {"oneOf": [{"$ref": "#/$defs/B"}]}},
            "l": {"items": {"$ref": "#/$defs/B"}},
            "p": {"additionalProperties": {"type": "number"}},
        },
    }
    assert _leaf_paths(schema) == {"a.x", "m.<*>.x", "l[*].x", "p"}


def test_every_leaf_key_of_the_json_schema_is_documented(page):
    leaves = _leaf_paths(config_json_schema())
    assert len(leaves) > 50  # the walk reached every section
    assert {"model.command", "inputs.<*>.low", "model.bind.<*>[*].field"} <= leaves
    text = _normalised(page)
    missing = sorted(path for path in leaves if f"`{path}`" not in text)
    assert not missing, f"keys missing from the page: {missing}"


def test_every_top_level_key_has_a_row(page):
    for key in config_json_schema()["properties"]:
        assert f"| `{key}` |" in page


def test_every_registered_kind_is_listed(page):
    schema = config_json_schema()
    model_kinds = set(schema["properties"]["model"]["discriminator"]["mapping"])
    dist_kinds = set(_dist_mapping(schema))
    method_kinds = set(schema["properties"]["method"]["discriminator"]["mapping"])
    backends = set(_enum(schema, "ExecutionSpec", "backend"))
    assert model_kinds == set(ADAPTERS)
    assert method_kinds == set(METHOD_KINDS)
    assert backends and backends <= set(BACKENDS)
    assert dist_kinds
    for kind in ADAPTERS:
        assert f"`model` with `kind: {kind}`" in page
    for dist in dist_kinds:
        assert f"`inputs.<name>` with `dist: {dist}`" in page
    rows = {line.split(" | ")[0]: line for line in page.splitlines() if line.startswith("| `")}
    for kind in METHOD_KINDS:
        assert re.search(rf"`method` with `kind: [^`]*\b{kind}\b", page), kind
    for backend in backends:
        assert f"`{backend}`" in rows["| `execution.backend`"]


def _dist_mapping(schema: dict[str, Any]) -> dict[str, str]:
    """The ``dist`` values of an input: the member of ``inputs``' union (a distribution or a
    random process) that is picked by ``dist``."""
    members = schema["properties"]["inputs"]["additionalProperties"]["oneOf"]
    (found,) = [m for m in members if m.get("discriminator", {}).get("propertyName") == "dist"]
    return found["discriminator"]["mapping"]


def test_kinds_come_from_the_schema_not_from_the_generator():
    tree = ast.parse((ROOT / "pcmb" / "config" / "reference.py").read_text(encoding="utf-8"))
    texts = {  # the generator's string constants, not its header and example
        node.value
        for statement in tree.body
        if not (
            isinstance(statement, ast.Assign | ast.AnnAssign)
            and ast.unparse(statement).startswith(("EXAMPLE", "_HEADER"))
        )
        for node in ast.walk(statement)
        if isinstance(node, ast.Constant) and isinstance(node.value, str)
    }
    kinds = {*METHOD_KINDS, *BACKENDS, *ADAPTERS, *_dist_mapping(config_json_schema())}
    assert not kinds & texts


def test_the_example_is_a_valid_config():
    # As configs/quarter_car.yaml: its relative model path resolves against configs/.
    config = load_config(ROOT / "configs" / "example.yaml", text=EXAMPLE)
    assert config.input_names == ("A", "kT", "c")
    assert config.analysis is not None


def test_the_page_shows_the_example(page):
    assert f"```yaml\n{EXAMPLE}```" in page


def test_undescribed_keys_are_key_paths_of_the_page(page):
    for path in undescribed_keys():
        assert f"| `{path}` |" in page


@pytest.mark.slow
def test_the_module_prints_the_page_and_is_not_loaded_by_the_command_line(page):
    done = subprocess.run(
        [sys.executable, "-m", "pcmb.config.reference"], capture_output=True, check=True
    )
    assert done.stdout.decode("utf-8") == page
    code = (
        "import sys\nfrom pcmb import cli\n"
        "try:\n    cli.main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print('pcmb.config.reference' in sys.modules, file=sys.stderr)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stderr.strip() == "False"
