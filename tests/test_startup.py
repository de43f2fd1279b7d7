"""What each command imports and starts before its work (issue 24): whole processes, no
timing asserts; the times are in docs/benchmarks.md."""

import subprocess
import sys

import pytest


def _loaded(code: str, modules: list[str]) -> dict[str, bool]:
    """Which of ``modules`` are in ``sys.modules`` after running ``code`` in a fresh
    interpreter."""
    probe = f"{code}\nimport sys\nprint([m in sys.modules for m in {modules!r}])"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return dict(zip(modules, eval(out.stdout.strip().splitlines()[-1]), strict=True))


@pytest.mark.parametrize("heavy", ["scipy.special", "scipy.linalg", "joblib"])
def test_reading_the_config_schema_imports_no_scipy_nor_joblib(heavy):
    assert _loaded("import pcmb.config.schema", [heavy]) == {heavy: False}
