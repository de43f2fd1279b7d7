"""Tests of models/quarter_car.py: physics against closed forms, batching against separate runs.

The per-node references re-state the equations of Part II (Eq. 1–5, 10, 11) here, apart from the
model's code, and integrate one node at a time with plain ``solve_ivp`` (DOP853, rtol 1e-11).
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from model_loading import CONFIGS_DIR, gauss_legendre_grid, model_class, reference_run
from scipy.integrate import simpson
from scipy.stats import ks_2samp

import pcmb
from pcmb.references import quarter_car_linear

QuarterCar = model_class("quarter_car", "QuarterCar")

# The model's documented promise (its docstring): with the default tolerances every node is
# within 1e-6 of the output's largest magnitude of a tight separate run.
PROMISE = 1e-6


def suspension_force(p, damper, d, dv, spring="cubic"):
    """Force of the suspension on the wheel (minus that on the body), Part II Eq. 1–5 and 10."""
    spring_force = p["k"] * d**3 if spring == "cubic" else p["k"] * d
    if damper == "linear":
        return spring_force + p["c"] * dv
    viscous = (p["c0"] + p["c1"] * p["I"]) * dv
    return spring_force + viscous + (p["F0"] + p["F1"] * p["I"]) * np.tanh(p["mr_slope"] * dv)


def reference_car(p, terrain, damper):
    """Right-hand side of one node (state x1, x2, v1, v2), cubic spring."""

    def rhs(t, y):
        x1, x2, v1, v2 = y
        force = suspension_force(p, damper, x1 - x2, v1 - v2)
        return [v1, v2, -force / p["Ms"], (force + p["kT"] * (terrain(t) - x2)) / p["Mu"]]

    return rhs


def per_node_references(nodes, nominal, make_terrain, damper, times, edges=lambda p: ()):
    """(B, 5, T) tight separate runs of x1, x2, v1, v2 and a1, restarted at each node's
    terrain discontinuities."""
    runs = []
    for node in nodes:
        p = {**nominal, **node}
        terrain = make_terrain(p)
        rhs = reference_car(p, terrain, damper)
        y = np.array([terrain(0.0), terrain(0.0), 0.0, 0.0])
        cuts = [0.0, *edges(p), times[-1]]
        pieces = []
        for start, stop in itertools.pairwise(cuts):
            inside = times[(times > start) & (times <= stop)] if start > 0 else times[times <= stop]
            grid = np.append(inside[inside < stop], stop)
            states = reference_run(rhs, y, grid, t0=start, atol=1e-13)
            pieces.append(states[:, : inside.size])
            y = states[:, -1]
        x1, x2, v1, v2 = np.concatenate(pieces, axis=1)
        a1 = -suspension_force(p, damper, x1 - x2, v1 - v2) / p["Ms"]
        runs.append([x1, x2, v1, v2, a1])
    return np.array(runs)


def assert_within_promise(out, references, damping_slope=0.0):
    """States within the promise; a1 too, plus its sensitivity to the relative velocity.

    a1 is computed from the states, so it inherits their error, amplified by the damper's
    slope dFd/dδ' / Ms (``damping_slope``; for the MR damper at most
    (c0 + c1 I + mr_slope·(F0 + F1 I))/Ms).
    """
    for k, name in enumerate(("x1", "x2", "v1", "v2")):
        scale = np.abs(references[:, k]).max()
        assert np.abs(out[name] - references[:, k]).max() <= PROMISE * scale, name
    velocity_scale = np.abs(references[:, 2:4]).max()
    bound = PROMISE * (np.abs(references[:, 4]).max() + damping_slope * 2 * velocity_scale)
    assert np.abs(out["a1"] - references[:, 4]).max() <= bound


@pytest.mark.slow
def test_sine_batch_matches_tight_separate_runs():
    """The default case: A, kT, c on a 3×3×3 Gauss grid over the config's ranges, 0–3 s."""
    grid = gauss_legendre_grid((0.025, 0.075), (1.2e5, 1.8e5), (800.0, 1200.0), points=3)
    model = QuarterCar()
    times = np.linspace(0.0, 3.0, 301)
    out = model.simulate({"A": grid[:, 0], "kT": grid[:, 1], "c": grid[:, 2]}, times)
    assert {name: value.shape for name, value in out.items()} == dict.fromkeys(
        QuarterCar.outputs, (27, 301)
    )
    nodes = [{"A": a, "kT": kt, "c": c} for a, kt, c in grid]

    def sine(p):
        return lambda t: p["A"] * np.sin(2 * np.pi * p["f"] * t)

    references = per_node_references(nodes, model.parameters, sine, "linear", times)
    assert_within_promise(out, references)
    # Alone (B = 1, as the executor re-runs a failed node) each node keeps the promise too.
    for b in range(0, 27, 3):
        alone = model.simulate(
            {"A": grid[b : b + 1, 0], "kT": grid[b : b + 1, 1], "c": grid[b : b + 1, 2]}, times
        )
        assert_within_promise(alone, references[b : b + 1])


