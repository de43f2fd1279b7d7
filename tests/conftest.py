"""Fixtures shared by several test modules.

Exact reference solutions live in :mod:`pcmb.references`; helpers that must be importable
by path stay modules of their own (``executor_models``: model classes worker processes
unpickle; ``model_loading``: the simulators of ``models/`` loaded at module level).
``fmu_dir`` builds real FMUs with pythonfmu once per session. The test process runs BLAS on
one thread (``one_blas_thread``): on a 2-core machine whose tests start worker pools, a
multithreaded eigen-solver in the test process waits for cores (a 1 s test took 50 s under
load); a test whose subject is the process's threads asks for ``all_blas_threads``.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
#: pythonfmu slaves built into FMUs by ``fmu_dir``: the example of configs/ and the tests'.
FMU_SOURCES = (
    *sorted((ROOT / "models" / "fmu").glob("*.py")),
    *sorted((ROOT / "tests" / "data" / "fmu").glob("*.py")),
)

LINEAR_MODEL = '''
import os
import time

import numpy as np


class Linear:
    """y = a t + b², z = a b: closed-form statistics; optional failure. A process with
    $LINEAR_DELAY set sleeps that many seconds a run (the config is the same without)."""

    outputs = ("y", "z")

    def __init__(self, a=1.0, b=0.0, fail_above=None):
        self.parameters = {"a": a, "b": b}
        self.fail_above = fail_above

    def simulate(self, params, times):
        a = np.asarray(params.get("a", self.parameters["a"]), float)
        b = np.asarray(params.get("b", self.parameters["b"]), float)
        a, b = np.broadcast_arrays(a, b)
        time.sleep(float(os.environ.get("LINEAR_DELAY", 0.0)) * a.size)
        y = a[:, None] * times + b[:, None] ** 2
        if self.fail_above is not None:
            if a.size == 1 and a[0] > self.fail_above:
                raise RuntimeError(f"blew up at a={a[0]}")
            y[a > self.fail_above] = np.nan
        return {"y": y, "z": np.repeat((a * b)[:, None], times.size, axis=1)}
'''


@pytest.fixture(scope="session", autouse=True)
def one_blas_thread() -> Iterator[threadpool_limits]:
    """BLAS and OpenMP limited to one thread in the test process for the whole session."""
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS is limited only once loaded)

    with threadpool_limits(limits=1) as limiter:
        yield limiter


@pytest.fixture
def all_blas_threads(one_blas_thread: threadpool_limits) -> Iterator[None]:
    """The process's own BLAS and OpenMP thread counts back, for one test."""
    one_blas_thread.restore_original_limits()
    yield
    threadpool_limits(limits=1)


@pytest.fixture
def linear_study(tmp_path: Path) -> Callable[..., Path]:
    """Write a python-kind study of the ``Linear`` model into ``tmp_path``.

    Calling the fixture, ``linear_study(order=3, extra_params="", execution="jobs: 1",
    name="linear")``, writes ``linear_model.py`` and ``<name>.yaml`` (a ~ U[1, 3],
    b ~ N(0, 1), 5 times on [0, 2], output ``tmp_path / "out.h5"``) and returns the config
    path. ``extra_params`` is appended to the model's params, e.g. ``", fail_above: 2.5"``.
    """

    def write(
        *, order: int = 3, extra_params: str = "", execution: str = "jobs: 1", name: str = "linear"
    ) -> Path:
        (tmp_path / "linear_model.py").write_text(LINEAR_MODEL)
        config = tmp_path / f"{name}.yaml"
        config.write_text(
            textwrap.dedent(
                f"""\
                name: {name}
                model:
                  kind: python
                  entry: linear_model.py:Linear
                  params: {{a: 1.0, b: 0.0{extra_params}}}
                  outputs: [y, z]
                time: {{start: 0.0, stop: 2.0, points: 5}}
                inputs:
                  a: {{dist: uniform, low: 1.0, high: 3.0}}
                  b: {{dist: normal, mean: 0.0, std: 1.0}}
                method: {{kind: collocation, order: {order}}}
                execution: {{{execution}}}
                output: {tmp_path / "out.h5"}
                """
            )
        )
        return config

    return write


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of FMUs built at test time from ``FMU_SOURCES`` (``<Name>.py`` ->
    ``<Name>.fmu``): FMI 2.0 slaves by pythonfmu, FMI 3.0 ones (importing pythonfmu3) by
    pythonfmu3. Skips when pythonfmu ships no binary for this platform."""
    from fmpy import platform, supported_platforms
    from pythonfmu import FmuBuilder
    from pythonfmu3 import FmuBuilder as Fmi3Builder

    dest = tmp_path_factory.mktemp("fmus")
    for source in FMU_SOURCES:
        fmi3 = "from pythonfmu3 import" in source.read_text(encoding="utf-8")
        built = (Fmi3Builder if fmi3 else FmuBuilder).build_FMU(source, dest=dest)
        if platform not in supported_platforms(str(built)):
            pytest.skip(f"pythonfmu ships no FMU binary for this platform ({platform})")
    return dest
