"""Tests of pcmb.integrate.runge_kutta (the explicit pairs) and pcmb.integrate.stacked_ode
(stacked and projected batch integration, and the model base).

Accuracy bounds: an integrator that keeps every step's local error within rtol (relative to
the state) gives a global error of a modest multiple of rtol on these stable, non-chaotic
problems over a few dozen oscillations or time constants. The tests allow 100·rtol (times
the solution's scale) for that accumulation, against closed-form solutions.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.integrate
from model_loading import GLOBAL_FACTOR
from scipy.integrate import solve_ivp

from pcmb.errors import ConfigError, ModelError
from pcmb.integrate.runge_kutta import DOP853, PAIRS, RK23, RK45, rk_step
from pcmb.integrate.stacked_ode import StackedODEModel, solve_projected, solve_stacked


def oscillators(omega: np.ndarray):
    """x'' = -ω² x per node: rhs on (2, B) states."""

    def rhs(t, y):
        x, v = y
        return np.stack([v, -(omega**2) * x])

    return rhs


# =========================================================================== solve_stacked


def test_stacked_oscillators_match_closed_form():
    omega = np.linspace(1.0, 5.0, 40)
    amplitude = np.linspace(0.5, 2.0, 40)
    times = np.linspace(0.0, 10.0, 201)
    y0 = np.stack([amplitude, np.zeros_like(amplitude)])
    rtol = 1e-9
    states = solve_stacked(oscillators(omega), y0, times, rtol=rtol, atol=1e-12)
    assert states.shape == (2, 40, 201)
    exact = amplitude[:, None] * np.cos(omega[:, None] * times)
    assert np.abs(states[0] - exact).max() <= GLOBAL_FACTOR * rtol * amplitude.max()
    assert np.array_equal(states[:, :, 0], y0)  # t0 is an output time: the initial state


def test_one_node_among_idle_ones_keeps_its_own_accuracy():
    """The worst case of a stacked norm: one active node, B − 1 nodes with zero error.

    A plain stacked solver hides the active node's error behind sqrt(B) idle nodes; with the
    per-node error norm the solver applies exactly the acceptance test of a separate run of
    that node, so its trajectory is the separate run's, up to round-off.
    """
    n_nodes, omega, rtol, atol = 200, 5.0, 1e-7, 1e-10
    times = np.linspace(0.0, 10.0, 101)
    y0 = np.zeros((2, n_nodes))
    y0[0, 0] = 1.0  # node 0 oscillates, the others stay at rest
    rhs = oscillators(np.full(n_nodes, omega))
    batch = solve_stacked(rhs, y0, times, rtol=rtol, atol=atol)
    alone = solve_stacked(oscillators(np.array([omega])), y0[:, :1], times, rtol=rtol, atol=atol)
    exact = np.cos(omega * times)
    # Same accepted steps, so the same trajectory up to the last bits of the step sizes.
    assert np.abs(batch[0, 0] - alone[0, 0]).max() <= 1e-12
    error_alone = np.abs(alone[0, 0] - exact).max()
    assert error_alone <= GLOBAL_FACTOR * rtol

    # Teeth: the plain stacked call at the same tolerances lets node 0 drift much further.
    plain = solve_ivp(
        lambda t, y: rhs(t, y.reshape(2, n_nodes)).ravel(),
        (0.0, 10.0),
        y0.ravel(),
        method="DOP853",
        t_eval=times,
        rtol=rtol,
        atol=atol,
    )
    error_plain = np.abs(plain.y.reshape(2, n_nodes, -1)[0, 0] - exact).max()
    assert error_plain > 3 * error_alone


def test_every_node_of_a_batch_is_at_least_as_accurate_as_promised():
    rng = np.random.default_rng(0)
    omega = rng.uniform(0.5, 6.0, 300)
    times = np.linspace(0.0, 8.0, 81)
    rtol = 1e-8
    y0 = np.stack([np.ones(300), np.zeros(300)])
    states = solve_stacked(oscillators(omega), y0, times, rtol=rtol, atol=1e-11)
    per_node = np.abs(states[0] - np.cos(omega[:, None] * times)).max(axis=1)
    assert per_node.max() <= GLOBAL_FACTOR * rtol


def test_breakpoints_restart_at_each_nodes_switching_time():
    """y' = -y + H(t - s) per node: exact 1 - exp(-(t - s)) after its switch time s."""
    switch = np.array([0.5, 1.0, 1.5])
    times = np.linspace(0.0, 4.0, 81)  # contains every switch time exactly

    def rhs(t, y):
        return -y + (t >= switch)[None, :]

    rtol = 1e-9
    states = solve_stacked(rhs, np.zeros((1, 3)), times, rtol=rtol, atol=1e-12, breakpoints=switch)
    exact = np.where(times >= switch[:, None], 1 - np.exp(-(times - switch[:, None])), 0.0)
    assert np.abs(states[0] - exact).max() <= GLOBAL_FACTOR * rtol