def bump_of(p):
    start, stop = p["bump_start"], p["bump_start"] + p["bump_duration"]
    return lambda t: p["bump_height"] * float(start <= t < stop)


@pytest.mark.slow
def test_mr_damper_over_a_bump_matches_tight_separate_runs():
    """The MR case of configs/mr_damper.yaml (I on 4 Gauss–Legendre points of [0, 2] A, 0–6
    s), with the bump start uncertain too. The damper's steep tanh makes it the hardest case
    for step control, and a stacked DOP853 without its per-node norm misses the promise here.
    """
    current = 1.0 + np.polynomial.legendre.leggauss(4)[0]
    start = np.array([0.5, 0.6, 0.7, 0.8])
    model = QuarterCar(terrain="bump", damper="mr")
    times = np.linspace(0.0, 6.0, 601)
    out = model.simulate({"I": current, "bump_start": start}, times)
    nodes = [{"I": i, "bump_start": s} for i, s in zip(current, start, strict=True)]
    references = per_node_references(
        nodes,
        model.parameters,
        bump_of,
        "mr",
        times,
        edges=lambda p: (p["bump_start"], p["bump_start"] + p["bump_duration"]),
    )
    p = model.parameters
    strongest = current.max()
    slope = p["c0"] + p["c1"] * strongest + p["mr_slope"] * (p["F0"] + p["F1"] * strongest)
    slope /= p["Ms"]
    assert_within_promise(out, references, damping_slope=slope)
    # The terrain output is the bump itself, 25 cm high, starting at each node's own time.
    assert out["z"].max() == pytest.approx(0.25)
    first = np.argmax(out["z"] > 0, axis=1)
    assert np.allclose(times[first], start)


@pytest.mark.slow
def test_kl_terrain_batch_matches_tight_separate_runs_and_the_profile():
    germs = np.array(
        [[0.0, 0.0, 0.0, 0.0], [1.0, -0.5, 0.3, 2.0], [-2.3, 1.2, -1.0, 0.0], [0.7, 0.7, 0.7, 0.7]]
    )
    names = ("xi11", "xi12", "xi21", "xi22")
    model = QuarterCar(terrain="kl")
    times = np.linspace(0.0, 10.0, 501)
    out = model.simulate({n: germs[:, i] for i, n in enumerate(names)}, times)

    def profile(p):
        # Part II Eq. 11 written out: D = 100 m, L1 = D/(6π), L2 = D/(14π), s = 10 m/s · t.
        def z(t):
            s = 10.0 * t
            l1, l2 = 100.0 / (6 * np.pi), 100.0 / (14 * np.pi)
            return (
                0.5 * np.sin(2 * np.pi * s / 100.0)
                + 0.2 * (p["xi11"] * np.cos(s / l1) + p["xi12"] * np.sin(s / l1))
                + 0.1 * (p["xi21"] * np.cos(s / l2) + p["xi22"] * np.sin(s / l2))
            )

        return z

    nodes = [dict(zip(names, row, strict=True)) for row in germs]
    expected_z = np.array([profile(node)(times) for node in nodes])
    assert np.abs(out["z"] - expected_z).max() <= 1e-14
    # The car starts at rest on the terrain under it.
    assert np.allclose(out["x1"][:, 0], expected_z[:, 0]) and np.allclose(
        out["x2"][:, 0], out["z"][:, 0]
    )
    references = per_node_references(nodes, model.parameters, profile, "linear", times)
    assert_within_promise(out, references)


