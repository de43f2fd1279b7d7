"""The package's layering, read from its import statements (static) and checked at run time."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "pcmb"
HEAVY = ("h5py", "joblib", "mujoco", "pydantic", "matplotlib", "distributed", "dask", "yaml")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, *, top_level_only: bool, typing_only: bool = True) -> set[str]:
    """Modules imported by a file: all of them, or only those run at import time (not inside
    functions and not under ``if TYPE_CHECKING``); ``typing_only``: with the imports under ``if
    TYPE_CHECKING``, which never run."""
    tree = ast.parse(path.read_text())
    found: set[str] = set()
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]

    def visit(node: ast.AST, inside: bool) -> None:
        for child in ast.iter_child_nodes(node):
            nested = inside or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                if not typing_only:
                    continue
                nested = True
            if isinstance(child, ast.Import) and not (top_level_only and inside):
                found.update(alias.name for alias in child.names)
            elif isinstance(child, ast.ImportFrom) and not (top_level_only and inside):
                base = child.module or ""
                if child.level:
                    anchor = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join([*anchor, base] if base else anchor)
                found.add(base)
                found.update(f"{base}.{alias.name}" for alias in child.names)
            visit(child, nested)

    visit(tree, False)
    return found


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _importers_of(prefix: str) -> set[str]:
    return {
        name
        for name, path in MODULES.items()
        if any(
            m == prefix or m.startswith(prefix + ".") for m in _imports(path, top_level_only=False)
        )
    }


def test_the_chaos_core_imports_no_heavy_library_and_no_pipeline():
    for name, path in MODULES.items():
        if not name.startswith("pcmb.chaos"):
            continue
        imported = _imports(path, top_level_only=False)
        pcmb_parts = {m for m in imported if m.startswith("pcmb.")}
        heavy = {m for m in imported if m.split(".")[0] in HEAVY}
        assert not heavy, f"{name} imports {heavy}"
        outside = {m for m in pcmb_parts if not m.startswith(("pcmb.chaos", "pcmb.errors"))}
        assert not outside, f"{name} imports {outside}"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("library", "owners"),
    [
        ("h5py", ("pcmb.store", "pcmb.sweep.table")),  # a result file; a sweep file
        ("mujoco", ("pcmb.adapters.mujoco",)),
        ("yaml", ("pcmb.config.loader",)),
        ("matplotlib", ("pcmb.analysis.report", "pcmb.sweep.chart")),  # a result's; a sweep's
    ],
)
def test_each_heavy_library_has_one_owner(library, owners):
    users = _importers_of(library)
    strangers = {u for u in users if not u.startswith(owners)}
    assert not strangers, f"{library} is imported by {sorted(strangers)} (owners: {owners})"


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of a directed graph (as a path that returns to its start), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def walk(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == 1:
                return [*stack[stack.index(target) :], target]
            if target not in state and (found := walk(target)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for name in sorted(graph):
        if name not in state and (found := walk(name)):
            return found
    return None


def test_the_cycle_finder_finds_cycles():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_no_import_cycles():
    # Imports inside functions count: a deferred import that closes a circle only hides it.
    # Those under TYPE_CHECKING, which never run, do not.
    graph = {
        name: {
            m
            for m in _imports(path, top_level_only=False, typing_only=False)
            if m in MODULES and m != name and not name.startswith(m + ".")
        }
        for name, path in MODULES.items()
    }
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def _loaded(code: str, packages: tuple[str, ...]) -> list[str]:
    """The packages among ``packages`` a fresh interpreter has imported after ``code``."""
    probe = (
        f"{code}import json, sys\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return sorted(set(json.loads(done.stdout)) & set(packages))


def test_the_public_core_api_loads_no_heavy_library():
    code = (
        "import pcmb\n"
        "pcmb.TensorGrid, pcmb.project_tensor, pcmb.ChaosExpansion, pcmb.Uniform, pcmb.Normal\n"
        "pcmb.Beta, pcmb.Gamma, pcmb.Transformed, pcmb.fit_least_squares, pcmb.KarhunenLoeve\n"
    )
    assert _loaded(code, HEAVY) == []


def test_a_worker_starts_without_scipy():
    # What every loky worker imports when it starts (pcmb.run.backends._warm_up): scipy is
    # half a second of import per worker, on the main job's critical path, that only
    # implicit integrators and the chaos machinery of the result need.
    assert _loaded("from pcmb.run.backends import _warm_up\n_warm_up()\n", (*HEAVY, "scipy")) == []


def test_running_knows_no_adapter_but_the_protocol():
    # Adapters declare the files their models read (ModelFactory.model_files, loaded_files):
    # the resume fingerprint and the workers need no adapter's class. The python adapter is
    # only imported ahead of the first task (run.backends._warm_up).
    for name, path in MODULES.items():
        if not name.startswith("pcmb.run."):
            continue
        imported = _imports(path, top_level_only=False, typing_only=False)
        adapters = {m for m in imported if m.startswith("pcmb.adapters.")}
        strangers = adapters - {"pcmb.adapters.protocol", "pcmb.adapters.python.model"}
        strangers = {m for m in strangers if not m.startswith("pcmb.adapters.protocol.")}
        assert not strangers, f"{name} imports {sorted(strangers)}"
