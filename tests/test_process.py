"""Random process inputs: the Karhunen–Loève expansion against closed forms, the config
section and its errors, and a study with a field input against exact statistics."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

import pcmb
from pcmb.chaos import process
from pcmb.config import validate_config
from pcmb.errors import ConfigError
from pcmb.references import cosine_covariance_kl, exponential_kl_eigenvalues


@pytest.fixture(scope="module")
def exponential_kl() -> process.RandomProcess:
    """σ = 1, ℓ = 1 on [0, 10], 201 points: 41 germs keep 95 % (Nyström on 2001 points)."""
    return process.RandomProcess.karhunen_loeve(
        process.exponential(1.0, 1.0), 0.0, 10.0, 201, energy=0.95
    )


@pytest.mark.slow
def test_exponential_eigenvalues_match_the_transcendental_equations(exponential_kl):
    kl = exponential_kl
    exact = exponential_kl_eigenvalues(1.0, 1.0, 10.0, kl.terms)
    error = np.abs(kl.eigenvalues - exact) / exact
    # The kink-corrected Gregory rule on 2001 points (h = 0.005) errs by ~(ω_k h)⁴/240 up to
    # a few times that: 5e-11 to 2e-9 for the first five modes, 2e-7 at the 41st (ω ≈ 13); the
    # Richardson estimate is within 3x.
    assert error[:5].max() < 1e-8
    assert error.max() < 1e-6
    assert error.max() <= 3 * kl.eigenvalue_error
    assert kl.eigenvalue_error <= 3 * error.max()


def test_energy_keeps_the_fewest_germs_the_exact_eigenvalues_need(exponential_kl):
    exact = exponential_kl_eigenvalues(1.0, 1.0, 10.0, 200)
    captured = np.cumsum(exact) / 10.0  # the trace σ²·(b - a)
    assert exponential_kl.terms == np.searchsorted(captured, 0.95) + 1
    assert exponential_kl.captured_energy == pytest.approx(captured[exponential_kl.terms - 1])


def test_truncation_error_is_the_neglected_eigenvalue_sum(exponential_kl):
    kl = exponential_kl
    neglected = 10.0 - exponential_kl_eigenvalues(1.0, 1.0, 10.0, kl.terms).sum()
    assert kl.truncation_error * kl.total_variance == pytest.approx(neglected, rel=1e-5)
    # Independently: the variance the kept modes miss at the grid points, integrated over the
    # interval (trapezoid; ~1e-3 for the oscillating tail modes at 2ωh ≈ 1.3).
    weights = np.full(kl.grid.size, kl.grid[1] - kl.grid[0])
    weights[[0, -1]] /= 2
    assert weights @ kl.variance_error == pytest.approx(neglected, rel=5e-3)
    assert np.all(kl.variance_error > 0)


@pytest.mark.slow
def test_a_line_spectrum_gives_exactly_two_terms_per_line():
    omega = [6 * np.pi / 100, 14 * np.pi / 100]  # 3 and 7 periods on [0, 100]
    kl = process.RandomProcess.karhunen_loeve(
        process.line_spectrum(omega, [0.04, 0.01]), 0.0, 100.0, 501, energy=1.0
    )
    expected, functions = cosine_covariance_kl(kl.grid, [0.04, 0.01], 1 / np.array(omega), 100)
    # Gregory's end weights are not exact for whole periods as the plain trapezoid is: their
    # O((ωh)⁴) error is ~2e-9 for ω = 0.44, h = 0.1.
    np.testing.assert_allclose(kl.eigenvalues, expected, rtol=1e-8)
    assert kl.captured_energy == pytest.approx(1.0, rel=1e-8)
    # Each double eigenvalue's modes span {cos, sin}: compare the projectors.
    for pair in (slice(0, 2), slice(2, 4)):
        modes = kl.modes[pair] / np.sqrt(kl.eigenvalues[pair])[:, None]
        np.testing.assert_allclose(
            modes.T @ modes, functions[:, pair] @ functions[:, pair].T, atol=1e-9
        )
    # Not a whole number of periods: still exactly two eigenpairs per line (rank 4).
    with pytest.raises(ValueError, match="4 non-zero eigenvalues"):
        process.RandomProcess.karhunen_loeve(
            process.line_spectrum(omega, [0.04, 0.01]), 0.0, 77.0, 301, terms=5
        )
    # Three terms carry 0.9 of the variance: energy 0.95 needs all four.
    short = process.RandomProcess.karhunen_loeve(
        process.line_spectrum(omega, [0.04, 0.01]), 0.0, 100.0, 501, energy=0.95
    )
    assert short.terms == 4


@pytest.mark.slow
def test_matern_special_cases_are_closed_forms():
    tau = np.array([0.0, 0.3, 1.0, 4.0])
    half = process.matern(2.0, 1.5, 0.5).function(tau)
    np.testing.assert_allclose(half, process.exponential(2.0, 1.5).function(tau))
    r = np.sqrt(3) * tau / 1.5
    three_halves = process.matern(2.0, 1.5, 1.5).function(tau)
    np.testing.assert_allclose(three_halves, 4.0 * (1 + r) * np.exp(-r), rtol=1e-12)
    # ν = 1/2 carries the exponential's kink correction: the same eigenvalues.
    a = process.RandomProcess.karhunen_loeve(process.matern(1.0, 2.0, 0.5), 0, 10, 101, terms=8)
    exact = exponential_kl_eigenvalues(1.0, 2.0, 10.0, 8)
    np.testing.assert_allclose(a.eigenvalues, exact, rtol=1e-7)


@pytest.mark.slow
def test_a_tabulated_psd_reproduces_its_covariance_eigenvalues():
    """The PSD (2σ²ℓ/π)/(1 + (ωℓ)²) of σ² exp(-|τ|/ℓ), cut at ω = 2000/ℓ (variance lost
    ~2/(π·2000) = 3e-4 of σ², mostly as a smoothing of the kink at zero lag). Steps of 0.1 in ω
    turn cos(ωτ) by at most 0.5 rad at the longest lag τ = 5: the trapezoidal error is far
    below the cut's."""
    omega = np.linspace(0.0, 2000.0, 20_001)
    psd = process.tabulated_psd(omega, (2 / np.pi) / (1 + omega**2))
    kl = process.RandomProcess.karhunen_loeve(psd, 0.0, 5.0, 201, terms=6)
    np.testing.assert_allclose(kl.eigenvalues, exponential_kl_eigenvalues(1, 1, 5, 6), rtol=2e-3)