def test_mr_damper_law_is_part_ii_eq_10_as_reconstructed():
    """Part II Eq. 10 read from its garbled text (docs/paper_cases.md §3), at Fig. 9a's corners.

    At t = 0 with both springs unstretched the only force on the body is the damper's, so
    Fd = -Ms·a1(0) for the initial relative velocity v1_0.
    """
    model = QuarterCar(terrain="bump", damper="mr", bump_start=1.0)
    current = np.array([0.0, 1.0, 2.0, 2.0, 1.0])
    velocity = np.array([1.5, 1.5, 1.5, -1.5, 0.0])
    out = model.simulate({"I": current, "v1_0": velocity}, np.array([0.0, 0.01]))
    force = -model.parameters["Ms"] * out["a1"][:, 0]
    # Fd = (701.95·I + 531)·v + (4 + 1015·I)·tanh(14.3·v), written out.
    eq10 = (701.95 * current + 531.0) * velocity + (4.0 + 1015.0 * current) * np.tanh(
        14.3 * velocity
    )
    assert force == pytest.approx(eq10, rel=1e-9, abs=1e-9)
    assert force[:3] == pytest.approx([800.5, 2868.4, 4936.4], abs=0.1)
    # Fig. 9a: odd in v, growing with I, inside its ±6000 N axes whose 2000 N ticks the
    # strongest curve passes (MATLAB's automatic limits: the next tick above the data).
    assert force[3] == -force[2] and force[4] == 0.0
    assert 4000.0 < force[2] < 6000.0


def test_eq_10_reconstruction_gives_the_surviving_characters():
    """Part II's text extraction emits each font of an equation as a group, its runs in
    reverse order, a decimal number as the runs integer, point, fraction (so 14.3 → "3.14";
    Eq. 27's 14.5 ≤ z0 ≤ 15.5 → "5.155.14"). Eq. 10 as reconstructed, run by run, in the
    model's coefficients, gives Part II's characters exactly."""
    p = QuarterCar(damper="mr").parameters

    def runs(number):
        whole, _, fraction = f"{number:g}".partition(".")
        return [whole, ".", fraction] if fraction else [whole]

    # F = (c1·I + c0) v + (F0 + F1·I) tanh(mr_slope·v), one list per font.
    roman = [*runs(p["c1"]), *runs(p["c0"]), *runs(p["F0"]), *runs(p["F1"]), "tanh"]
    roman += runs(p["mr_slope"])
    italic, symbols = ["F", "I", "v", "I", "v"], ["=", "⋅", "+", "+", "+", "⋅"]
    text = "( ) ( ) ( )" + "".join(
        "".join(reversed(group)) for group in (italic, [" "], roman, [" "], symbols)
    )
    assert text == "( ) ( ) ( )vIvIF 3.14tanh1015453195.701 ⋅+++⋅="


