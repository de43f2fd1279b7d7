"""Integrate a batch of independent ODE systems as one stacked system.

A collocation batch holds B nodes of the same model, each an independent initial value
problem with d states. Integrating them as one system of B·d states in a single solver call
replaces B solver set-ups and B Python step loops by one, with every right-hand side evaluated
on whole (d, B) arrays.

Layout: a batch state is an array of shape (d, B) -- states x nodes -- so ``x1, x2 = y``
unpacks one row per state, each row a (B,) vector over the nodes. The stacked vector handed to
the solver is that array raveled (row-major), so it is reshaped without copying.

Per-node accuracy
-----------------
scipy's solvers accept a step when one error norm over all components, scaled by
``atol + rtol·|y|``, is at most 1. Over a stacked system that norm mixes the nodes: the RMS
norm of RK23, RK45, Radau and BDF lets one node's error be up to sqrt(B) times what a run of
that node alone would accept, and DOP853's norm (a ratio of its 5th- and 3rd-order estimates
summed over all components) can hide a node's error behind the others' by any factor.
:func:`solve_stacked` therefore gives the explicit methods an error norm taken per node --
each node's own norm over its d states, exactly as a separate run computes it, and the largest
of these B norms -- so every accepted step passes every node's separate-run acceptance test.
The implicit methods get ``rtol/sqrt(B)`` and ``atol/sqrt(B)`` instead, which bounds each
node's RMS norm by the stacked one. :func:`solve_projected` controls the error per node the
same way, and projects the state onto a constraint manifold after every step.

Output times
------------
:func:`solve_stacked` samples the solution at ``times`` through the solver's dense output (its
continuous extension), as ``solve_ivp(t_eval=...)`` does. The step control does not see the
interpolation error between steps, which can exceed the step error when a fast mode spans a
good part of a step; choose tolerances for the accuracy wanted at the output times and check
it against a tight reference. :func:`solve_projected` lands a step on every output time
instead, so its outputs are integrated (and projected) states.

:class:`StackedODEModel` builds the model protocol of SPEC §3 on top: a subclass states its
parameters, initial state, right-hand side and outputs, and inherits parameter handling,
validation and batched integration.
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import DOP853, RK23, RK45, solve_ivp

from pcmb.errors import ConfigError, ConfigProblem, ModelError

__all__ = [
    "StackedODEModel",
    "solve_projected",
    "solve_stacked",
]

BatchRhs = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]
BatchProjection = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]

_EXPLICIT_METHODS = ("RK23", "RK45", "DOP853")
_IMPLICIT_METHODS = ("Radau", "BDF")
# scipy clips a smaller rtol (with a warning); below it round-off dominates anyway.
_RTOL_FLOOR = 100 * np.finfo(float).eps

# Dormand–Prince 5(4) (Hairer, Nørsett & Wanner, Solving ODEs I, Table 5.2): nodes C,
# coefficients A, 5th-order weights B5 and the difference B5 − B4 of the embedded 4th order.
_DP_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
_DP_A = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
        [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
        [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
    ]
)
_DP_B5 = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
_DP_B4 = np.array([5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40])
_DP_E = _DP_B5 - _DP_B4
_DP_ERROR_ORDER = 4  # order of the embedded solution: the error estimate is O(h^5)
# Step-size controller bounds (the usual choice: scipy and Hairer use the same).
_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 10.0


# =========================================================================== stacked solve


def solve_stacked(
    rhs: BatchRhs,
    y0: ArrayLike,
    times: ArrayLike,
    *,
    t0: float = 0.0,
    method: str = "DOP853",
    rtol: float = 1e-9,
    atol: float | ArrayLike = 1e-12,
    breakpoints: Iterable[float] = (),
) -> NDArray[np.float64]:
    """Integrate B independent systems of d states as one stacked system.

    Parameters
    ----------
    rhs:
        ``rhs(t, y) -> dy/dt`` with ``y`` and the result of shape (d, B). It must treat the
        columns independently (node b's derivative depends on column b only) and must not
        modify ``y``.
    y0:
        Initial state at ``t0``, shape (d, B).
    times:
        Output times, shape (T,), strictly increasing, all ``>= t0``.
    t0:
        Time of the initial state.
    method:
        One of scipy's ``"RK23"``, ``"RK45"``, ``"DOP853"`` (explicit) or ``"Radau"``,
        ``"BDF"`` (implicit; they get the block-diagonal Jacobian sparsity of the batch, so a
        finite-difference Jacobian costs d right-hand side calls, not B·d).
    rtol, atol:
        Per-node tolerances, as for a separate run of one node: ``atol`` is a scalar or a (d,)
        vector (one value per state). Explicit methods apply them to every node's own error
        norm; implicit methods get them divided by sqrt(B) (see the module notes), with
        ``rtol`` floored at 100 machine epsilons.
    breakpoints:
        Times where ``rhs`` is discontinuous (a step input): the integration restarts there
        instead of stepping across the jump. Values outside ``(t0, times[-1])`` are ignored.

    Returns
    -------
    NDArray
        States at ``times``, shape (d, B, T).

    Raises
    ------
    ValueError
        Shapes, times, tolerances or method are invalid, or ``rhs`` returns the wrong shape.
    ModelError
        The integration failed (the solver's message, or a non-finite value in ``rhs``).
    """
    state = _as_state(y0)
    d, n_nodes = state.shape
    grid = _as_times(times, t0)
    per_state_atol = _as_atol(atol, d)
    if method not in _EXPLICIT_METHODS + _IMPLICIT_METHODS:
        choices = ", ".join(_EXPLICIT_METHODS + _IMPLICIT_METHODS)
        raise ValueError(f"method must be one of {choices}, got {method!r}")
    _check_rtol(rtol)
    options: dict[str, Any]
    if method in _IMPLICIT_METHODS:
        scale = 1.0 / math.sqrt(n_nodes)
        options = {
            "method": method,
            "rtol": max(rtol * scale, _RTOL_FLOOR),
            "atol": np.repeat(per_state_atol * scale, n_nodes),
            # Node b's states depend on node b's only: d finite-difference groups suffice.
            "jac_sparsity": scipy.sparse.kron(
                np.ones((d, d)), scipy.sparse.identity(n_nodes), format="csc"
            ),
        }
    else:
        options = {
            "method": _PER_NODE_SOLVERS[method],
            "n_nodes": n_nodes,
            "rtol": rtol,
            "atol": np.repeat(per_state_atol, n_nodes),
        }
    _check_rhs(rhs, t0, state)

    last_t = [t0]

    def fun(t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        last_t[0] = t
        return rhs(t, y.reshape(d, n_nodes)).reshape(-1)

    cuts = sorted({float(b) for b in breakpoints if t0 < b < grid[-1]})
    edges = [t0, *cuts, float(grid[-1])]
    out = np.empty((d, n_nodes, grid.size))
    y = state.reshape(-1)
    for start, stop in itertools.pairwise(edges):
        # Output times in (start, stop]; the first segment also owns t0 itself.
        inside = (grid > start) & (grid <= stop) if start > t0 else grid <= stop
        # The segment's end is always evaluated: it is the next segment's initial state.
        t_eval = np.append(grid[inside & (grid < stop)], stop)
        if start == stop:
            out[:, :, inside] = y.reshape(d, n_nodes, 1)
            continue
        try:
            with np.errstate(over="raise", invalid="raise", divide="raise"):
                sol = solve_ivp(fun, (start, stop), y, t_eval=t_eval, **options)
        except FloatingPointError as exc:
            raise ModelError(
                f"{method} integration failed near t={last_t[0]:.6g}: non-finite value in the "
                f"right-hand side ({exc})"
            ) from exc
        if sol.status != 0:
            raise ModelError(f"{method} integration failed near t={sol.t[-1]:.6g}: {sol.message}")
        values = sol.y.reshape(d, n_nodes, -1)
        out[:, :, inside] = values[:, :, : np.count_nonzero(inside)]
        y = sol.y[:, -1]
    return out


class _PerNodeNorm:
    """Mixin for scipy's explicit Runge–Kutta solvers: the error norm of a stacked (d, B)
    state is the largest per-node norm, each computed as a separate run of the node would.

    It overrides ``_estimate_error_norm(K, h, scale)``, the hook scipy's ``RungeKutta`` step
    calls with the stage derivatives K (stages, d·B) and the tolerance scale (d·B,).
    """

    def __init__(self, *args: Any, n_nodes: int, **options: Any) -> None:
        self._n_nodes = n_nodes
        super().__init__(*args, **options)

    def _by_node(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        return values.reshape(-1, self._n_nodes)  # (d, B): the stacked layout


class _PerNodeRK(_PerNodeNorm):
    """RK23 and RK45: the RMS over a node's d states of its scaled error estimate."""

    def _estimate_error_norm(self, K: NDArray, h: float, scale: NDArray) -> float:
        scaled = self._by_node(self._estimate_error(K, h) / scale)
        return float(np.max(np.sqrt(np.mean(scaled**2, axis=0))))


class _PerNodeDOP853(_PerNodeNorm):
    """DOP853: its combined 5th/3rd-order estimate (Hairer's DOP853), per node."""

    def _estimate_error_norm(self, K: NDArray, h: float, scale: NDArray) -> float:
        err5 = np.sum(self._by_node(K.T @ self.E5 / scale) ** 2, axis=0)
        err3 = np.sum(self._by_node(K.T @ self.E3 / scale) ** 2, axis=0)
        denominator = err5 + 0.01 * err3
        d = scale.size // self._n_nodes
        active = denominator > 0  # a node with both estimates zero has zero error
        norms = np.zeros_like(err5)
        norms[active] = abs(h) * err5[active] / np.sqrt(denominator[active] * d)
        return float(np.max(norms))


class _PerNodeRK23(_PerNodeRK, RK23):
    """RK23 with the per-node error norm."""


class _PerNodeRK45(_PerNodeRK, RK45):
    """RK45 with the per-node error norm."""


class _PerNodeDOP853Solver(_PerNodeDOP853, DOP853):
    """DOP853 with the per-node error norm."""


_PER_NODE_SOLVERS: dict[str, type] = {
    "RK23": _PerNodeRK23,
    "RK45": _PerNodeRK45,
    "DOP853": _PerNodeDOP853Solver,
}


# =========================================================================== projected solve


def solve_projected(
    rhs: BatchRhs,
    project: BatchProjection,
    y0: ArrayLike,
    times: ArrayLike,
    *,
    t0: float = 0.0,
    rtol: float = 1e-9,
    atol: float | ArrayLike = 1e-12,
    max_steps: int = 1_000_000,
) -> NDArray[np.float64]:
    """Integrate a batch with an embedded Runge–Kutta pair and a projection after every step.

    The method is Dormand–Prince 5(4) with local extrapolation (the 5th-order solution is
    kept). Each accepted step is followed by ``project``, which maps the state back onto the
    constraint manifold (e.g. position and velocity constraints of a mechanical system, Part I
    Eq. 5–6); the next step starts from the projected state. Steps are shortened to land on
    every output time, so outputs are projected states, not interpolants.

    Error control is per node: the error estimate of node b is scaled by
    ``atol + rtol·max(|y|, |y_new|)`` and its RMS over the d states is taken; a step is
    accepted when the largest of these B norms is at most 1. Every node therefore meets the
    acceptance test of a separate run; the batch shares one step size (the smallest any node
    needs).

    Parameters
    ----------
    rhs:
        ``rhs(t, y) -> dy/dt``, ``y`` and result of shape (d, B).
    project:
        ``project(t, y) -> y_projected``, shape (d, B) in and out. Applied to the initial state
        too, so a slightly inconsistent initial state is made consistent.
    y0:
        Initial state at ``t0``, shape (d, B).
    times:
        Output times, shape (T,), strictly increasing, all ``>= t0``.
    t0:
        Time of the initial state.
    rtol, atol:
        Per-node tolerances; ``atol`` scalar or (d,).
    max_steps:
        Attempted steps (accepted or rejected) allowed before giving up.

    Returns
    -------
    NDArray
        Projected states at ``times``, shape (d, B, T).

    Raises
    ------
    ValueError
        Invalid shapes, times or tolerances, or ``rhs``/``project`` return the wrong shape.
    ModelError
        The step size underflowed, ``max_steps`` was exceeded, or a value became non-finite.
    """
    state = _as_state(y0)
    d, n_nodes = state.shape
    grid = _as_times(times, t0)
    tol_abs = _as_atol(atol, d)[:, None]
    _check_rtol(rtol)
    if max_steps < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    _check_rhs(rhs, t0, state)
    t = float(t0)
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            y = _checked_projection(project, t, state)
            out = np.empty((d, n_nodes, grid.size))
            done = int(np.searchsorted(grid, t, side="right"))  # outputs at t0: the start
            out[:, :, :done] = y[:, :, None]
            if done == grid.size:
                return out
            h = _initial_step(rhs, t, y, rtol, tol_abs, grid[-1] - t)
            stages = np.empty((_DP_C.size, d, n_nodes))
            for _ in range(max_steps):
                if done == grid.size:
                    return out
                target = grid[done]
                step = min(h, target - t)
                if t + step == t:
                    raise ModelError(f"step size underflow at t={t:.6g}")
                y_new = _dopri_step(rhs, t, y, step, stages)
                error = step * (_DP_E @ stages.reshape(_DP_C.size, -1)).reshape(y.shape)
                scale = tol_abs + rtol * np.maximum(np.abs(y), np.abs(y_new))
                norm = float(np.max(np.sqrt(np.mean((error / scale) ** 2, axis=0))))
                factor = _step_factor(norm)
                if norm <= 1.0:
                    t = target if step == target - t else t + step
                    y = _checked_projection(project, t, y_new)
                    if t == target:
                        out[:, :, done] = y
                        done += 1
                    h = step * factor
                else:
                    h = step * min(factor, 1.0)
    except FloatingPointError as exc:
        raise ModelError(f"non-finite value near t={t:.6g} ({exc})") from exc
    raise ModelError(f"no result after {max_steps} steps (reached t={t:.6g})")


def _dopri_step(
    rhs: BatchRhs,
    t: float,
    y: NDArray[np.float64],
    h: float,
    stages: NDArray[np.float64],
) -> NDArray[np.float64]:
    """One Dormand–Prince step; fills ``stages`` (7, d, B) and returns the 5th-order state."""
    flat = stages.reshape(_DP_C.size, -1)  # a view: stage sums as one small matrix product
    stages[0] = rhs(t, y)
    for i in range(1, _DP_C.size):
        y_stage = y + h * (_DP_A[i, :i] @ flat[:i]).reshape(y.shape)
        stages[i] = rhs(t + _DP_C[i] * h, y_stage)
    # The last row of A is B5 (first same as last): the last stage point is the new state.
    return y_stage


def _step_factor(norm: float) -> float:
    if norm == 0.0:
        return _MAX_FACTOR
    proposal = _SAFETY * norm ** (-1.0 / (_DP_ERROR_ORDER + 1))
    return min(_MAX_FACTOR, max(_MIN_FACTOR, proposal))


def _initial_step(
    rhs: BatchRhs,
    t: float,
    y: NDArray[np.float64],
    rtol: float,
    tol_abs: NDArray[np.float64],
    span: float,
) -> float:
    """Starting step of Hairer, Nørsett & Wanner (II.4), with the per-node maximum norm."""

    def norm(v: NDArray[np.float64]) -> float:
        return float(np.max(np.sqrt(np.mean((v / scale) ** 2, axis=0))))

    scale = tol_abs + rtol * np.abs(y)
    f0 = rhs(t, y)
    d0, d1 = norm(y), norm(f0)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, span)
    f1 = rhs(t + h0, y + h0 * f0)
    d2 = norm(f1 - f0) / h0
    if max(d1, d2) <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (_DP_ERROR_ORDER + 1))
    return min(100 * h0, h1, span)


