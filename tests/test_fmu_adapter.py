"""``kind: fmu``: real FMUs, built by pythonfmu at test time (``fmu_dir``), run through FMPy.

The FMUs (``models/fmu/DampedOscillator.py``, ``tests/data/fmu/*.py``) are the free damped
oscillator x'' + c x' + k x = 0, whose exact solution is known:

- DampedOscillator and Springs (co-simulation, FMI 2.0) and Oscillator3 as co-simulation
  (FMI 3.0) advance their state by the exact solution over each communication step, so
  their outputs are the closed form to rounding wherever the steps land: a step that missed
  an output time would show at 1e-13;
- Oscillator3 as model exchange (FMI 3.0, with units) is integrated by FMPy's CVode, so it
  matches the closed form to the integration tolerance.

Statistics of chaos studies (uncertain k, c) are checked against a tensor Gauss–Legendre
quadrature of the closed form with 60 points per input, independent of pcmb: to 1e-8 at
order 4 (the collocation truncation error; see tests/test_docs_models.py), from YAML through
``pcmb run`` and from Python through ``pcmb.Study``.
"""

from __future__ import annotations

import ctypes
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss

import pcmb
from pcmb.adapters.fmu.factory import FmuModelFactory
from pcmb.cli import main
from pcmb.config import validate_config
from pcmb.errors import (
    ConfigError,
    MissingDependencyError,
    ModelError,
    ModelRunError,
    PcmbWarning,
)
from pcmb.references import damped_oscillator
from pcmb.result import Status
from pcmb.run.fingerprint import model_files

ROOT = Path(__file__).resolve().parents[1]
K_RANGE, C_RANGE = (3.5, 4.5), (0.2, 0.6)
TIMES = np.linspace(0.0, 5.0, 101)
# Order 4 in (k, c): mean and std within 2e-9 of the converged values (test_docs_models.py).
ORDER, TOLERANCE = 4, 1e-8


def free_response(t, k, c, x0=1.0, v0=0.0):
    """x and v of x'' + c x' + k x = 0 from (x0, v0) at t = 0 (underdamped), each (T,)."""
    a = c / 2
    w = np.sqrt(k - a * a)
    b = (v0 + a * x0) / w
    decay, cos, sin = np.exp(-a * t), np.cos(w * t), np.sin(w * t)
    return decay * (x0 * cos + b * sin), decay * (v0 * cos - (a * b + w * x0) * sin)


def gauss_statistics(function, points=60):
    """Mean and std, (T,), of ``function(k, c)`` -> (N, T) over the uniform k and c."""
    z, w = leggauss(points)
    k, c = (lo + (hi - lo) * (z + 1) / 2 for lo, hi in (K_RANGE, C_RANGE))
    kk, cc = np.meshgrid(k, c, indexing="ij")
    weights = np.outer(w / 2, w / 2).ravel()
    values = function(kk.ravel(), cc.ravel())
    mean = weights @ values
    return mean, np.sqrt(weights @ (values - mean) ** 2)


def exact_x(k, c):
    return damped_oscillator(TIMES, k, c)


def check_statistics(result, tolerance=TOLERANCE):
    mean, std = gauss_statistics(exact_x)
    assert np.abs(result.mean("x") - mean).max() <= tolerance
    assert np.abs(result.std("x") - std).max() <= tolerance


def oscillator(fmu_dir, **arguments):
    return FmuModelFactory(fmu=fmu_dir / "DampedOscillator.fmu", **arguments)


def springs(fmu_dir, **arguments):
    arguments.setdefault("bind", {"k0": ("k[0]",)})
    arguments.setdefault("outputs", ("x[0]", "x[1]"))
    return FmuModelFactory(fmu=fmu_dir / "Springs.fmu", **arguments)


def config_data(fmu, **model):
    return {
        "name": "fmu",
        "model": {"kind": "fmu", "fmu": str(fmu), **model},
        "time": {"start": 0.0, "stop": 1.0, "points": 11},
        "inputs": {"k": {"dist": "uniform", "low": 3.5, "high": 4.5}},
        "method": {"kind": "collocation", "order": 1},
        "execution": {"jobs": 1},
    }