@pytest.mark.parametrize("method", ["Radau", "BDF"])
def test_implicit_methods_on_a_stiff_batch(method):
    """y' = -λ (y - cos t), y(0) = 0, with λ up to 1e5: closed form below."""
    lam = np.array([1e3, 1e4, 1e5])
    times = np.linspace(0.0, 2.0, 41)

    def rhs(t, y):
        return -lam[None, :] * (y - np.cos(t))

    rtol = 1e-8
    states = solve_stacked(rhs, np.zeros((1, 3)), times, method=method, rtol=rtol, atol=1e-12)
    lam_, t = lam[:, None], times[None, :]
    exact = (lam_**2 * np.cos(t) + lam_ * np.sin(t) - lam_**2 * np.exp(-lam_ * t)) / (lam_**2 + 1)
    assert np.abs(states[0] - exact).max() <= GLOBAL_FACTOR * rtol


def test_stacked_failure_is_a_model_error():
    # y' = y² from y(0) = 1 blows up at t = 1.
    with pytest.raises(ModelError, match="failed near t="):
        solve_stacked(lambda t, y: y**2, np.ones((1, 2)), np.linspace(0.0, 2.0, 5))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"y0": np.ones(3)}, "y0 must have shape"),
        ({"times": np.array([0.0, 2.0, 1.0])}, "strictly increasing"),
        ({"times": np.array([-1.0, 1.0])}, "initial time"),
        ({"method": "LSODA"}, "method must be one of"),
        ({"rtol": 0.0}, "rtol must be"),
        ({"atol": np.ones(3)}, "one value per state"),
        ({"atol": -1.0}, "atol must be positive"),
    ],
)
def test_stacked_rejects_bad_arguments(kwargs, message):
    arguments = {
        "rhs": lambda t, y: -y,
        "y0": np.ones((2, 4)),
        "times": np.linspace(0.0, 1.0, 3),
        **kwargs,
    }
    rhs, y0, times = arguments.pop("rhs"), arguments.pop("y0"), arguments.pop("times")
    with pytest.raises(ValueError, match=message):
        solve_stacked(rhs, y0, times, **arguments)


def test_stacked_rejects_an_rhs_of_the_wrong_shape():
    with pytest.raises(ValueError, match="rhs returned shape"):
        solve_stacked(lambda t, y: y[0], np.ones((2, 4)), np.linspace(0.0, 1.0, 3))


# =========================================================================== Runge–Kutta pairs

EPS = np.finfo(float).eps


@functools.cache
def rooted_trees(order: int) -> tuple[tuple, ...]:
    """Rooted trees with ``order`` vertices, each written as the sorted tuple of its subtrees."""
    return tuple(sorted(set(_forests(order - 1))))


