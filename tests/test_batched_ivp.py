"""Tests of pcmb.adapters.stacked_ode: stacked and projected batch integration, and the model base.

Accuracy bounds: an integrator that keeps every step's local error within rtol (relative to
the state) gives a global error of a modest multiple of rtol on these stable, non-chaotic
problems over a few dozen oscillations or time constants. The tests allow 100·rtol (times
the solution's scale) for that accumulation, against closed-form solutions.
"""

from __future__ import annotations

import numpy as np
import pytest
from model_loading import GLOBAL_FACTOR
from scipy.integrate import DOP853, RK23, RK45, solve_ivp

from pcmb.adapters.stacked_ode import StackedODEModel, solve_projected, solve_stacked
from pcmb.errors import ConfigError, ModelError


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


@pytest.mark.parametrize("method", ["RK23", "RK45", "DOP853"])
def test_stacked_error_norm_is_the_worst_separate_runs_norm(method):
    """The stacked solvers' step test, checked against scipy's own solver on each node."""
    from pcmb.adapters.stacked_ode import _PER_NODE_SOLVERS

    d, n_nodes, h = 3, 5, 0.01
    rng = np.random.default_rng(1)
    plain_class = {"RK23": RK23, "RK45": RK45, "DOP853": DOP853}[method]
    stacked = _PER_NODE_SOLVERS[method](
        lambda t, y: -y, 0.0, np.ones(d * n_nodes), 1.0, n_nodes=n_nodes
    )
    alone = plain_class(lambda t, y: -y, 0.0, np.ones(d), 1.0)
    stages = rng.standard_normal((stacked.K.shape[0], d, n_nodes))
    stages[:, :, 2] *= 1e3  # one node far worse than the others
    scale = rng.uniform(0.5, 2.0, (d, n_nodes))
    norm = stacked._estimate_error_norm(stages.reshape(-1, d * n_nodes), h, scale.ravel())
    separate = [alone._estimate_error_norm(stages[:, :, b], h, scale[:, b]) for b in range(5)]
    assert norm == pytest.approx(max(separate), rel=1e-12)


def test_dop853_stacked_norm_can_hide_a_node_whatever_the_scaling():
    """Why DOP853 needs its norm per node: its estimate |h|·‖e5‖²/√((‖e5‖² + 0.01‖e3‖²)·n)
    over a stack lets one node's large 3rd-order estimate shrink another node's error, so
    no tolerance scaling of the plain stacked solver bounds every node."""
    d, h = 2, 0.01
    plain_stacked = DOP853(lambda t, y: -y, 0.0, np.ones(2 * d), 1.0)
    alone = DOP853(lambda t, y: -y, 0.0, np.ones(d), 1.0)
    stages = np.zeros((plain_stacked.K.shape[0], d, 2))
    # Node 0: stages with a 5th-order error estimate only; node 1: a pure 3rd-order one.
    stages[:, :, 0] = np.linalg.lstsq(
        np.stack([DOP853.E5, DOP853.E3]), np.array([[1.0, 1.0], [0.0, 0.0]]), rcond=None
    )[0]
    stages[:, :, 1] = (
        1e4
        * np.linalg.lstsq(
            np.stack([DOP853.E5, DOP853.E3]), np.array([[0.0, 0.0], [1.0, 1.0]]), rcond=None
        )[0]
    )
    scale = np.ones((d, 2))
    node0 = alone._estimate_error_norm(stages[:, :, 0], h, scale[:, 0])
    # Even with the tolerance shrunk by sqrt(B) = sqrt(2), the stack reports far less.
    stacked = plain_stacked._estimate_error_norm(
        stages.reshape(-1, 2 * d), h, scale.ravel() / np.sqrt(2)
    )
    assert stacked < node0 / 100


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


# =========================================================================== solve_projected


def test_dormand_prince_tableau_is_scipys():
    """An independent copy of the same pair: scipy's RK45 (error weights there are B4 - B5)."""
    from pcmb.adapters import stacked_ode as batched_ivp

    assert np.allclose(batched_ivp._DP_C[:6], RK45.C, rtol=0, atol=1e-15)
    assert np.allclose(batched_ivp._DP_A[:6, :5], RK45.A, rtol=0, atol=1e-15)
    assert np.allclose(batched_ivp._DP_B5[:6], RK45.B, rtol=0, atol=1e-15)
    assert np.allclose(batched_ivp._DP_E, -RK45.E, rtol=0, atol=1e-15)
    # Classical order conditions of the 5th-order weights through order 4, and the bushy
    # tree of order 5: sums of b·c^(q-1) equal 1/q.
    b, c = batched_ivp._DP_B5, batched_ivp._DP_C
    assert [float(b @ c**q) for q in range(5)] == pytest.approx([1, 1 / 2, 1 / 3, 1 / 4, 1 / 5])


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
