"""Integrate a batch of independent ODE systems as one stacked system.

A collocation batch holds B nodes of the same model, each an independent initial value problem
with d states, held as one (d, B) array -- states x nodes -- and integrated in one solver call
with every right-hand side evaluated on whole (d, B) arrays. The explicit methods
(:mod:`pcmb.integrate.runge_kutta`) control each node's error by its own norm; the implicit ones
(scipy's Radau and BDF) get tolerances divided by sqrt(B), which bounds every node's RMS norm by
the stacked one. :class:`StackedODEModel` builds the model protocol (docs/models.md) on top.
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.errors import ConfigError, ConfigProblem, ModelError
from pcmb.integrate.runge_kutta import (
    PAIRS,
    RK45,
    initial_step,
    integrate,
    node_rms,
    rk_step,
    step_factor,
)

__all__ = [
    "StackedODEModel",
    "solve_projected",
    "solve_stacked",
]

BatchRhs = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]
BatchProjection = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]

_EXPLICIT_METHODS = tuple(PAIRS)
_IMPLICIT_METHODS = ("Radau", "BDF")
# scipy clips a smaller rtol (with a warning); below it round-off dominates anyway.
_RTOL_FLOOR = 100 * np.finfo(float).eps


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
        An explicit pair of :mod:`pcmb.integrate.runge_kutta` (``"RK23"``, ``"RK45"``,
        ``"DOP853"``) or scipy's implicit ``"Radau"``, ``"BDF"`` (with the block-diagonal
        Jacobian sparsity of the batch, so a finite-difference Jacobian costs d right-hand
        side calls, not B·d).
    rtol, atol:
        Per-node tolerances, as for a separate run of one node: ``atol`` is a scalar or a (d,)
        vector (one value per state). Explicit methods apply them to every node's own error
        norm; implicit methods get them divided by sqrt(B), with ``rtol`` floored at 100
        machine epsilons.
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

    Notes
    -----
    Outputs come from the dense output (continuous extension) of the step that reaches them,
    as with ``solve_ivp(t_eval=...)``. Step control does not see the interpolation error,
    which can exceed the step error when a fast mode spans a good part of a step.
    """
    state = _as_state(y0)
    d, n_nodes = state.shape
    grid = _as_times(times, t0)
    per_state_atol = _as_atol(atol, d)
    if method not in _EXPLICIT_METHODS + _IMPLICIT_METHODS:
        choices = ", ".join(_EXPLICIT_METHODS + _IMPLICIT_METHODS)
        raise ValueError(f"method must be one of {choices}, got {method!r}")
    _check_rtol(rtol)
    _check_rhs(rhs, t0, state)

    last_t = [t0]

    def fun(t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        last_t[0] = t
        return np.asarray(rhs(t, y.reshape(d, n_nodes)), dtype=float).reshape(-1)

    # advance(start, stop, y, t_eval) -> states at t_eval, (d·B, len(t_eval)).
    if method in _IMPLICIT_METHODS:
        import scipy.sparse  # deferred: a quarter second of import that explicit methods skip
        from scipy.integrate import solve_ivp

        scale = 1.0 / math.sqrt(n_nodes)
        options: dict[str, Any] = {
            "method": method,
            "rtol": max(rtol * scale, _RTOL_FLOOR),
            "atol": np.repeat(per_state_atol * scale, n_nodes),
            # Node b's states depend on node b's only: d finite-difference groups suffice.
            "jac_sparsity": scipy.sparse.kron(
                np.ones((d, d)), scipy.sparse.identity(n_nodes), format="csc"
            ),
        }

        def advance(
            start: float, stop: float, y: NDArray[np.float64], t_eval: NDArray[np.float64]
        ) -> NDArray[np.float64]:
            sol = solve_ivp(fun, (start, stop), y, t_eval=t_eval, **options)
            if sol.status != 0:
                raise ModelError(
                    f"{method} integration failed near t={last_t[0]:.6g}: {sol.message}"
                )
            return sol.y

    else:
        pair, tolerance = PAIRS[method], np.repeat(per_state_atol, n_nodes)

        def advance(
            start: float, stop: float, y: NDArray[np.float64], t_eval: NDArray[np.float64]
        ) -> NDArray[np.float64]:
            return integrate(
                pair, fun, start, y, t_eval, rtol=rtol, atol=tolerance, n_nodes=n_nodes
            )

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
                values = advance(start, stop, y, t_eval)
        except FloatingPointError as exc:
            raise ModelError(
                f"{method} integration failed near t={last_t[0]:.6g}: non-finite value in the "
                f"right-hand side ({exc})"
            ) from exc
        out[:, :, inside] = values.reshape(d, n_nodes, -1)[:, :, : np.count_nonzero(inside)]
        y = values[:, -1]
    return out


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
    needs). Step, norm, starting step (measured with the same per-node norm) and step-size
    rule are those of :data:`pcmb.integrate.runge_kutta.RK45`; unlike :func:`solve_stacked`,
    a step right after a rejection may grow.

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
    tolerance = np.repeat(_as_atol(atol, d), n_nodes)
    _check_rtol(rtol)
    if max_steps < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    _check_rhs(rhs, t0, state)

    def fun(t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(rhs(t, y.reshape(d, n_nodes)), dtype=float).reshape(-1)

    def per_node(x: NDArray[np.float64]) -> float:
        return node_rms(x, n_nodes)

    t = float(t0)
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            y = _checked_projection(project, t, state).reshape(-1)
            out = np.empty((d, n_nodes, grid.size))
            done = int(np.searchsorted(grid, t, side="right"))  # outputs at t0: the start
            out[:, :, :done] = y.reshape(d, n_nodes, 1)
            if done == grid.size:
                return out
            f = fun(t, y)
            h = initial_step(
                fun, t, y, f, grid[-1] - t, RK45.error_order, rtol, tolerance, per_node
            )
            stages = RK45.stage_storage(y.size)
            for _ in range(max_steps):
                target = grid[done]
                step = min(h, target - t)
                if t + step == t:
                    raise ModelError(f"step size underflow at t={t:.6g}")
                y_new, _ = rk_step(RK45, fun, t, y, f, step, stages)
                scale = tolerance + np.maximum(np.abs(y), np.abs(y_new)) * rtol
                norm = RK45.error_norm(stages, step, scale, n_nodes)
                factor = step_factor(norm, RK45.error_order)
                if norm <= 1.0:
                    t = target if step == target - t else t + step
                    y = _checked_projection(project, t, y_new.reshape(d, n_nodes)).reshape(-1)
                    if t == target:
                        out[:, :, done] = y.reshape(d, n_nodes)
                        done += 1
                        if done == grid.size:
                            return out
                    f = fun(t, y)
                    h = step * factor
                else:
                    h = step * min(factor, 1.0)
    except FloatingPointError as exc:
        raise ModelError(f"non-finite value near t={t:.6g} ({exc})") from exc
    raise ModelError(f"no result after {max_steps} steps (reached t={t:.6g})")


def _checked_projection(
    project: BatchProjection, t: float, y: NDArray[np.float64]
) -> NDArray[np.float64]:
    projected = np.asarray(project(t, y), dtype=float)
    if projected.shape != y.shape:
        raise ValueError(f"project returned shape {projected.shape}, expected {y.shape}")
    return projected


# =========================================================================== model base


class StackedODEModel(ABC):
    """Base class for batched ODE models that follow the model protocol (docs/models.md).

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
    # Parameters that may also come as (B, m) arrays: field inputs (a random process on a
    # grid); their nominal value is a number, the same at every point.
    _fields: ClassVar[frozenset[str]] = frozenset()
    initial_time: ClassVar[float] = 0.0
    #: Most nodes per ``simulate`` call (model protocol hint; the executor makes its chunks
    #: as equal as can be within it: 225 runs go in 113 + 112). A stacked
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
        p = self._prepare(self._batch(params))
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

    def _prepare(self, p: dict[str, NDArray[np.float64]]) -> Mapping[str, Any]:
        """The batch's parameters as the physics hooks receive them; override to compute
        per-batch data once (a spline through a field input). Default: ``p`` unchanged."""
        return p

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
        """Every parameter as a (B,) array ((B, m) for a field input given one): the uncertain
        ones from ``params``, others nominal."""
        owner = type(self).__name__
        unknown = [name for name in params if name not in self.parameters]
        if unknown:
            raise ValueError(
                f"{owner} has no parameter {', '.join(map(repr, unknown))} "
                f"(parameters: {', '.join(self.parameters)})"
            )
        arrays = {name: np.asarray(value, dtype=float) for name, value in params.items()}
        shapes = {name: a.shape for name, a in arrays.items()}
        allowed = all(
            len(shape) == 1 or (len(shape) == 2 and name in self._fields)
            for name, shape in shapes.items()
        )
        if not allowed or len({shape[0] for shape in shapes.values()}) > 1:
            fields = f" ({', '.join(sorted(self._fields))} also (B, m))" if self._fields else ""
            raise ValueError(
                f"{owner} parameters must all be 1-D arrays of one length B{fields}, got {shapes}"
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
                where = np.unravel_index(int(np.flatnonzero(bad)[0]), values.shape)
                node = int(where[0])
                need = (
                    "positive"
                    if name in self._positive
                    else "non-negative"
                    if name in self._nonnegative
                    else "finite"
                )
                raise ValueError(
                    f"{owner} parameter {name!r} must be {need}, got {float(values[where])!r}"
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