@functools.cache
def _forests(size: int) -> tuple[tuple, ...]:
    """Multisets of rooted trees with ``size`` vertices in all, as sorted tuples."""
    if size == 0:
        return ((),)
    found = set()
    for first in range(1, size + 1):
        for tree in rooted_trees(first):
            for rest in _forests(size - first):
                found.add(tuple(sorted((tree, *rest))))
    return tuple(found)


def tree_order(tree: tuple) -> int:
    return 1 + sum(tree_order(child) for child in tree)


def density(tree: tuple) -> int:
    """γ(t) = |t| · Π γ(children): the order condition of t is b·Φ(t) = 1/γ(t)."""
    return tree_order(tree) * int(np.prod([density(child) for child in tree]))


def elementary_weight(tree: tuple, a: np.ndarray) -> np.ndarray:
    """Φ(t) per stage: 1 for a single vertex, else the product over children of a·Φ(child)."""
    weight = np.ones(a.shape[0])
    for child in tree:
        weight = weight * (a @ elementary_weight(child, a))
    return weight


def extended(pair) -> tuple[np.ndarray, np.ndarray]:
    """The tableau with stage s = f(t + h, y_new) appended: A (s+1, s+1) and b (s+1,)."""
    s = pair.stages
    a = np.zeros((s + 1, s + 1))
    a[:s, :s], a[s, :s] = pair.a, pair.b
    return a, np.append(pair.b, 0.0)


def condition_residual(weights: np.ndarray, tree: tuple, a: np.ndarray, target: float):
    """|weights·Φ(t) − target| and its round-off allowance: every coefficient and every one of
    the at most (s + 1)·|t| products and sums on a path carries a relative error of eps, so the
    float result is within that many eps of the magnitude Σ|w|·Φ(|A|)(t)."""
    value = weights @ elementary_weight(tree, a)
    magnitude = np.abs(weights) @ elementary_weight(tree, np.abs(a))
    return abs(value - target), (a.shape[0] + 1) * tree_order(tree) * EPS * magnitude


def test_rooted_tree_counts():
    """1, 1, 2, 4, 9, 20, 48, 115, 286 trees of orders 1 to 9 (OEIS A000081)."""
    assert [len(rooted_trees(q)) for q in range(1, 10)] == [1, 1, 2, 4, 9, 20, 48, 115, 286]


@pytest.mark.parametrize("pair", [RK23, RK45, DOP853], ids=lambda pair: pair.name)
def test_tableau_satisfies_the_order_conditions_of_its_order_exactly(pair):
    """Row sums of A are the nodes c, b·Φ(t) = 1/γ(t) for every rooted tree up to the order,
    and some tree of the next order violates it (the order is not higher)."""
    a, b = extended(pair)
    row_sums = pair.a.sum(axis=1)
    assert np.all(np.abs(row_sums - pair.c) <= pair.stages * EPS * np.abs(pair.a).sum(axis=1))
    for q in range(1, pair.order + 1):
        for tree in rooted_trees(q):
            residual, allowance = condition_residual(b, tree, a, 1 / density(tree))
            assert residual <= allowance, (q, tree)
    violations = [
        residual > 1e3 * allowance
        for tree in rooted_trees(pair.order + 1)
        for residual, allowance in [condition_residual(b, tree, a, 1 / density(tree))]
    ]
    assert any(violations)


@pytest.mark.parametrize(
    ("pair", "weights", "embedded_order"),
    [(RK23, "e", 2), (RK45, "e", 4), (DOP853, "e", 5), (DOP853, "e3", 3)],
    ids=["RK23", "RK45", "DOP853-e5", "DOP853-e3"],
)
def test_error_weights_compare_with_an_embedded_method_of_lower_order(
    pair, weights, embedded_order
):
    """e = (embedded weights) − b: both solutions satisfy the conditions up to the embedded
    order, so e·Φ(t) = 0 there; at the next order the embedded one fails (the estimate is
    O(h^(embedded_order + 1)))."""
    a, _ = extended(pair)
    e = getattr(pair, weights)
    for q in range(1, embedded_order + 1):
        for tree in rooted_trees(q):
            residual, allowance = condition_residual(e, tree, a, 0.0)
            assert residual <= allowance, (q, tree)
    assert any(
        residual > 1e3 * allowance
        for tree in rooted_trees(embedded_order + 1)
        for residual, allowance in [condition_residual(e, tree, a, 0.0)]
    )


