"""The house rules that tooling can check, as part of the suite CI runs."""

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
