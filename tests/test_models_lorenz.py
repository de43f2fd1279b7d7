"""Tests of models/lorenz.py: equilibria, the stable case, chaotic accuracy."""

from __future__ import annotations

import numpy as np
import pytest
from model_loading import GLOBAL_FACTOR, gauss_legendre_grid, model_class, reference_run

from pcmb.references import lorenz_equilibria

Lorenz = model_class("lorenz", "Lorenz")

STABLE = {"sigma": 1.0, "rho": 10.0, "beta": 1.0}
CHAOTIC = {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0}
LYAPUNOV = 0.906  # largest Lyapunov exponent of the classic chaotic case


def lorenz_rhs(sigma, rho, beta):
    def rhs(t, y):
        x, yy, z = y
        return [sigma * (yy - x), x * (rho - z) - yy, x * yy - beta * z]

    return rhs


@pytest.mark.parametrize("case", [STABLE, CHAOTIC], ids=["stable", "chaotic"])
def test_equilibria_are_fixed_points(case):
    points = lorenz_equilibria(case["rho"], case["beta"])
    model = Lorenz(**case)
    out = model.simulate(
        {"x0": points[:, 0], "y0": points[:, 1], "z0": points[:, 2]}, np.linspace(0.0, 2.0, 21)
    )
    for k, name in enumerate("xyz"):
        # At rest the solver lengthens its steps until its error estimate reaches the
        # tolerance, so an unstable equilibrium is held to the integration tolerance.
        bound = GLOBAL_FACTOR * model.rtol * (case["rho"] - 1)
        assert np.abs(out[name] - points[:, k, None]).max() <= bound


def cube_nodes():
    """3×3×3 Gauss–Legendre nodes of the paper's cube [0, 1]² × [14.5, 15.5]."""
    grid = gauss_legendre_grid((0.0, 1.0), (0.0, 1.0), (14.5, 15.5), points=3)
    return {"x0": grid[:, 0], "y0": grid[:, 1], "z0": grid[:, 2]}


def test_stable_case_converges_to_3_3_9_at_the_linearized_rate():
    """The Jacobian at (3, 3, 9) has eigenvalues −2 and −0.5 ± 2.96i: distances shrink as
    e^{−0.5 t}; over 5 time units the windowed peak distance drops by e^{−2.5}."""
    times = np.linspace(0.0, 15.0, 1501)
    out = Lorenz(**STABLE).simulate(cube_nodes(), times)
    distance = np.sqrt((out["x"] - 3) ** 2 + (out["y"] - 3) ** 2 + (out["z"] - 9) ** 2)
    late = distance[:, times >= 12.5].max(axis=1)  # windows longer than one 2.1-unit period
    early = distance[:, (times >= 7.5) & (times <= 10.0)].max(axis=1)
    # e^{−0.5·12.5} ≈ 2e-3 of an initial offset of about 6, with room for the transient
    # growth of the non-normal linearization.
    assert late.max() <= 0.1
    ratio = late / early
    # The peak ratio is e^{−2.5} up to the phase of the oscillation inside the windows.
    assert np.all((ratio > np.exp(-2.5) / 1.5) & (ratio < np.exp(-2.5) * 1.5))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("case", "horizon"), [(STABLE, 15.0), (CHAOTIC, 5.0)], ids=["stable", "chaotic"]
)
def test_batch_matches_tight_separate_runs(case, horizon):
    """Stable: errors do not grow. Chaotic: an error made at time s grows like e^{λ (t − s)}
    on average; beyond t ≈ 5 the finite-time stretching of single trajectories outruns that
    average, so single trajectories are compared up to t = 5 only (the model's docstring)."""
    times = np.linspace(0.0, horizon, 101)
    nodes = cube_nodes()
    model = Lorenz(**case)
    out = model.simulate(nodes, times)
    # Node 0 alone (B = 1) keeps the promise too.
    alone = model.simulate({name: values[:1] for name, values in nodes.items()}, times)
    out = {name: np.vstack([out[name], alone[name]]) for name in "xyz"}
    nodes = {name: np.append(values, values[0]) for name, values in nodes.items()}
    growth = np.exp(LYAPUNOV * times) if case is CHAOTIC else np.ones_like(times)
    for b in range(len(nodes["x0"])):
        y0 = [nodes["x0"][b], nodes["y0"][b], nodes["z0"][b]]
        reference = reference_run(lorenz_rhs(**case), y0, times, atol=1e-12)
        for k, name in enumerate("xyz"):
            scale = np.abs(reference[k]).max()
            error = np.abs(out[name][b] - reference[k])
            assert np.all(error <= GLOBAL_FACTOR * model.rtol * scale * growth), (b, name)