def exp_sin(t, y):
    """y' = y cos t: with y(0) = 1 the solution is exp(sin t)."""
    return y * np.cos(t)


@pytest.mark.parametrize(
    ("pair", "steps"), [(RK23, 64), (RK45, 32), (DOP853, 8)], ids=["RK23", "RK45", "DOP853"]
)
def test_fixed_steps_converge_at_the_pairs_order(pair, steps):
    """Halving the step divides the global error by 2^order. The step counts put the errors
    between 1e-11 and 1e-5: far above round-off and in the asymptotic range, where the next
    error term moves the observed order by less than 0.2."""

    def error(n: int) -> float:
        h, y = 2.0 / n, np.ones(1)
        f, stages = exp_sin(0.0, y), pair.stage_storage(1)
        for i in range(n):
            y, f = rk_step(pair, exp_sin, i * h, y, f, h, stages)
        return abs(y[0] - np.exp(np.sin(2.0)))

    assert np.log2(error(steps) / error(2 * steps)) == pytest.approx(pair.order, abs=0.2)


@pytest.mark.parametrize(
    ("pair", "dense_order", "h"),
    [(RK23, 3, 0.05), (RK45, 4, 0.05), (DOP853, 7, 0.2)],
    ids=["RK23", "RK45", "DOP853"],
)
def test_dense_output_has_its_order_inside_a_step(pair, dense_order, h):
    """From the exact state, the interpolant's error inside a step is O(h^(q+1)) for a dense
    output of order q (cubic Hermite for RK23, Shampine's quartic for RK45, DOP853's 7th
    order); it starts at the old state and ends at the new one."""
    t0 = 0.3

    def worst_error(step: float) -> float:
        y0 = np.exp(np.sin(np.array([t0])))
        stages = pair.stage_storage(1)
        y1, _ = rk_step(pair, exp_sin, t0, y0, exp_sin(t0, y0), step, stages)
        times = t0 + step * np.linspace(0.0, 1.0, 41)
        values = pair.interpolant(exp_sin, t0, y0, y1, step, stages)(times)[0]
        assert values[0] == y0[0]
        assert abs(values[-1] - y1[0]) <= 4 * EPS * abs(y1[0])
        return float(np.abs(values - np.exp(np.sin(times))).max())

    observed = np.log2(worst_error(h) / worst_error(h / 2))
    assert observed == pytest.approx(dense_order + 1, abs=0.2)


def forced_oscillator(t, y):
    """x'' = −4x + 0.3 sin t on (2, B) states."""
    return np.stack([y[1], -4.0 * y[0] + 0.3 * np.sin(t)])


@pytest.mark.parametrize("name", ["RK23", "RK45", "DOP853"])
def test_a_step_and_its_dense_output_are_scipys_bit_for_bit(name):
    """Same tableau, same arithmetic: one step of a given size (accepted at once) and its dense
    output equal those of scipy's public solver class of the same name."""
    y0, h = np.array([1.0, 0.5]), 0.05

    def fun(t, y):
        return forced_oscillator(t, y[:, None])[:, 0]

    solver = getattr(scipy.integrate, name)(fun, 0.0, y0, 1.0, first_step=h, atol=1e-9)
    solver.step()
    assert solver.step_size == h  # accepted without a rejection
    pair = PAIRS[name]
    stages = pair.stage_storage(y0.size)
    y1, _ = rk_step(pair, fun, 0.0, y0, fun(0.0, y0), h, stages)
    assert np.array_equal(y1, solver.y)
    times = np.linspace(0.0, h, 7)
    dense = pair.interpolant(fun, 0.0, y0, y1, h, stages)(times)
    assert np.array_equal(dense, solver.dense_output()(times))


