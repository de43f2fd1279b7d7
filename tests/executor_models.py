"""Small models for the executor tests, following the model protocol.

They live in an importable module (not in the test files) so that worker processes can unpickle
their factories by reference. Every model counts, per process, the nodes it simulated
(``SIMULATED``), so a test running in-process can check how many nodes were actually run.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb import batched

# Node counts of every simulate call made in this process, in order.
SIMULATED: list[int] = []


def _batch_size(params: Mapping[str, NDArray[np.float64]]) -> int:
    size = len(next(iter(params.values())))
    SIMULATED.append(size)
    return size


class StackedOscillator:
    """x'' + c x' + k x = 0, x(0) = 1, x'(0) = 0, all B nodes as one stacked ``solve_ivp``.

    Its exact solution is :func:`pcmb.references.damped_oscillator` (underdamped: c² < 4k).

    The stacked RK45 controls its error over the whole batch, so a node's values depend (in the
    last bits) on which nodes share its batch, just like the project's native models.
    """

    outputs = ("x", "v")

    def __init__(self, sleep: float = 0.0, rtol: float = 1e-8, poison_k: float = np.nan) -> None:
        self.sleep, self.rtol, self.poison_k = sleep, rtol, poison_k

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        # Imported here so that workers running only the light models start faster.
        from scipy.integrate import solve_ivp

        b = _batch_size(params)
        k, c = params["k"], params["c"]

        # The node with k == poison_k gets a NaN derivative after t = 1 (a diverging node).
        poisoned = k == self.poison_k

        def rhs(t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
            x, v = y[:b], y[b:]
            acceleration = np.where(poisoned & (t > 1.0), np.nan, -c * v - k * x)
            return np.concatenate([v, acceleration])

        y0 = np.concatenate([np.ones(b), np.zeros(b)])
        sol = solve_ivp(
            rhs, (times[0], times[-1]), y0, t_eval=times, rtol=self.rtol, atol=self.rtol * 1e-2
        )
        time.sleep(self.sleep)
        return {"x": sol.y[:b], "v": sol.y[b:]}


class Ramp:
    """y = (a + sum(z)) t, exact in floating point whatever the batch. ``z`` is optional (N, m)."""

    outputs = ("y", "pid", "batch_size", "batch_first")

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        b = _batch_size(params)
        slope = params["a"] + (params["z"].sum(axis=1) if "z" in params else 0.0)
        self.check(params)
        ones = np.ones((b, times.size))
        return {
            "y": slope[:, None] * times,
            "pid": os.getpid() * ones,  # which process ran the node
            "batch_size": b * ones,  # which batch the node was part of
            "batch_first": params["a"][0] * ones,
        }

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        """Hook for the failing variants; the plain ramp never fails."""


class PreferringRamp(Ramp):
    """A ramp that states the chunk size it prefers (model protocol hint)."""

    chunk_size = 5


class StackedRamp(Ramp):
    """A ramp that prefers the chunks of the stacked ODE models (128 nodes), whose every call
    costs its steps whatever the batch."""

    chunk_size = 128


class RaisingRamp(Ramp):
    """Raises when a node with ``a`` in ``bad`` is in the batch."""

    def __init__(self, bad: Sequence[float]) -> None:
        self.bad = np.asarray(bad, dtype=np.float64)

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        hit = params["a"][np.isin(params["a"], self.bad)]
        if hit.size:
            raise ValueError(f"a={float(hit[0])!r} is outside the model's range")


class FlakyRamp(Ramp):
    """Raises for a node with ``a`` in ``bad`` in its first ``failures`` calls, then works.

    ``nonce`` makes each test's factory distinct, so the per-process model cache does not hand
    one test the call counts of another.
    """

    def __init__(self, bad: Sequence[float], failures: int, nonce: str) -> None:
        self.bad = np.asarray(bad, dtype=np.float64)
        self.failures, self.nonce = failures, nonce
        self.calls: dict[float, int] = {}

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        for a in params["a"][np.isin(params["a"], self.bad)]:
            self.calls[float(a)] = self.calls.get(float(a), 0) + 1
            if self.calls[float(a)] <= self.failures:
                raise RuntimeError(f"transient failure {self.calls[float(a)]} at a={float(a)!r}")


class SwitchedRamp(Ramp):
    """Raises for a node with ``a`` in ``bad`` while the file ``switch`` exists; ``RAN`` keeps
    the parameters (by name, sorted) of every node it was called at in this process."""

    RAN: ClassVar[list[tuple[float, ...]]] = []

    def __init__(self, bad: Sequence[float], switch: str) -> None:
        self.bad, self.switch = np.asarray(bad, dtype=np.float64), switch

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        self.RAN.extend(zip(*(params[name].tolist() for name in sorted(params)), strict=True))
        hit = params["a"][np.isin(params["a"], self.bad)]
        if hit.size and os.path.exists(self.switch):
            raise ValueError(f"a={float(hit[0])!r} is switched off")


class PositiveRamp(SwitchedRamp):
    """A switched ramp whose ``a`` must be positive, like a stiffness: raises for a <= 0."""

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        super().check(params)
        if np.any(params["a"] <= 0):
            raise ValueError(f"a must be positive, got {float(params['a'].min())!r}")


class NanRamp(Ramp):
    """Returns NaN from t >= ``t_bad`` on for nodes with ``a`` in ``bad``."""

    def __init__(self, bad: Sequence[float], t_bad: float) -> None:
        self.bad = np.asarray(bad, dtype=np.float64)
        self.t_bad = t_bad

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        out = super().simulate(params, times)
        rows = np.isin(params["a"], self.bad)
        out["y"][np.ix_(rows, times >= self.t_bad)] = np.nan
        return out


class WrongShapeRamp(Ramp):
    """Forgets the last time point."""

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        return {name: value[:, :-1] for name, value in super().simulate(params, times).items()}


class CrashingRamp(Ramp):
    """Kills its own process (SIGSEGV or ``os._exit``) when the node ``a == victim`` runs.

    It never kills the process that built the factory (the test process): there it raises, so
    a test that expects a worker death fails loudly instead of killing pytest.
    """

    def __init__(self, victim: float, how: str, test_pid: int) -> None:
        self.victim, self.how, self.test_pid = victim, how, test_pid

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        if self.victim not in params["a"]:
            return
        if os.getpid() == self.test_pid:
            raise RuntimeError("CrashingRamp refuses to kill the test process")
        if self.how == "segv":
            os.kill(os.getpid(), signal.SIGSEGV)
        os._exit(7)


class BrokenFactory:
    """A factory that cannot build its model (like a scene file that fails to load)."""

    def __call__(self) -> Ramp:
        raise FileNotFoundError("scene.xml not found")


def oscillator_nodes(n_nodes: int) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.float64]]:
    """Inputs (k, c) of ``n_nodes`` underdamped oscillators and a 0–5 s output grid."""
    params = {"k": np.linspace(1.0, 4.0, n_nodes), "c": np.linspace(0.1, 0.5, n_nodes)[::-1]}
    return params, np.linspace(0.0, 5.0, 101)


class MutatingRamp(Ramp):
    """Writes into its input array (a model bug the executor must contain)."""

    def check(self, params: Mapping[str, NDArray[np.float64]]) -> None:
        params["a"][0] = 0.0


@batched(outputs=("huge", "flat", "z"))
def edges(params, times):
    """huge = 1e200 (1 + 0.1 a t + 0.05 b² t²); flat = 2.5; z = a b t (0 at t = 0)."""
    a, b = params["a"][:, None], params["b"][:, None]
    return {
        "huge": 1e200 * (1.0 + 0.1 * a * times + 0.05 * b**2 * times**2),
        "flat": np.full((a.size, times.size), 2.5),
        "z": a * b * times,
    }
