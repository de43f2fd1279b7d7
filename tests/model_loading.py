"""Load the native simulators of ``models/`` by file path, as pcmb does, and run references.

``models/`` is not a package: pcmb imports a model file by its path with the file's folder on
``sys.path`` (so a model can import a sibling such as ``terrain_process``). The tests do the
same here instead of importing ``models`` as a package.
"""

from __future__ import annotations

import functools
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

MODELS_DIR = Path(__file__).resolve().parents[1] / "models"
CONFIGS_DIR = Path(__file__).resolve().parents[1] / "configs"

# The tight per-node reference of the issue: a separate DOP853 run at rtol 1e-11.
REFERENCE_RTOL = 1e-11
# Global error allowance in units of rtol. A step controller that keeps each local error
# within rtol (relative to the state) gives, on stable non-chaotic problems over a few dozen
# oscillations or time constants, a global error of a modest multiple of rtol; 100 covers
# that accumulation.
GLOBAL_FACTOR = 100


@functools.cache
def load_model_module(stem: str) -> ModuleType:
    """Import ``models/<stem>.py`` by path (once per test session)."""
    path = MODELS_DIR / f"{stem}.py"
    spec = importlib.util.spec_from_file_location(f"pcmb_test_models_{stem}", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(MODELS_DIR))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(MODELS_DIR))
    return module


def model_class(stem: str, name: str) -> type:
    """The class ``name`` of ``models/<stem>.py``."""
    return getattr(load_model_module(stem), name)


def reference_run(
    rhs: Callable[[float, NDArray[np.float64]], NDArray[np.float64]],
    y0: NDArray[np.float64],
    times: NDArray[np.float64],
    *,
    atol: float,
    t0: float = 0.0,
) -> NDArray[np.float64]:
    """One node alone, tight: plain ``solve_ivp`` DOP853 at rtol 1e-11; states (d, T)."""
    sol = solve_ivp(
        rhs,
        (t0, times[-1]),
        np.asarray(y0, dtype=float),
        method="DOP853",
        t_eval=times,
        rtol=REFERENCE_RTOL,
        atol=atol,
    )
    if sol.status != 0:
        raise RuntimeError(sol.message)
    return sol.y


def gauss_legendre_grid(*ranges: tuple[float, float], points: int) -> NDArray[np.float64]:
    """Tensor grid of ``points`` Gauss–Legendre points per range, shape (points**n, n)."""
    nodes, _ = np.polynomial.legendre.leggauss(points)
    axes = [0.5 * (lo + hi) + 0.5 * (hi - lo) * nodes for lo, hi in ranges]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1)