@pytest.mark.parametrize("name", ["RK23", "RK45", "DOP853"])
@pytest.mark.parametrize("rtol", [1e-5, 1e-7])
def test_a_batch_of_one_follows_scipys_solve_ivp(name, rtol):
    """One node runs scipy's algorithm: starting step, step control, dense output and output
    sampling. Only roundings differ -- the per-node norm is sqrt(mean(x²)) where scipy takes
    ‖x‖/√n, and RK45's error weights are rounded as b̂ − b -- so step sizes differ in their
    last bits and the outputs by round-off: each step rounds fewer than 64 operations in a
    chain per state (stages, update, dense output), each by at most one ulp of the solution's
    scale. Any difference in the algorithm would show at the level of rtol, far above."""
    times = np.linspace(0.0, 10.0, 101)
    atol = 1e-12
    ours = solve_stacked(
        forced_oscillator, np.array([[1.0], [0.0]]), times, method=name, rtol=rtol, atol=atol
    )[:, 0]

    def fun(t, y):
        return forced_oscillator(t, y[:, None])[:, 0]

    options = {"method": name, "rtol": rtol, "atol": atol}
    reference = solve_ivp(fun, (0.0, 10.0), [1.0, 0.0], t_eval=times, **options).y
    steps = solve_ivp(fun, (0.0, 10.0), [1.0, 0.0], **options).t.size - 1
    round_off = steps * 64 * EPS * np.abs(reference).max()
    assert round_off < 1e-2 * rtol  # the comparison can tell the algorithms apart
    assert np.abs(ours - reference).max() <= round_off


@pytest.mark.parametrize("pair", [RK23, RK45, DOP853], ids=lambda pair: pair.name)
def test_error_norm_is_the_worst_nodes_own_norm(pair):
    """The stacked acceptance test: the largest of B per-node norms, each the norm a one-node
    batch computes (equal up to the rounding of a d-term sum)."""
    d, n_nodes, h = 3, 5, 0.01
    rng = np.random.default_rng(1)
    stages = rng.standard_normal((pair.stages + 1, d, n_nodes))
    stages[:, :, 2] *= 1e3  # one node far worse than the others
    scale = rng.uniform(0.5, 2.0, (d, n_nodes))
    norm = pair.error_norm(stages.reshape(-1, d * n_nodes), h, scale.ravel(), n_nodes)
    separate = [
        pair.error_norm(np.ascontiguousarray(stages[:, :, b]), h, scale[:, b], 1)
        for b in range(n_nodes)
    ]
    assert norm == pytest.approx(max(separate), rel=d * EPS)


@pytest.mark.parametrize("pair", [RK23, RK45, DOP853], ids=lambda pair: pair.name)
def test_idle_nodes_do_not_dilute_an_active_nodes_error(pair):
    """One active node among B − 1 with zero error: the per-node norm is the active node's
    own, where one norm over the stack as a single system would be sqrt(B) times smaller."""
    d, n_nodes, h = 2, 100, 0.01
    stages = np.zeros((pair.stages + 1, d, n_nodes))
    stages[:, :, 0] = np.random.default_rng(2).standard_normal((pair.stages + 1, d))
    scale = np.ones(d * n_nodes)
    alone = pair.error_norm(np.ascontiguousarray(stages[:, :, 0]), h, np.ones(d), 1)
    flat = stages.reshape(-1, d * n_nodes)
    assert pair.error_norm(flat, h, scale, n_nodes) == pytest.approx(alone, rel=d * EPS)
    as_one_system = pair.error_norm(flat, h, scale, 1)
    assert as_one_system == pytest.approx(alone / np.sqrt(n_nodes), rel=d * n_nodes * EPS)