def test_realisations_have_the_expanded_covariance(exponential_kl):
    germs = np.random.default_rng(0).standard_normal((4000, exponential_kl.terms))
    field = exponential_kl.realize(germs)
    assert field.shape == (4000, 201)
    points = [0, 50, 100, 200]
    kept = exponential_kl.modes[:, points].T @ exponential_kl.modes[:, points]
    sample = np.cov(field[:, points], rowvar=False)
    # Sampling error of a covariance entry ~ sqrt(2/4000) of the variance.
    np.testing.assert_allclose(sample, kept, atol=0.07)


# --------------------------------------------------------------------------- config

CONFIG = {
    "name": "field",
    "model": {"kind": "python", "entry": "field_model.py:Probe"},
    "time": {"start": 0.0, "stop": 1.0, "points": 3},
    "inputs": {
        "road": {
            "process": "kl",
            "covariance": {"kind": "exponential", "sigma": 0.05, "length": 5.0},
            "grid": {"start": 0, "stop": 20, "points": 41},
            "energy": 0.9,
        },
        "a": {"dist": "uniform", "low": -0.1, "high": 0.1},
    },
    "method": {"kind": "collocation", "order": {"road": 1, "a": 1}, "validation": 0},
    "execution": {"jobs": 1, "nominal_run": False},
}

MODEL = '''
import numpy as np

class Probe:
    """y(t) = road(x = 10) + a·t: a linear functional of the field and a scalar."""
    outputs = ("y",)
    parameters = {"road": 0.0, "a": 0.0}

    def simulate(self, params, times):
        road = np.asarray(params["road"])
        assert road.ndim == 2 and road.shape[1] == 41, road.shape
        return {"y": road[:, 20:21] + np.asarray(params["a"])[:, None] * times}
'''


def _config(tmp_path, **inputs):
    (tmp_path / "field_model.py").write_text(MODEL)
    data = {**CONFIG, "inputs": {**CONFIG["inputs"], **inputs}}
    return validate_config(data, base_dir=tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("setting", "key", "message"),
    [
        (
            {"covariance": {"kind": "exponential", "sigma": 0.05, "length": -5.0}},
            "inputs.road.covariance.length",
            "> 0",
        ),
        (
            {"covariance": {"kind": "matern", "sigma": 0.05, "length": 5.0}},
            "inputs.road.covariance.nu",
            "missing",
        ),
        (
            {"covariance": {"kind": "lines", "omega": [0.1, 0.2], "variance": [1.0]}},
            "inputs.road.covariance.variance",
            "expected 2 values",
        ),
        ({"grid": {"start": 3, "stop": 1, "points": 11}}, "inputs.road.grid.stop", "stop > start"),
        ({"grid": {"start": 0, "stop": 1, "points": 5000}}, "inputs.road.grid.points", "<= 2001"),
        ({"terms": 3}, "inputs.road.terms", "not both"),
        ({"energy": 1.5}, "inputs.road.energy", "<= 1"),
        ({"energy": None, "terms": 0}, "inputs.road.terms", ">= 1"),
        ({"process": "pce"}, "inputs.road.process", "expected 'kl'"),
    ],
)
def test_bad_process_settings_name_their_key(tmp_path, setting, key, message):
    road = {**CONFIG["inputs"]["road"], **setting}
    with pytest.raises(ConfigError) as caught:
        _config(tmp_path, road=road)
    paths = {problem.path: problem.message for problem in caught.value.problems}
    assert key in paths, paths
    assert message in paths[key]