@pytest.fixture(scope="module")
def mr_damper_remedy():
    """The MR damper to t = 6 s (61 times) and its remedy's result, ``elements: auto`` at
    order 3 to 1 % of the largest std: the study of both Fig. 11 tests, run once."""
    config = pcmb.load_config(CONFIGS_DIR / "mr_damper.yaml")
    study = pcmb.Study.from_config(config, {"backend": "inprocess", "nominal_run": False})
    study = study.replace(times=np.linspace(0.0, 6.0, 61))
    remedy = study.replace(
        method={**study.method.model_dump(exclude_unset=True), "elements": "auto"},
        diagnostics={"tolerance": 0.01},
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        return study, remedy.run()


@pytest.mark.slow
def test_mr_damper_fig_11_holds_only_with_the_remedy(mr_damper_remedy):
    """Part II Fig. 11 (x1 at t = 6 s), each method against 1000 Monte Carlo runs, judged by
    the Monte Carlo's standard errors (docs/paper_cases.md §3). The paper's departures grow as
    the square root of the runs: at 1000 the smallest (the distribution's) is about 6.5.

    The paper's order 3 (4 runs) is far outside them: x1(6 s) has 13 extrema in I, which a
    cubic cannot follow. The remedy the tool leads to, ``elements: auto`` at order 3, asked
    for 1 % of the largest std (below the 1.7 % by which 2000 Monte Carlo runs err), agrees
    within what it was asked plus 3 standard errors for the mean and the std (1 % of the
    largest std is 2.7 and 6.8 of them at 6 s). Its partition on this grid (61 times) also
    holds the distribution within the 99 % two-sample Kolmogorov–Smirnov distance (0.032
    from the reference of scripts/mr_damper_fig11.py); the tolerance does not bound the PDF,
    and on the script's 601 times the partition chosen is 0.066 from it.
    """
    study, remedy = mr_damper_remedy
    runs = 1000
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        # All runs in one stacked solve: its per-step overhead once, not once per 128 runs.
        carlo = study.replace(
            method={"kind": "montecarlo", "samples": runs, "seed": 1},
            execution={**study.execution.model_dump(exclude_unset=True), "chunk_size": runs},
        ).run()
        paper = study.run()
    sampled = carlo.values["x1"][carlo.ok][:, -1]
    std = sampled.std(ddof=1)
    kurtosis = np.mean((sampled - sampled.mean()) ** 4) / sampled.var() ** 2
    mean_error, std_error = std / np.sqrt(runs), std * np.sqrt((kurtosis - 1) / (4 * runs))
    draws = 100_000
    ks_99 = 1.628 * np.sqrt(1 / runs + 1 / draws)  # two-sample Kolmogorov–Smirnov, 99 %

    def departures(result):
        surrogate = result.expansions["x1"].sample(draws, seed=0)[:, -1]
        return (
            abs(result.mean("x1")[-1] - sampled.mean()) / mean_error,
            abs(result.std("x1")[-1] - std) / std_error,
            ks_2samp(surrogate, sampled).statistic / ks_99,
        )

    assert min(departures(paper)) > 5
    assert np.isfinite(paper.diagnostics["x1"].failing_from)  # and the tool says so
    asked = 0.01 * carlo.values["x1"][carlo.ok].std(axis=0, ddof=1).max()
    mean_z, std_z, ks = departures(remedy)
    assert mean_z < asked / mean_error + 3 and std_z < asked / std_error + 3
    assert ks < 1  # its verdict: the test below


@pytest.mark.slow
def test_mr_damper_remedy_is_not_flagged_by_its_held_out_check(mr_damper_remedy):
    """The remedy of Fig. 11 (``elements: auto``, order 3, to 1 %: 9 elements, 68 runs) is
    0.31 % off at worst over t in [0, 6] (against the reference of scripts/mr_damper_fig11.py,
    100 elements of 8 Gauss–Legendre points). Its held-out check once flagged it from t = 2.3:
    "mean off by an estimated 1.3 % (± 0.44 % from 19 held-out runs)", 98 % of it the unseen
    mean of the two elements without placed runs (I in [0.375, 0.5] and [0.75, 1]),
    extrapolated from their own degrees 1-3, whose two neighbour averages read flat: 560 and
    960 times their true errors (issue 23; the unit case in tests/test_held_out.py)."""
    _, remedy = mr_damper_remedy
    assert np.isnan(remedy.diagnostics["x1"].failing_from)


def test_linear_suspension_matches_the_closed_form_response():
    """Linear spring and damper: the whole response (transient and steady state) in closed
    form (:func:`pcmb.references.quarter_car_linear`)."""
    ms, mu, k, c, kt, a, f = 250.0, 35.0, 2.0e4, 1000.0, 1.5e5, 0.05, 1.3
    model = QuarterCar(spring="linear", Ms=ms, Mu=mu, k=k, c=c, kT=kt, A=a, f=f)
    times = np.linspace(0.0, 6.0, 601)
    out = model.simulate({}, times)
    exact = quarter_car_linear(times, ms=ms, mu=mu, k=k, c=c, kt=kt, amplitude=a, frequency=f)
    for k_state, name in enumerate(("x1", "x2", "v1", "v2")):
        scale = np.abs(exact[k_state]).max()
        # Global error of the default rtol 1e-8: the documented 1e-6 of the scale.
        assert np.abs(out[name][0] - exact[k_state]).max() <= PROMISE * scale, name


def test_cubic_suspension_balances_its_energy():
    """E = ½Ms v1² + ½Mu v2² + ¼k δ⁴ + ½kT (x2 − z)² changes by ∫(−c δ'² + kT (z − x2) z') dt.

    The power is integrated with Simpson's rule on a 1e-4 s grid (quadrature error ~1e-9 of
    E); the remaining residual is the integration error, 1e-6 of the energy scale by the
    model's promise.
    """
    model = QuarterCar(A=0.06, f=1.5)
    times = np.linspace(0.0, 3.0, 30001)
    out = model.simulate({}, times)
    p = model.parameters
    x1, x2, v1, v2, z = (out[name][0] for name in ("x1", "x2", "v1", "v2", "z"))
    z_dot = p["A"] * 2 * np.pi * p["f"] * np.cos(2 * np.pi * p["f"] * times)
    energy = (
        0.5 * p["Ms"] * v1**2
        + 0.5 * p["Mu"] * v2**2
        + 0.25 * p["k"] * (x1 - x2) ** 4
        + 0.5 * p["kT"] * (x2 - z) ** 2
    )
    power = -p["c"] * (v1 - v2) ** 2 + p["kT"] * (z - x2) * z_dot
    work = np.array([simpson(power[: i + 1], x=times[: i + 1]) for i in range(0, times.size, 1000)])
    residual = energy[::1000] - energy[0] - work
    assert energy.max() > 10.0  # the check is not vacuous: the car is shaken
    assert np.abs(residual).max() <= PROMISE * energy.max()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"terrain": "gravel"}, "terrain must be one of sine, bump, kl"),
        ({"damper": "magnetic"}, "damper must be one of linear, mr"),
        ({"spring": "quadratic"}, "spring must be one of cubic, linear"),
        ({"I": 1.0}, "no parameter 'I'"),  # the linear damper has no current
        ({"terrain": "bump", "A": 0.1}, "no parameter 'A'"),
        ({"Ms": -250.0}, "'Ms' must be positive"),
        ({"damper": "mr", "I": -0.5}, "'I' must be non-negative"),
        ({"kT": "150000"}, "'kT' must be a number"),
    ],
)
def test_invalid_options_and_parameters_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        QuarterCar(**kwargs)


def test_parameters_follow_the_options():
    assert set(QuarterCar().parameters) == {
        "Ms", "Mu", "kT", "k", "c", "A", "f", "x1_0", "x2_0", "v1_0", "v2_0",
    }  # fmt: skip
    mr_kl = QuarterCar(terrain="kl", damper="mr").parameters
    assert {"I", "c0", "c1", "F0", "F1", "mr_slope", "xi11", "speed"} <= set(mr_kl)
    assert "c" not in mr_kl and "A" not in mr_kl