def test_dop853_node_norms_keep_one_nodes_estimate_from_hiding_anothers():
    """DOP853's norm |h|·‖e5‖²/√((‖e5‖² + 0.01‖e3‖²)·n) over a whole stack lets one node's
    large 3rd-order estimate shrink another node's error by any factor, so no scaling of the
    tolerances bounds every node; per node, each keeps its own norm."""
    d, h = 2, 0.01
    # Stage vectors with (e5·k, e3·k) = (1, 0) and (0, 1).
    basis = np.linalg.lstsq(np.stack([DOP853.e, DOP853.e3]), np.eye(2), rcond=None)[0]
    stages = np.zeros((DOP853.stages + 1, d, 2))
    stages[:, :, 0] = basis[:, [0]]  # node 0: a 5th-order estimate only
    stages[:, :, 1] = 1e4 * basis[:, [1]]  # node 1: a large 3rd-order estimate only
    flat = stages.reshape(-1, 2 * d)
    node0 = DOP853.error_norm(np.ascontiguousarray(stages[:, :, 0]), h, np.ones(d), 1)
    assert DOP853.error_norm(flat, h, np.ones(2 * d), 2) == pytest.approx(node0, rel=d * EPS)
    # As one system, even with the tolerance shrunk by sqrt(B) = sqrt(2), node 0 is hidden.
    assert DOP853.error_norm(flat, h, np.ones(2 * d) / np.sqrt(2), 1) < node0 / 100


# =========================================================================== solve_projected


def rotation(omega: np.ndarray):
    def rhs(t, y):
        x, yy = y
        return np.stack([-omega * yy, omega * x])

    return rhs


def onto_circle(t, y):
    return y / np.hypot(y[0], y[1])


def test_projected_rotation_stays_on_its_circle_and_on_time():
    omega = np.array([1.0, 2.0, 3.0])
    times = np.linspace(0.0, 10.0, 51)
    rtol = 1e-9
    y0 = np.stack([np.ones(3), np.zeros(3)])
    states = solve_projected(rotation(omega), onto_circle, y0, times, rtol=rtol, atol=1e-12)
    assert states.shape == (2, 3, 51)
    radius_error = np.abs(np.hypot(states[0], states[1]) - 1.0).max()
    assert radius_error <= 1e-15 * 4  # round-off of one scaling
    exact = np.stack([np.cos(omega[:, None] * times), np.sin(omega[:, None] * times)])
    assert np.abs(states - exact).max() <= GLOBAL_FACTOR * rtol


@pytest.mark.parametrize("rtol", [1e-6, 1e-8, 1e-10])
def test_projected_error_follows_the_tolerance(rtol):
    """Decay y' = -y on [0, 5]: error within 100·rtol, and the identity projection is harmless."""
    times = np.linspace(0.0, 5.0, 11)
    states = solve_projected(
        lambda t, y: -y, lambda t, y: y, np.ones((1, 2)), times, rtol=rtol, atol=1e-14
    )
    assert np.abs(states[0] - np.exp(-times)).max() <= GLOBAL_FACTOR * rtol


def test_projected_error_control_is_per_node():
    """The maximum over per-node norms: idle companions change nothing for an active node."""
    omega, rtol = 4.0, 1e-7
    times = np.linspace(0.0, 6.0, 31)
    y0 = np.zeros((2, 50))
    y0[0, 0] = 1.0  # node 0 rotates, the others sit at the origin

    def keep(t, y):
        return y

    batch = solve_projected(rotation(np.full(50, omega)), keep, y0, times, rtol=rtol, atol=1e-10)
    alone = solve_projected(
        rotation(np.array([omega])), keep, y0[:, :1], times, rtol=rtol, atol=1e-10
    )
    # Same step sequence; only the rounding of the stage sums differs with the array shape.
    assert np.abs(batch[:, 0] - alone[:, 0]).max() <= 1e-12
    assert np.abs(alone[0, 0] - np.cos(omega * times)).max() <= GLOBAL_FACTOR * rtol