def test_an_input_that_is_neither_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"inputs\.road: expected a distribution"):
        _config(tmp_path, road={"covariance": {}})


def test_study_hands_the_model_the_field_and_stores_the_process(tmp_path):
    config = _config(tmp_path)
    kl = config.study_inputs["road"]
    names = [f"road[{k}]" for k in range(kl.terms)]
    assert config.input_names == (*names, "a")
    result = pcmb.Study.from_config(config).run(tmp_path / "out.h5")
    # y = z(10) + a·t is linear in the germs: order 1 is exact. Var z(10) is the kept
    # modes' sum of squares there; Var a = 0.2²/12.
    var_road = np.sum(kl.modes[:, 20] ** 2)
    var_a = 0.2**2 / 12 * config.times**2
    np.testing.assert_allclose(result.mean("y"), 0.0, atol=1e-15)
    np.testing.assert_allclose(result.std("y") ** 2, var_road + var_a, rtol=1e-12)
    assert var_road == pytest.approx(0.05**2 - kl.variance_error[20], rel=1e-12)
    grouped = result.sobol_process("y", "road")
    np.testing.assert_allclose(grouped, var_road / (var_road + var_a), rtol=1e-12)
    # Per germ, the indices of the group add up to the group's (no interactions here).
    np.testing.assert_allclose(result.sobol_total("y")[: kl.terms].sum(axis=0), grouped)

    with h5py.File(tmp_path / "out.h5") as file:
        group = file["processes/road"]
        np.testing.assert_array_equal(group["eigenvalues"][()], kl.eigenvalues)
        assert group["modes"].shape == (kl.terms, 41)
        assert group.attrs["truncation_error"] == pytest.approx(kl.truncation_error)
        np.testing.assert_allclose(group["sobol_total/y"][()], grouped)
    loaded = pcmb.load(tmp_path / "out.h5")
    np.testing.assert_array_equal(loaded.processes["road"].modes, kl.modes)
    np.testing.assert_allclose(loaded.sobol_process("y", "road"), grouped)


@pytest.mark.slow
@pytest.mark.parametrize(
    "method",
    [
        {"kind": "collocation", "grid": "smolyak", "level": 1},
        {"kind": "regression", "samples": 60, "order": 1, "selection": "none", "q": 1.0},
        {"kind": "montecarlo", "samples": 64, "seed": 1},
        {"kind": "adaptive", "tolerance": 1e-3, "max_runs": 200},
    ],
)
def test_process_germs_are_ordinary_inputs_for_every_method(tmp_path, method):
    road = {**CONFIG["inputs"]["road"], "energy": None, "terms": 3}
    config = _config(tmp_path, road=road)
    data = {**config.model_dump(mode="json"), "method": {**method, "validation": 0}}
    data["model"]["entry"] = "field_model.py:Probe"
    study = pcmb.Study.from_config(validate_config(data, base_dir=tmp_path))
    result = study.run()
    kl = study.processes["road"]
    var = np.sum(kl.modes[:, 20] ** 2) + 0.2**2 / 12 * config.times**2
    if method["kind"] == "montecarlo":  # sampling error of a variance: sqrt(2/N)
        np.testing.assert_allclose(result.std("y") ** 2, var, rtol=4 * np.sqrt(2 / 64))
    else:  # linear in the germs: exact
        np.testing.assert_allclose(result.std("y") ** 2, var, rtol=1e-10)


def test_validate_says_how_many_germs_and_the_energy_kept(tmp_path, capsys):
    from pcmb.cli import main

    (tmp_path / "field_model.py").write_text(MODEL)
    config = tmp_path / "field.yaml"
    config.write_text(json.dumps(CONFIG))  # JSON is YAML
    assert main(["validate", str(config)]) == 0
    kl = _config(tmp_path).study_inputs["road"]
    shown = capsys.readouterr().out
    assert (
        f"process  road: exponential covariance, {kl.terms} germs road[0]..road[{kl.terms - 1}] "
        f"keep {kl.captured_energy:.4f} of the variance"
    ) in shown
    assert "  road[0]    normal(mean=0.0, std=1.0)" in shown
