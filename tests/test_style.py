"""The house rules that tooling can check, as part of the suite CI runs."""

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ruff(*args):
    exe = shutil.which("ruff")
    command = [exe] if exe else [sys.executable, "-m", "ruff"]
    return subprocess.run([*command, *args], cwd=ROOT, capture_output=True, text=True)


def test_ruff_lint_is_clean():
    result = _ruff("check", "pcmb", "tests", "models", "scripts")
    assert result.returncode == 0, result.stdout + result.stderr


def test_ruff_format_is_clean():
    result = _ruff("format", "--check", "pcmb", "tests", "models", "scripts")
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.parametrize(
    "heavy", ["mujoco", "h5py", "matplotlib", "distributed", "yaml", "pydantic"]
)
def test_importing_pcmb_does_not_import_heavy_modules(heavy):
    code = f"import sys, pcmb; print({heavy!r} in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_public_name_resolves():
    import pcmb

    for name in pcmb.__all__:
        assert getattr(pcmb, name) is not None
    assert set(pcmb.__all__) == set(pcmb._MODULE_OF)
    listed = [name for names in pcmb._EXPORTS.values() for name in names]
    assert len(listed) == len(set(listed)), "a name is exported from two modules"


def _integer_powers(tree: ast.AST) -> list[int]:
    """Lines of ``a ** n`` with an integer ``n`` >= 3 anywhere in ``tree`` (functions, lambdas,
    module level) but in a function that builds a ``PolynomialForm``, whose powers are of
    symbols, computed once."""
    symbolic = {
        id(node)
        for function in ast.walk(tree)
        if isinstance(function, ast.FunctionDef)
        and any(isinstance(n, ast.Name) and n.id == "PolynomialForm" for n in ast.walk(function))
        for node in ast.walk(function)
    }
    return [
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.BinOp)
        and isinstance(node.op, ast.Pow)
        and isinstance(node.right, ast.Constant)
        and isinstance(node.right.value, int)
        and node.right.value >= 3
        and id(node) not in symbolic
    ]


@pytest.mark.parametrize("path", sorted((ROOT / "models").glob("*.py")), ids=lambda p: p.name)
def test_models_raise_to_integer_powers_by_products(path):
    """``x * x * x``, not ``x**3``: libm's pow takes a slow path (for 216 negative values
    ``y**3`` costs 23 µs a call against 0.6 µs, ``y**4`` 21 against 0.9), and a model's
    right-hand side or force law runs at every step of every node."""
    assert _integer_powers(ast.parse(path.read_text())) == []