def test_projected_failures_are_model_errors():
    times = np.linspace(0.0, 2.0, 3)
    with pytest.raises(ModelError, match="no result after 5 steps"):
        solve_projected(lambda t, y: -y, lambda t, y: y, np.ones((1, 1)), times, max_steps=5)
    with pytest.raises(ModelError):
        solve_projected(lambda t, y: y**2, lambda t, y: y, np.ones((1, 1)), times)


def test_projected_rejects_a_projection_of_the_wrong_shape():
    with pytest.raises(ValueError, match="project returned shape"):
        solve_projected(lambda t, y: -y, lambda t, y: y[0], np.ones((2, 3)), np.array([0.0, 1.0]))


# =========================================================================== StackedODEModel


class Decay(StackedODEModel):
    """y' = -k y, y(0) = y0: the smallest model on the base class."""

    outputs = ("y",)
    _positive = frozenset({"k"})

    def __init__(self, *, rtol=1e-10, atol=1e-12, **params):
        super().__init__({"k": 1.0, "y0": 1.0}, params, rtol=rtol, atol=atol)

    def _initial_state(self, p):
        return p["y0"][None, :]

    def _rhs(self, t, y, p):
        return -p["k"] * y

    def _observe(self, times, states, p):
        return {"y": states[0]}


def test_model_merges_uncertain_inputs_with_nominal_values():
    model = Decay(y0=2.0)
    assert dict(model.parameters) == {"k": 1.0, "y0": 2.0}
    times = np.linspace(0.0, 3.0, 7)
    k = np.array([0.5, 1.0, 2.0])
    out = model.simulate({"k": k}, times)
    assert set(out) == {"y"} and out["y"].shape == (3, 7)
    exact = 2.0 * np.exp(-k[:, None] * times)
    assert np.abs(out["y"] - exact).max() <= GLOBAL_FACTOR * model.rtol * 2.0
    # No uncertain input: one run at the nominal values.
    assert model.simulate({}, times)["y"].shape == (1, 7)


def test_model_parameters_are_read_only():
    model = Decay()
    with pytest.raises(TypeError):
        model.parameters["k"] = 3.0  # type: ignore[index]


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"kk": 1.0}, "Decay has no parameter 'kk'"),
        ({"k": "1e5"}, "'k' must be a number"),
        ({"k": True}, "'k' must be a number"),
        ({"k": -1.0}, "'k' must be positive"),
        ({"y0": float("nan")}, "'y0' must be finite"),
        ({"rtol": 0.5e-20}, "rtol must be"),
        ({"atol": 0.0}, "atol must be"),
    ],
)
def test_model_constructor_rejects_bad_parameters(params, message):
    with pytest.raises(ValueError, match=message):
        Decay(**params)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"c": np.ones(2)}, "no parameter 'c'"),
        ({"k": np.ones(2), "y0": np.ones(3)}, "one length B"),
        ({"k": np.ones((2, 2))}, "1-D arrays"),
        ({"k": np.array([1.0, -1.0])}, r"'k' must be positive, got -1\.0 at node 1"),
        ({"k": np.array([])}, "empty batch"),
    ],
)
def test_model_simulate_rejects_bad_batches(params, message):
    with pytest.raises(ValueError, match=message):
        Decay().simulate(params, np.linspace(0.0, 1.0, 3))


def test_model_times_start_at_the_initial_state():
    model = Decay()
    with pytest.raises(ValueError, match="initial time"):
        model.simulate({"k": np.ones(1)}, np.array([-0.5, 1.0]))
    with pytest.raises(ConfigError, match="time"):
        model.check_times(np.array([-0.5, 1.0]))
    model.check_times(np.linspace(0.0, 1.0, 5))  # a valid grid passes silently
