"""Tests of models/pendulum.py against the exact elliptic-function solution.

θ(t) = 2 asin(k sn(K(k) − √(g/L) t, k)), k = sin(θ0/2), for a release from rest at θ0
(:func:`pcmb.references.pendulum_angle`).
"""

from __future__ import annotations

import numpy as np
import pytest
from model_loading import GLOBAL_FACTOR, model_class, reference_run

from pcmb.references import pendulum_angle

PendulumODE = model_class("pendulum", "PendulumODE")
PendulumDAE = model_class("pendulum", "PendulumDAE")

LENGTHS = np.array([0.8, 0.9, 1.0, 1.1, 1.2])  # the paper's L = 1 + 0.2 ξ range
TIMES = np.linspace(0.0, 15.0, 301)


def test_ode_matches_the_exact_solution_at_the_tightest_tolerance():
    model = PendulumODE(rtol=1e-12, atol=1e-14)
    out = model.simulate({"L": LENGTHS}, TIMES)
    exact = pendulum_angle(TIMES, LENGTHS)
    assert np.abs(out["theta"] - exact).max() <= 1e-8  # the bound
    assert np.allclose(out["x"], LENGTHS[:, None] * np.sin(out["theta"]), rtol=0, atol=1e-15)
    assert np.allclose(out["y"], LENGTHS[:, None] * np.cos(out["theta"]), rtol=0, atol=1e-15)


def test_ode_batch_matches_tight_separate_runs_at_the_default_tolerance():
    model = PendulumODE()
    out = model.simulate({"L": LENGTHS}, TIMES)
    alone = model.simulate({"L": LENGTHS[:1]}, TIMES)  # B = 1 keeps the promise too
    out = {name: np.vstack([out[name], alone[name]]) for name in ("theta", "omega")}
    for b, length in enumerate([*LENGTHS, LENGTHS[0]]):
        reference = reference_run(
            lambda t, y, length=length: [y[1], -(9.81 / length) * np.sin(y[0])],
            [np.pi / 4, 0.0],
            TIMES,
            atol=1e-14,
        )
        # The documented promise: 100·rtol = 1e-8 rad (θ and ω are of order 1).
        assert np.abs(out["theta"][b] - reference[0]).max() <= GLOBAL_FACTOR * model.rtol
        assert np.abs(out["omega"][b] - reference[1]).max() <= GLOBAL_FACTOR * model.rtol * 3


def test_dae_stays_on_the_constraint_and_matches_the_exact_solution():
    model = PendulumDAE()
    out = model.simulate({"L": LENGTHS}, TIMES)
    assert np.abs(out["constraint"]).max() <= 1e-10  # the bound (round-off here)
    theta = pendulum_angle(TIMES, LENGTHS)
    # The step control keeps each node's local error within rtol; 100·rtol·L overall.
    bound = GLOBAL_FACTOR * model.rtol * LENGTHS.max()
    assert np.abs(out["x"] - LENGTHS[:, None] * np.sin(theta)).max() <= bound
    assert np.abs(out["y"] - LENGTHS[:, None] * np.cos(theta)).max() <= bound
    assert np.abs(out["theta"] - theta).max() <= bound / LENGTHS.min()


@pytest.mark.parametrize("rtol", [1e-7, 1e-9])
def test_dae_error_follows_its_tolerance(rtol):
    model = PendulumDAE(rtol=rtol, atol=rtol * 1e-2)
    out = model.simulate({"L": LENGTHS[[0, -1]]}, TIMES)
    exact = LENGTHS[[0, -1], None] * np.sin(pendulum_angle(TIMES, LENGTHS[[0, -1]]))
    assert np.abs(out["x"] - exact).max() <= GLOBAL_FACTOR * rtol * LENGTHS.max()


def test_rotating_pendulum_unwraps_its_angle_in_both_forms():
    """Launched at 8 rad/s > 2√(g/L) it goes over the top: θ grows past 2π without jumps."""
    times = np.linspace(0.0, 3.0, 601)
    params = {"omega0": np.array([8.0]), "L": np.array([1.0])}
    ode = PendulumODE().simulate(params, times)
    dae = PendulumDAE().simulate(params, times)
    assert ode["theta"][0, -1] > 2 * np.pi
    assert np.abs(dae["theta"] - ode["theta"]).max() <= 1e-6
    assert np.abs(dae["x"] - ode["x"]).max() <= 1e-6


@pytest.mark.parametrize("cls", [PendulumODE, PendulumDAE])
def test_pendulum_rejects_bad_parameters(cls):
    with pytest.raises(ValueError, match="'L' must be positive"):
        cls(L=0.0)
    with pytest.raises(ValueError, match="no parameter 'mass'"):
        cls(mass=1.0)
    with pytest.raises(ValueError, match=r"'L' must be positive, got -0\.5 at node 1"):
        cls().simulate({"L": np.array([1.0, -0.5])}, TIMES)
