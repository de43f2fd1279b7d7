"""The MuJoCo scenes of models/mujoco/ and their configs, cross-checked against references.

- pendulum: the exact elliptic-function solution and the native PendulumODE;
- quarter car: the native QuarterCar (linear spring, and the paper's cubic one by binding);
- contact: the closed-form slide of a box on an incline, and what its kink does to the chaos.

Statistics are chaos means and stds on the same tensor Gauss grid for MuJoCo and for the
reference, so their difference is MuJoCo's error alone: with weights summing to one, the
mean moves by at most the largest node difference and so does the std (it is 1-Lipschitz in
the weighted L2 norm). The node tolerances below therefore bound the statistics too.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from pcmb.adapters.mujoco.model import MujocoModel
from pcmb.adapters.python import load_entry
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.cli import main
from pcmb.config.schema import load_config
from pcmb.references import pendulum_angle

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
MODELS = ROOT / "models"


def config_model(name: str):
    config = load_config(CONFIGS / name)
    return config, config.model_factory()()


def statistics(grid: TensorGrid, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chaos mean and std, (T,) each, of (N, T) values on ``grid``."""
    expansion = ChaosExpansion(project_tensor(grid, values), grid.multi_index, grid.distributions)
    return expansion.mean(), expansion.std()


# --------------------------------------------------------------------------- pendulum


def test_mujoco_pendulum_matches_the_exact_solution_and_the_native_model():
    config, model = config_model("mujoco_pendulum.yaml")
    times = config.times  # 0-15 s
    grid = TensorGrid([Uniform(0.8, 1.2)], orders=[7])  # the config's inputs and order
    lengths = grid.params[:, 0]
    mujoco_theta = model.simulate({"L": lengths}, times)["theta"]
    exact = pendulum_angle(times, lengths)  # θ0 = π/4, the config's
    native_model = load_entry("pendulum.py:PendulumODE", MODELS)(rtol=1e-12, atol=1e-14)
    native = native_model.simulate({"L": lengths}, times)["theta"]

    # RK4 at h = 1 ms: global error ~ (ω h)^4 ω t / 120 = 7e-11 rad for ω = sqrt(9.81/0.8)
    # and t = 15 s (the point mass's 1e-12 inertia adds ~1e-11); PendulumODE at rtol 1e-12
    # is within 1e-8 rad of the exact solution (its own tests). 2e-10 and 1e-8 rad:
    mujoco_tol, native_tol = 2e-10, 1e-8
    np.testing.assert_allclose(mujoco_theta, exact, rtol=0, atol=mujoco_tol)
    np.testing.assert_allclose(native, exact, rtol=0, atol=native_tol)
    for ours, theirs, tol in [
        (mujoco_theta, exact, mujoco_tol),
        (mujoco_theta, native, mujoco_tol + native_tol),
    ]:
        for a, b in zip(statistics(grid, ours), statistics(grid, theirs), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=tol)


def test_the_pendulum_statistics_are_limited_by_the_order_not_by_mujoco():
    # What the config's comment claims: at order 7 the chaos truncation error grows with time
    # as the nodes' periods drift apart, and by 15 s it dwarfs MuJoCo's 2e-10 rad. The
    # converged statistics come from 80 Gauss nodes of the exact solution.
    times = np.linspace(0.0, 15.0, 1501)
    fine = TensorGrid([Uniform(0.8, 1.2)], orders=[79])
    true_mean, _ = statistics(fine, pendulum_angle(times, fine.params[:, 0]))
    grid = TensorGrid([Uniform(0.8, 1.2)], orders=[7])
    mean, _ = statistics(grid, pendulum_angle(times, grid.params[:, 0]))
    error = np.abs(mean - true_mean)
    assert error[times <= 3.0].max() < 1e-9
    assert error[-1] > 1e-4


# --------------------------------------------------------------------------- quarter car


def relative_error(ours: np.ndarray, theirs: np.ndarray) -> float:
    return float(np.abs(ours - theirs).max() / np.abs(theirs).max())


# RK4 at h = 1 ms: the slow modes (the body at ~9 rad/s, the 1 Hz terrain) are exact to
# ~(ω h)^4 ω t / 120 ~ 1e-10; the wheel hop mode (~70 rad/s, (ω h)^4 ω / 120 ~ 1.4e-5 per
# second of persistent motion) is excited by the start and damped within ~0.07 s (damping
# ratio ~0.2), so its error stays ~1e-6 of its amplitude. The shaker moves the road by
# ~1e-9 relative. Hence 2e-6 of each output's largest magnitude; the native model at
# rtol 1e-11 is far tighter.
QUARTER_CAR_TOL = 2e-6


def test_mujoco_quarter_car_matches_the_native_linear_quarter_car():
    config, model = config_model("mujoco_quarter_car.yaml")
    inputs = [Uniform(0.025, 0.075), Uniform(1.2e5, 1.8e5), Uniform(800.0, 1200.0)]
    grid = TensorGrid(inputs, orders=[2, 2, 2])  # the config's inputs, 27 nodes
    params = dict(zip(config.inputs, grid.params.T, strict=True))
    ours = model.simulate(params, config.times)
    native = load_entry("quarter_car.py:QuarterCar", MODELS)(
        spring="linear", rtol=1e-11, atol=1e-13
    ).simulate(params, config.times)
    for name in model.outputs:
        assert relative_error(ours[name], native[name]) < QUARTER_CAR_TOL, name
        scale = np.abs(native[name]).max()
        for a, b in zip(statistics(grid, ours[name]), statistics(grid, native[name]), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=QUARTER_CAR_TOL * scale)