def _checked_projection(
    project: BatchProjection, t: float, y: NDArray[np.float64]
) -> NDArray[np.float64]:
    projected = np.asarray(project(t, y), dtype=float)
    if projected.shape != y.shape:
        raise ValueError(f"project returned shape {projected.shape}, expected {y.shape}")
    return projected


# =========================================================================== model base


class StackedODEModel(ABC):
    """Base class for batched ODE models that follow the model protocol (SPEC §3).

    A subclass is its physics: it sets ``outputs`` and implements :meth:`_initial_state`,
    :meth:`_rhs` and :meth:`_observe` on (d, B) state arrays and (B,) parameter arrays (and
    :meth:`_breakpoints` when its forcing jumps). This class supplies the rest: nominal
    parameters by name, validation, merging the uncertain inputs of a batch with the nominal
    values, and one stacked integration per batch (:func:`solve_stacked`).

    The initial state is the state at t = 0; output times must be ``>= 0``.

    Parameters
    ----------
    defaults:
        Every parameter's name and default nominal value.
    given:
        Nominal values that override the defaults (the constructor's keywords).
    rtol, atol:
        Per-node integration tolerances (``atol`` scalar or one value per state).
    method:
        A :func:`solve_stacked` method.

    Attributes
    ----------
    outputs:
        Names of the observables :meth:`simulate` returns.
    parameters:
        Read-only mapping name -> nominal value.

    Raises
    ------
    ValueError
        An unknown parameter name, a non-numeric or non-finite value, a value that violates
        the subclass's sign constraints (``_positive``, ``_nonnegative``), or an invalid
        tolerance or method.
    """

    outputs: ClassVar[tuple[str, ...]]
    # Parameters that must be > 0 (masses, lengths) or >= 0 (currents, damping).
    _positive: ClassVar[frozenset[str]] = frozenset()
    _nonnegative: ClassVar[frozenset[str]] = frozenset()
    initial_time: ClassVar[float] = 0.0
    #: Nodes per ``simulate`` call the executor should use (model protocol hint). A stacked
    #: solve costs a per-step Python overhead for the whole batch plus a small per-node
    #: share; measured on the quarter car (2,200 steps): 0.24 s for 1 node, 0.52 s for 216.
    #: At ~128 nodes the two are comparable, so larger chunks stop paying.
    chunk_size: ClassVar[int] = 128

    def __init__(
        self,
        defaults: Mapping[str, float],
        given: Mapping[str, object],
        *,
        rtol: float,
        atol: float | ArrayLike,
        method: str = "DOP853",
    ) -> None:
        owner = type(self).__name__
        unknown = [name for name in given if name not in defaults]
        if unknown:
            raise ValueError(
                f"{owner} has no parameter {', '.join(map(repr, unknown))} "
                f"(parameters: {', '.join(defaults)})"
            )
        values = {}
        for name, default in defaults.items():
            value = given.get(name, default)
            if isinstance(value, bool) or not isinstance(value, int | float | np.number):
                raise ValueError(f"{owner} parameter {name!r} must be a number, got {value!r}")
            values[name] = float(value)
        self._check_values({name: np.array([v]) for name, v in values.items()}, owner)
        _check_rtol(rtol)
        tolerance = np.asarray(atol, dtype=float)
        if tolerance.ndim > 1 or not (np.isfinite(tolerance).all() and (tolerance > 0).all()):
            raise ValueError(f"atol must be a positive scalar or (d,) vector, got {atol!r}")
        if method not in _EXPLICIT_METHODS + _IMPLICIT_METHODS:
            choices = ", ".join(_EXPLICIT_METHODS + _IMPLICIT_METHODS)
            raise ValueError(f"method must be one of {choices}, got {method!r}")
        self.parameters: Mapping[str, float] = MappingProxyType(values)
        self.rtol = float(rtol)
        self.atol = atol
        self.method = method

    # ------------------------------------------------------------------ protocol

    def simulate(
        self, params: Mapping[str, ArrayLike], times: ArrayLike
    ) -> dict[str, NDArray[np.float64]]:
        """Run one batch of nodes.

        Parameters
        ----------
        params:
            The uncertain inputs only, name -> (B,) values (one B for all). Every other
            parameter keeps its nominal value. Empty: one run at the nominal values (B = 1).
        times:
            Output times, shape (T,), strictly increasing, ``>= 0``.

        Returns
        -------
        dict[str, NDArray]
            Every name in ``outputs`` -> (B, T).

        Raises
        ------
        ValueError
            An unknown parameter, inconsistent or non-1-D shapes, an invalid value at some
            node, or invalid times.
        ModelError
            The integration failed.
        """
        grid = _as_times(times, self.initial_time)
        p = self._batch(params)
        states = self._integrate(p, grid)
        return self._observe(grid, states, p)

    def check_times(self, times: ArrayLike) -> None:
        """Reject an output grid this model cannot produce, before anything runs.

        Raises
        ------
        ConfigError
            At ``time``: the grid starts before t = 0 or is not strictly increasing.
        """
        try:
            _as_times(times, self.initial_time)
        except ValueError as exc:
            raise ConfigError([ConfigProblem(path="time", message=str(exc))]) from None

    # ------------------------------------------------------------------ physics hooks

    @abstractmethod
    def _initial_state(self, p: Mapping[str, NDArray[np.float64]]) -> NDArray[np.float64]:
        """State at t = 0, (d, B), from the (B,) parameter arrays ``p``."""

    @abstractmethod
    def _rhs(
        self, t: float, y: NDArray[np.float64], p: Mapping[str, NDArray[np.float64]]
    ) -> NDArray[np.float64]:
        """dy/dt at time ``t``, (d, B)."""

    @abstractmethod
    def _observe(
        self,
        times: NDArray[np.float64],
        states: NDArray[np.float64],
        p: Mapping[str, NDArray[np.float64]],
    ) -> dict[str, NDArray[np.float64]]:
        """Outputs from the (d, B, T) states at ``times``: name -> (B, T)."""

    def _breakpoints(self, p: Mapping[str, NDArray[np.float64]]) -> Sequence[float]:
        """Times where the right-hand side jumps (none by default)."""
        return ()

    def _integrate(
        self, p: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """States at ``times``, (d, B, T): one stacked solve of the whole batch."""
        return solve_stacked(
            lambda t, y: self._rhs(t, y, p),
            self._initial_state(p),
            times,
            t0=self.initial_time,
            method=self.method,
            rtol=self.rtol,
            atol=self.atol,
            breakpoints=self._breakpoints(p),
        )

    # ------------------------------------------------------------------ parameters

    def _batch(self, params: Mapping[str, ArrayLike]) -> dict[str, NDArray[np.float64]]:
        """Every parameter as a (B,) array: the uncertain ones from ``params``, others nominal."""
        owner = type(self).__name__
        unknown = [name for name in params if name not in self.parameters]
        if unknown:
            raise ValueError(
                f"{owner} has no parameter {', '.join(map(repr, unknown))} "
                f"(parameters: {', '.join(self.parameters)})"
            )
        arrays = {name: np.asarray(value, dtype=float) for name, value in params.items()}
        shapes = {name: a.shape for name, a in arrays.items()}
        if any(len(shape) != 1 for shape in shapes.values()) or len(set(shapes.values())) > 1:
            raise ValueError(
                f"{owner} parameters must all be 1-D arrays of one length B, got {shapes}"
            )
        n_nodes = next(iter(shapes.values()))[0] if shapes else 1
        if n_nodes == 0:
            raise ValueError(f"{owner} got an empty batch (B = 0)")
        full = {name: np.full(n_nodes, value) for name, value in self.parameters.items()}
        full.update(arrays)
        self._check_values(full, owner)
        return full

    def _check_values(self, p: Mapping[str, NDArray[np.float64]], owner: str) -> None:
        for name, values in p.items():
            bad = ~np.isfinite(values)
            if name in self._positive:
                bad |= ~(values > 0)
            elif name in self._nonnegative:
                bad |= ~(values >= 0)
            if bad.any():
                node = int(np.flatnonzero(bad)[0])
                need = (
                    "positive"
                    if name in self._positive
                    else "non-negative"
                    if name in self._nonnegative
                    else "finite"
                )
                raise ValueError(
                    f"{owner} parameter {name!r} must be {need}, got {float(values[node])!r}"
                    + (f" at node {node}" if values.size > 1 else "")
                )


# =========================================================================== validation


def _as_state(y0: ArrayLike) -> NDArray[np.float64]:
    state = np.array(y0, dtype=float)  # a copy: the solver must not alias the caller's array
    if state.ndim != 2 or 0 in state.shape:
        raise ValueError(f"y0 must have shape (d, B) with d, B >= 1, got {state.shape}")
    if not np.isfinite(state).all():
        raise ValueError("y0 has non-finite values")
    return state


def _as_times(times: ArrayLike, t0: float) -> NDArray[np.float64]:
    grid = np.asarray(times, dtype=float)
    if grid.ndim != 1 or grid.size == 0:
        raise ValueError(f"times must be a non-empty 1-D array, got shape {grid.shape}")
    if not np.isfinite(grid).all():
        raise ValueError("times has non-finite values")
    if np.any(np.diff(grid) <= 0):
        raise ValueError("times must be strictly increasing")
    if grid[0] < t0:
        raise ValueError(f"times must start at or after the initial time {t0:g}, got {grid[0]:g}")
    return grid


def _as_atol(atol: float | ArrayLike, d: int) -> NDArray[np.float64]:
    value = np.asarray(atol, dtype=float)
    if value.ndim == 0:
        value = np.full(d, float(value))
    if value.shape != (d,):
        raise ValueError(
            f"atol must be a scalar or have one value per state ({d}), got {value.shape}"
        )
    if not (np.isfinite(value).all() and (value > 0).all()):
        raise ValueError(f"atol must be positive and finite, got {value}")
    return value


def _check_rtol(rtol: float) -> None:
    if not (math.isfinite(rtol) and _RTOL_FLOOR <= rtol < 1):
        raise ValueError(f"rtol must be in [{_RTOL_FLOOR:.3g}, 1), got {rtol!r}")


def _check_rhs(rhs: BatchRhs, t0: float, state: NDArray[np.float64]) -> None:
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        try:
            derivative = np.asarray(rhs(t0, state.copy()), dtype=float)
        except FloatingPointError as exc:
            raise ModelError(
                f"non-finite value in the right-hand side at t={t0:g} ({exc})"
            ) from exc
    if derivative.shape != state.shape:
        raise ValueError(f"rhs returned shape {derivative.shape}, expected {state.shape}")