# --------------------------------------------------------------------------- co-simulation


def test_cosimulation_steps_onto_an_uneven_grid_from_its_start_time(fmu_dir):
    model = oscillator(fmu_dir, params={"x0": 0.5, "v0": 0.3})()
    assert model.interface == "co-simulation"
    rng = np.random.default_rng(1)
    times = np.sort(0.3 + 4.0 * rng.random(40))  # starts at 0.3, uneven steps
    k, c = np.array([3.6, 4.4]), np.array([0.25, 0.55])
    out = model.simulate({"k": k, "c": c}, times)
    for i in range(2):
        x, v = free_response(times - times[0], k[i], c[i], x0=0.5, v0=0.3)
        np.testing.assert_allclose(out["x"][i], x, rtol=0, atol=1e-13)
        np.testing.assert_allclose(out["v"][i], v, rtol=0, atol=1e-13)


def test_fmi3_cosimulation_is_the_default_interface_of_an_fmu_with_both(fmu_dir):
    model = FmuModelFactory(fmu=fmu_dir / "Oscillator3.fmu")()
    assert model.interface == "co-simulation"
    times = np.sort(np.random.default_rng(2).random(30)) * 5.0  # uneven steps
    k, c = np.array([3.6, 4.4]), np.array([0.25, 0.55])
    out = model.simulate({"k": k, "c": c}, times)
    for i in range(2):
        x, v = free_response(times - times[0], k[i], c[i])
        np.testing.assert_allclose(out["x"][i], x, rtol=0, atol=1e-13)
        np.testing.assert_allclose(out["v"][i], v, rtol=0, atol=1e-13)
    assert model.instantiations == 1


def test_parameters_are_the_settable_real_variables_with_their_start_values(fmu_dir):
    model = oscillator(fmu_dir, params={"x0": 0.5})()
    assert dict(model.parameters) == {"k": 4.0, "c": 0.4, "x0": 0.5, "v0": 0.0}
    assert model.outputs == ("x", "v")  # default: the variables of causality output
    out = model.simulate({}, TIMES)  # no uncertain input: one run at the start values
    np.testing.assert_allclose(out["x"][0], free_response(TIMES, 4.0, 0.4, x0=0.5)[0], atol=1e-13)


def test_array_variables_by_their_fmi_names(fmu_dir):
    model = springs(fmu_dir, params={"k[1]": 6.25})()
    assert model.outputs == ("x[0]", "x[1]")
    assert model.parameters["k0"] == 4.0  # a bound input's nominal: its variable's start
    k0 = np.array([3.6, 4.4])
    out = model.simulate({"k0": k0}, TIMES)
    np.testing.assert_allclose(out["x[0]"], damped_oscillator(TIMES, k0, 0.4), atol=1e-13)
    np.testing.assert_allclose(out["x[1]"], damped_oscillator(TIMES, [6.25] * 2, 0.4), atol=1e-13)


def test_one_instance_reset_between_nodes(fmu_dir):
    model = oscillator(fmu_dir)()
    k, c = np.linspace(3.6, 4.4, 5), np.linspace(0.25, 0.55, 5)
    forward = model.simulate({"k": k, "c": c}, TIMES)
    backward = model.simulate({"k": k[::-1], "c": c[::-1]}, TIMES)
    assert model.instantiations == 1
    # every node starts from the same state whatever ran before it, bit for bit
    np.testing.assert_array_equal(forward["x"], backward["x"][::-1])
    fresh = oscillator(fmu_dir)().simulate({"k": k[2:3], "c": c[2:3]}, TIMES)
    np.testing.assert_array_equal(forward["x"][2], fresh["x"][0])