def test_mujoco_quarter_car_takes_the_papers_cubic_spring_by_binding():
    config = load_config(CONFIGS / "mujoco_quarter_car.yaml").model
    suspension = {"name": "suspension"}
    model = MujocoModel(
        xml=CONFIGS / config.xml,
        params={"A": 0.05, "k": 0.0, "k3": 6.0e6},  # MuJoCo >= 4: stiffness "0 0 6e6"
        bind={
            "A": [{"qvel0": "road"}],
            "k": [{"field": "tendon_stiffness", **suspension}],
            "k3": [{"field": "tendon_stiffnesspoly", **suspension, "index": 1}],
        },
        outputs={"x1": {"qpos": "chassis"}, "x2": {"qpos": "wheel"}},
    )
    times = np.linspace(0.0, 3.0, 301)
    amplitude = np.array([0.025, 0.05, 0.075])
    ours = model.simulate({"A": amplitude}, times)
    native = load_entry("quarter_car.py:QuarterCar", MODELS)(
        spring="cubic", rtol=1e-11, atol=1e-13
    ).simulate({"A": amplitude}, times)
    for name in ("x1", "x2"):
        assert relative_error(ours[name], native[name]) < QUARTER_CAR_TOL, name


# --------------------------------------------------------------------------- contact

INCLINE = np.pi / 6
STICK = np.tan(INCLINE)  # mu* = 0.577: slides below, sticks above
LOW, HIGH = 0.3, 0.8  # the config's mu ~ U[0.3, 0.8]
H = 0.001  # the scene's timestep


def slide(mu: np.ndarray, times: np.ndarray) -> np.ndarray:
    """x(t) of the box, (N, T): semi-implicit Euler's exact x_n = a t (t + h) / 2, a >= 0."""
    acc = np.where(mu < STICK, 9.81 * (np.sin(INCLINE) - mu * np.cos(INCLINE)), 0.0)
    return 0.5 * acc[:, None] * times * (times + H)


def exact_slide_statistics(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of x(t) over mu ~ U[LOW, HIGH]: x = K (mu* - mu) below mu*, else 0."""
    k = 0.5 * 9.81 * np.cos(INCLINE) * times * (times + H)
    width = HIGH - LOW
    mean = k * (STICK - LOW) ** 2 / (2 * width)
    second = k**2 * (STICK - LOW) ** 3 / (3 * width)
    return mean, np.sqrt(second - mean**2)


# MuJoCo's contact is not Coulomb's law: its convex model lets a sliding box drift off the
# surface by ~mu |v| h per step, so the box hops up to ~5 mm above the incline and slides
# without friction for a while (1.4e-3 m in 2 s at worst here, 3e-4 of the 4.7 m slide),
# and a stuck box creeps ~6e-5 m. 3e-3 m covers both; it is what MuJoCo allows, not a
# figure of the method.
CONTACT_TOL = 3e-3


def test_contact_scene_slides_and_sticks_and_its_kink_slows_the_chaos():
    config, model = config_model("mujoco_contact.yaml")
    times = config.times  # 0-2 s
    true_mean, true_std = exact_slide_statistics(times)
    errors = {}
    for order in (3, 7, 15):
        grid = TensorGrid([Uniform(LOW, HIGH)], orders=[order])
        mu = grid.params[:, 0]
        x = model.simulate({"mu": mu}, times)["x"]
        reference = slide(mu, times)
        np.testing.assert_allclose(x, reference, rtol=0, atol=CONTACT_TOL)
        mean, std = statistics(grid, x)
        for a, b in zip((mean, std), statistics(grid, reference), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=CONTACT_TOL)
        errors[order] = abs(mean[-1] - true_mean[-1]) / true_mean[-1]
        assert abs(std[-1] - true_std[-1]) / true_std[-1] > 1e-4  # not spectral either
    # Gauss quadrature of the kinked x(mu) at t = 2 s (the config's figures): 2.5 % at
    # order 3, 0.04 % at 7 and 0.3 % at 15; MuJoCo's contact moves them by <= 2.3e-3
    # relative (CONTACT_TOL / mean). Doubling the order from 7 to 15 makes it worse.
    assert 2e-2 < errors[3] < 3e-2
    assert errors[7] < 3e-3
    assert 2e-3 < errors[15] < 6e-3
    assert errors[15] > errors[7]


def test_pcmb_run_on_the_contact_config_stores_the_same_statistics(tmp_path):
    out = tmp_path / "contact.h5"
    assert main(["run", str(CONFIGS / "mujoco_contact.yaml"), "-o", str(out), "--jobs", "1"]) == 0
    config, model = config_model("mujoco_contact.yaml")
    grid = TensorGrid([Uniform(LOW, HIGH)], orders=[7])
    mean, std = statistics(grid, model.simulate({"mu": grid.params[:, 0]}, config.times)["x"])
    with h5py.File(out, "r") as stored:
        # the same deterministic runs and the same projection: round-off only
        np.testing.assert_allclose(stored["outputs/x/mean"][()], mean, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(stored["outputs/x/std"][()], std, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(
    "name", ["mujoco_pendulum.yaml", "mujoco_quarter_car.yaml", "mujoco_contact.yaml"]
)
def test_the_mujoco_configs_validate(name):
    config, model = config_model(name)
    assert set(config.inputs) <= set(model.parameters)
    assert set(config.output_names or model.outputs) == set(model.outputs)