@pytest.mark.parametrize(
    ("threshold", "status", "instantiations"),
    [("discard_above", "status 2 (discard)", 1), ("raise_above", "status 4 (fatal)", 2)],
)
def test_a_failing_step_is_a_failed_node(fmu_dir, threshold, status, instantiations):
    model = springs(fmu_dir, params={threshold: 4.0}, outputs=("x[0]",))()
    times = np.linspace(0.0, 1.0, 21)
    k0 = np.array([3.6, 4.4, 3.8])
    out = model.simulate({"k0": k0}, times)
    assert np.isnan(out["x[0]"][1]).all()
    exact = damped_oscillator(times, k0[[0, 2]], 0.4)
    np.testing.assert_allclose(out["x[0]"][[0, 2]], exact, atol=1e-13)  # before and after
    assert model.instantiations == instantiations  # after a fatal status: a new instance
    with pytest.raises(ModelError, match=re.escape(status)) as caught:
        model.simulate({"k0": k0[1:2]}, times)
    assert "the FMU failed at t = 0.55: " in str(caught.value)  # the step from 0.55 to 0.6


def test_model_exchange_is_integrated_to_its_tolerance(fmu_dir):
    fmu = fmu_dir / "Oscillator3.fmu"
    k, c = np.array([3.6, 4.4]), np.array([0.25, 0.55])
    errors = {}
    for rtol in (1e-5, 1e-10):
        model = FmuModelFactory(
            fmu=fmu, interface="model-exchange", rtol=rtol, units={"x": "m", "k": "1/s2"}
        )()
        assert model.interface == "model-exchange"
        out = model.simulate({"k": k, "c": c}, TIMES)
        errors[rtol] = np.abs(out["x"] - damped_oscillator(TIMES, k, c)).max()
    assert errors[1e-10] < 1e-7 < errors[1e-5]  # the tolerance is CVode's


def test_a_failing_model_exchange_run_is_a_failed_node(fmu_dir):
    model = FmuModelFactory(
        fmu=fmu_dir / "Oscillator3.fmu",
        interface="model-exchange",
        params={"fail_after": 2.0},
        rtol=1e-10,
    )()
    with pytest.raises(
        ModelError, match=r"the FMU failed at t = 2(\.0\d*)?: RuntimeError: CVode error"
    ):
        model.simulate({"k": np.array([4.0])}, TIMES)
    # the instance is reset after the failure: a node that never reaches t = 2 runs exactly
    out = model.simulate({"k": np.array([4.0])}, TIMES[:40])
    np.testing.assert_allclose(out["x"][0], damped_oscillator(TIMES[:40], 4.0, 0.4), atol=1e-7)


def test_the_solver_guard_keeps_an_fmi_error_from_the_solver_callbacks(fmu_dir):
    # An FMI error inside CVode's right-hand side cannot pass through FMPy's C callback:
    # the guard keeps it, gives the solver NaN and calls the FMU no more.
    from pcmb.adapters.fmu.model import _SolverGuard

    model = FmuModelFactory(fmu=fmu_dir / "Oscillator3.fmu", interface="model-exchange")()
    guard = _SolverGuard(model._instance)
    guard.enterInitializationMode(startTime=0.0)
    guard.exitInitializationMode()
    guard.enterContinuousTimeMode()
    buffer = (ctypes.c_double * 3)()
    guard.getContinuousStateDerivatives(buffer, 2)
    assert list(buffer) == [0.0, -4.0, 0.0] and guard.error is None
    guard.getContinuousStateDerivatives(buffer, 3)  # a size the FMU refuses: an error
    error = guard.error
    assert error is not None and np.isnan(list(buffer)).all()
    guard.setTime(0.5)
    guard.getContinuousStateDerivatives(buffer, 2)  # not called: NaN again, same error
    assert guard.error is error and np.isnan(list(buffer)[:2]).all()


def test_model_exchange_needs_an_evenly_spaced_grid(fmu_dir):
    model = FmuModelFactory(fmu=fmu_dir / "Oscillator3.fmu", interface="model-exchange")()
    with pytest.raises(ConfigError, match="time: a model-exchange FMU needs an evenly spaced"):
        model.check_times(np.array([0.0, 0.1, 0.3]))


def test_the_fmu_file_is_fingerprinted(fmu_dir):
    assert model_files(oscillator(fmu_dir)) == [fmu_dir / "DampedOscillator.fmu"]


# --------------------------------------------------------------------------- checks


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fmu", "model", "inputs", "expected"),
    [
        (
            "DampedOscillator",
            {"outputs": ["x", "xx"]},
            None,
            "model.outputs[1]: 'xx' is not a variable of the FMU (did you mean x?); "
            "variables are k, c, x0, v0, x, v",
        ),
        (
            "DampedOscillator",
            {"params": {"x": 2.0}},
            None,
            "model.params.x: 'x' cannot be set: its causality is output",
        ),
        (
            "DampedOscillator",
            {"params": {"x0": "1.0"}},
            None,
            "model.params.x0: expected a number, true or false",
        ),
        (
            "DampedOscillator",
            {"params": {"x0": True}},
            None,
            "model.params.x0: 'x0' is a real variable of the FMU, got True",
        ),
        (
            "DampedOscillator",
            {"interface": "model-exchange"},
            None,
            "model.interface: the FMU has no model-exchange interface (it has: co-simulation)",
        ),
        (
            "Oscillator3",
            {"units": {"x": "m", "k": "N/m"}},
            None,
            "model.units.k: the FMU declares 'k' in '1/s2', not in 'N/m'",
        ),
        (
            "Springs",
            {"bind": {"k0": ["k[2]"]}},
            {"k0": {"dist": "uniform", "low": 3.5, "high": 4.5}},
            "model.bind.k0[0]: 'k[2]' is not a variable of the FMU (did you mean",
        ),
        (
            "Springs",
            {"bind": {"c": ["k[0]"]}},
            {"c": {"dist": "uniform", "low": 0.2, "high": 0.6}},
            "model.bind.c: 'c' is a variable of the FMU",
        ),
        (
            "DampedOscillator",
            {},
            {"x": {"dist": "uniform", "low": 0.5, "high": 1.5}},
            "inputs.x: 'x' is not a parameter of FmuModel (parameters: k, c, x0, v0)",
        ),
        ("Missing", {}, None, "model.fmu: file "),
    ],
)
def test_validation_names_the_key(fmu_dir, fmu, model, inputs, expected):
    data = config_data(fmu_dir / f"{fmu}.fmu", **model)
    if inputs is not None:
        data["inputs"] = inputs
    with pytest.raises(ConfigError) as caught:
        validate_config(data)
    assert expected in str(caught.value)


def test_pcmb_validate_reports_a_bad_output_with_its_line(fmu_dir, tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    text = (ROOT / "configs" / "fmu_oscillator.yaml").read_text(encoding="utf-8")
    text = text.replace("../models/fmu/build", str(fmu_dir)).replace("[x, v]", "[x, vv]")
    config.write_text(text, encoding="utf-8")
    assert main(["validate", str(config)]) == 2
    err = capsys.readouterr().err
    line = text.splitlines().index(next(s for s in text.splitlines() if "[x, vv]" in s)) + 1
    assert f"bad.yaml:{line}: model.outputs[1]: 'vv' is not a variable of the FMU" in err


def test_without_fmpy_the_message_names_the_extra(fmu_dir, monkeypatch):
    monkeypatch.setitem(sys.modules, "fmpy", None)  # as if fmpy were not installed
    monkeypatch.delitem(sys.modules, "pcmb.adapters.fmu.model", raising=False)
    with pytest.raises(MissingDependencyError, match=r'pip install "pcmb\[fmu\]"'):
        oscillator(fmu_dir)()


def test_a_file_that_is_not_an_fmu(tmp_path):
    fake = tmp_path / "fake.fmu"
    fake.write_text("not a zip archive", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"model.fmu: cannot read .*fake.fmu as an FMU"):
        FmuModelFactory(fmu=fake)()


# --------------------------------------------------------------------------- studies


def test_chaos_statistics_from_yaml_match_the_exact_solution(fmu_dir, tmp_path):
    config = tmp_path / "fmu_oscillator.yaml"
    text = (ROOT / "configs" / "fmu_oscillator.yaml").read_text(encoding="utf-8")
    config.write_text(text.replace("../models/fmu/build", str(fmu_dir)), encoding="utf-8")
    out = tmp_path / "out.h5"
    assert main(["run", str(config), "-o", str(out), "--quiet"]) == 0
    result = pcmb.load(out)
    assert result.values["x"].shape == ((ORDER + 1) ** 2, TIMES.size)
    np.testing.assert_allclose(result.values["x"], exact_x(*result.params.T), atol=1e-13)
    check_statistics(result)


def test_chaos_statistics_from_python_model_exchange(fmu_dir):
    study = pcmb.Study(
        FmuModelFactory(
            fmu=fmu_dir / "Oscillator3.fmu", interface="model-exchange", rtol=1e-10, outputs=("x",)
        ),
        {"k": pcmb.Uniform(*K_RANGE), "c": pcmb.Uniform(*C_RANGE)},
        TIMES,
        order=ORDER,
        nominal={"k": 4.0, "c": 0.4},
        jobs=2,
    )
    result = study.run()
    # CVode at rtol 1e-10: each node within 1e-7 of the closed form (see above), which bounds
    # the error of the quadrature mean and std too
    np.testing.assert_allclose(result.values["x"], exact_x(*result.params.T), atol=1e-7)
    check_statistics(result, tolerance=1e-7)


def test_array_outputs_through_the_store(fmu_dir, tmp_path):
    study = pcmb.Study(
        springs(fmu_dir),
        {"k0": pcmb.Uniform(*K_RANGE)},
        TIMES,
        order=6,
        nominal={"k0": 4.0},
        jobs=1,
    )
    study.run(tmp_path / "springs.h5")
    result = pcmb.load(tmp_path / "springs.h5")
    assert result.outputs == ("x[0]", "x[1]")
    np.testing.assert_allclose(result.values["x[0]"], exact_x(result.params[:, 0], 0.4), atol=1e-13)
    np.testing.assert_allclose(result.std("x[1]"), 0.0, atol=1e-13)  # k[1] is fixed


def test_failed_steps_follow_the_failure_policy(fmu_dir):
    def study(policy):
        return pcmb.Study(
            springs(fmu_dir, params={"discard_above": 4.3}, outputs=("x[0]",)),
            {"k0": pcmb.Uniform(*K_RANGE)},
            TIMES,
            order=3,
            nominal={"k0": 4.0},
            on_failure=policy,
            jobs=1,
            validation=0,
        )

    with pytest.raises(ModelRunError) as caught:
        study("abort").run()
    failed = caught.value.failures
    assert [f.index for f in failed] == [3]  # the one Gauss node above 4.3
    assert "fmi2DoStep failed with status 2 (discard)" in failed[0].message
    with pytest.warns(PcmbWarning) as records:  # the refit on 3 nodes warns too
        result = study("regress").run()
    assert any(re.search(r"node 3 .*status 2 \(discard\)", str(r.message)) for r in records)
    assert np.flatnonzero(result.status == Status.FAILED).tolist() == [3]


@pytest.mark.slow
def test_a_crash_in_the_fmu_costs_only_its_chunk(fmu_dir):
    study = pcmb.Study(
        springs(fmu_dir, params={"crash_above": 4.3}, outputs=("x[0]",)),
        {"k0": pcmb.Uniform(*K_RANGE)},
        TIMES,
        order=3,
        nominal={"k0": 4.0},
        on_failure="regress",
        jobs=2,
        validation=0,
    )
    with pytest.warns(PcmbWarning) as records:  # the refit on 3 nodes warns too
        result = study.run()  # this process runs no FMU code: it survives and goes on
    assert any(re.search(r"node 3 .*SIGSEGV", str(r.message)) for r in records)
    assert np.flatnonzero(result.status == Status.FAILED).tolist() == [3]
    assert "worker process died (signal 11, SIGSEGV)" in result.failures[0].message
    ok = result.status == Status.OK
    np.testing.assert_allclose(
        result.values["x[0]"][ok], exact_x(result.params[ok, 0], 0.4), atol=1e-13
    )
