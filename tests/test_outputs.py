"""Outputs that are not time series (scalars, outputs on their own axis) and ``derived:``
figures of merit, from the model or the config through run, store, inspect, report and
compare, against closed forms and fine quadratures."""

from __future__ import annotations

import csv
import stat
import sys
import textwrap
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from output_models import FREQUENCIES, Decay, Resonance, gain

import pcmb
from pcmb.analysis.comparison import compare
from pcmb.analysis.derived import FIGURES, DerivedOutput, derive, parse_derived
from pcmb.cli import main
from pcmb.config import load_config
from pcmb.errors import ConfigError, ModelDefinitionError, ModelError, UsageError
from pcmb.result import Status
from pcmb.run.journal import Journal
from pcmb.sweep.table import read_sweep

MODELS = Path(__file__).parent / "output_models.py"
GAUSS = np.polynomial.legendre.leggauss(400)


def uniform_moments(function, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of ``function(u)``, u ~ U[low, high], by 400-point Gauss-Legendre."""
    x, w = GAUSS
    values = function(0.5 * (low + high) + 0.5 * (high - low) * x)
    mean = (w / 2) @ values
    return mean, np.sqrt((w / 2) @ (values - mean) ** 2)


# ------------------------------------------------------------------ the figures, one by one


TIMES = np.linspace(0.0, 1.0, 101)


def test_every_figure_kind_matches_its_closed_form():
    a = np.array([[1.0], [2.5]])
    wave = a * np.sin(2 * np.pi * TIMES)
    np.testing.assert_allclose(FIGURES["max_abs"].function(TIMES, wave), a[:, 0], rtol=1e-15)
    # The trapezoid rule is exact for sin² over a whole period on a uniform grid.
    np.testing.assert_allclose(FIGURES["rms"].function(TIMES, wave), a[:, 0] / np.sqrt(2))
    ramp = a * TIMES
    np.testing.assert_allclose(FIGURES["at"].function(TIMES, ramp, time=0.3333), a[:, 0] * 0.3333)
    k = np.array([1.0, 2.0])
    step = 1.0 - np.exp(-np.outer(k, np.linspace(0.0, 1.0, 2001)))
    found = FIGURES["settling_time"].function(np.linspace(0.0, 1.0, 2001), step, band=0.02)
    final = np.exp(-k)
    exact = -np.log(final + 0.02 * (1.0 - final)) / k
    # Linear between grid points: an error of order k² dt² / 8.
    np.testing.assert_allclose(found, exact, atol=1e-7)


def test_settling_time_of_a_run_always_inside_its_band_is_the_start():
    flat = np.full((1, TIMES.size), 3.0)
    assert FIGURES["settling_time"].function(TIMES, flat, band=0.02)[0] == TIMES[0]


def test_a_nan_run_has_a_nan_figure_without_warnings():
    runs = np.vstack([np.sin(TIMES), np.full(TIMES.size, np.nan)])
    derived = parse_derived({name: {name: "y", **opts} for name, opts in _OPTIONS.items()})
    found = derive(derived, TIMES, {"y": runs})
    for name, values in found.items():
        assert values.shape == (2, 1)
        assert np.isfinite(values[0, 0]) and np.isnan(values[1, 0]), name


_OPTIONS = {"max_abs": {}, "rms": {}, "at": {"time": 0.5}, "settling_time": {"band": 0.1}}


def test_every_registered_figure_is_tested():
    assert set(FIGURES) == set(_OPTIONS)


def test_derived_entries_are_parsed_with_defaults():
    found = parse_derived({"s": {"settling_time": "x"}, "p": {"at": "v", "time": 2}})
    assert found == {
        "s": DerivedOutput("settling_time", "x", {"band": 0.02}),
        "p": DerivedOutput("at", "v", {"time": 2.0}),
    }


@pytest.mark.parametrize(
    ("entry", "key", "message"),
    [
        ({}, "derived.d", "exactly one figure kind"),
        ({"rms": "x", "max_abs": "x"}, "derived.d", "exactly one figure kind"),
        ({"at": "x"}, "derived.d.time", "required by at"),
        ({"rms": "x", "band": 0.1}, "derived.d.band", "unknown option of rms"),
        ({"settling_time": "x", "band": -1}, "derived.d.band", "must be > 0"),
        ({"at": "x", "time": "soon"}, "derived.d.time", "expected a number"),
    ],
)
def test_bad_derived_entries_name_their_key(entry, key, message):
    with pytest.raises(ConfigError) as caught:
        parse_derived({"d": entry})
    assert [p.path for p in caught.value.problems] == [key]
    assert message in caught.value.problems[0].message


# ------------------------------------------------------------------------- configs


def _config(
    tmp_path: Path,
    derived: str,
    time: str = "{start: 0.0, stop: 1.0, points: 1001}",
    analysis: str = "{samples: 4000, units: {x1_peak: m, wave: m}}",
):
    text = textwrap.dedent(
        f"""\
        name: figures of merit
        model:
          kind: python
          entry: {MODELS}:Signals
        time: {time}
        inputs:
          a: {{dist: uniform, low: 1.0, high: 3.0}}
          b: {{dist: uniform, low: 0.0, high: 1.0}}
          k: {{dist: uniform, low: 1.0, high: 2.0}}
        method: {{kind: collocation, order: {{a: 2, b: 1, k: 8}}}}
        analysis: {analysis}
        derived: {derived}
        """
    )
    path = tmp_path / "figures.yaml"
    path.write_text(text)
    return path


DERIVED = (
    "{x1_peak: {max_abs: wave}, x1_rms: {rms: wave}, x2_at: {at: ramp, time: 0.3333}, "
    "x3_settle: {settling_time: step, band: 0.02}}"
)


def test_config_errors_name_the_derived_keys(tmp_path):
    path = _config(
        tmp_path, "{x1_peak: {max_abs: x9}, late: {at: ramp, time: 5.0}, wave: {rms: wave}}"
    )
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    found = {p.path: p.message for p in caught.value.problems}
    assert found["derived.x1_peak.max_abs"] == (
        "'x9' is not an output; outputs are wave, ramp, step, line"
    )
    assert found["derived.late.time"] == "5 is outside the grid [0, 1]"
    assert found["derived.wave"] == "'wave' is already an output of the model"


def test_a_figure_of_merit_has_a_unit_but_no_spectrum(tmp_path):
    path = _config(tmp_path, DERIVED, analysis="{psd: [wave, x1_peak], units: {x1_peak: m}}")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    found = {p.path: p.message for p in caught.value.problems}
    assert found == {"analysis.psd[1]": "'x1_peak' is not a time output"}


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("figures")
    path = _config(folder, DERIVED)
    output = folder / "figures.h5"
    assert main(["run", str(path), "-o", str(output), "--quiet"]) == 0
    return output, pcmb.load(output)


def test_derived_figures_have_their_exact_statistics(figures):
    _, result = figures
    third = 1.0 / np.sqrt(3.0)  # std of U[1, 3]
    expected = {
        "x1_peak": (2.0, third),
        "x1_rms": (np.sqrt(2.0), third / np.sqrt(2.0)),
        "x2_at": (0.5 * 0.3333, 0.3333 / np.sqrt(12.0)),
    }

    def settle(k):
        final = np.exp(-k)
        return -np.log(final + 0.02 * (1.0 - final)) / k

    expected["x3_settle"] = tuple(float(v) for v in uniform_moments(settle, 1.0, 2.0))
    for name, (mean, std) in expected.items():
        assert result.values[name].shape == (result.n_nodes, 1)
        assert result.axes[name] is None
        # Polynomials of the inputs (exact to round-off), or a smooth function of k on a
        # 1001-point grid (linear interpolation: k² dt² / 8 ~ 5e-7).
        np.testing.assert_allclose(result.mean(name), [mean], rtol=1e-6, err_msg=name)
        np.testing.assert_allclose(result.std(name), [std], rtol=1e-5, err_msg=name)


def test_derived_figures_get_sobol_indices_diagnostics_and_pdfs(figures):
    _, result = figures
    names = result.input_names
    # x1_peak = a: all of its variance is a's; x3_settle depends on k only.
    np.testing.assert_allclose(result.sobol_total("x1_peak")[:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(
        result.sobol_first("x3_settle")[names.index("k"), 0], 1.0, atol=1e-12
    )
    for name in ("x1_peak", "x1_rms", "x2_at", "x3_settle"):
        found = result.diagnostics[name]
        assert found.reliable and found.holdout is not None and found.holdout.count > 0
        assert found.estimate.shape == (1,)
        pdf = result.analysis.outputs[name].pdf
        assert pdf.at.tolist() == [0.0] and pdf.value.shape[0] == 1
    # The held-out runs got their figures too (from their own time series).
    held = result.held_out
    np.testing.assert_allclose(
        held.values["x1_peak"][:, 0], held.params[:, names.index("a")], rtol=1e-14
    )


def test_derived_figures_are_stored_without_a_time_dimension(figures):
    xarray = pytest.importorskip("xarray")
    path, result = figures
    with xarray.open_dataset(path, group="outputs/x3_settle", engine="h5netcdf") as ds:
        assert ds["values"].dims == ("node",)
        assert ds["mean"].dims == () and ds["std"].dims == ()
        assert ds["sobol_first"].dims == ("input",)
        assert ds["coefficients"].dims == ("term",)
        np.testing.assert_array_equal(ds["mean"].values, result.mean("x3_settle")[0])
    with xarray.open_dataset(path, group="outputs/wave", engine="h5netcdf") as ds:
        assert ds["values"].dims == ("node", "time")


def test_inspect_lists_the_derived_figures(figures, capsys):
    path, _ = figures
    assert main(["inspect", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in ("x1_peak", "x1_rms", "x2_at", "x3_settle"):
        (row,) = [line for line in lines if line.startswith(f"{name} ")]
        assert row.endswith("  scalar")
        assert any(line.startswith(f"checked  {name}: reliable (") for line in lines)


@pytest.mark.slow
def test_report_draws_a_scalar_as_pdf_and_sobol_bars(figures, tmp_path):
    pytest.importorskip("matplotlib")
    path, _ = figures
    assert main(["report", str(path), "-o", str(tmp_path / "report")]) == 0
    written = {p.name for p in (tmp_path / "report").iterdir()}
    assert {"x3_settle_pdf.png", "x3_settle_sobol.png", "wave_time.png"} <= written
    assert "x3_settle_time.png" not in written


# ------------------------------------------------------- model outputs off the time grid


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    output = tmp_path_factory.mktemp("swept") / "swept.h5"
    study = pcmb.Study(
        Resonance(),
        {"zeta": pcmb.Uniform(0.1, 0.3)},
        [0.0, 1.0],
        order=10,
        jobs=1,
        analysis=pcmb.AnalysisSettings(samples=4000),
    )
    return output, study.run(output)


def test_a_frequency_axis_output_matches_a_fine_quadrature(swept):
    _, result = swept
    mean, std = uniform_moments(lambda z: gain(z, FREQUENCIES), 0.1, 0.3)
    axis = result.axes["gain"]
    assert (axis.name, axis.unit) == ("frequency", "Hz")
    np.testing.assert_array_equal(axis.values, FREQUENCIES)
    # 1/|H| is analytic in ζ; order 10 on [0.1, 0.3] leaves ~3e-11 of the largest std.
    assert np.max(np.abs(result.mean("gain") - mean)) < 1e-9 * std.max()
    assert np.max(np.abs(result.std("gain") - std)) < 1e-9 * std.max()
    assert result.sobol_total("gain").shape == (1, FREQUENCIES.size)
    assert result.diagnostics["gain"].estimate.shape == (FREQUENCIES.size,)


def test_a_scalar_model_output_is_stored_and_read_back(tmp_path):
    output = tmp_path / "decay.h5"
    study = pcmb.Study(Decay(), {"k": pcmb.Uniform(1.0, 2.0)}, np.linspace(0, 1, 5), order=8)
    result = study.run(output)
    # energy = 1/(2k): E = ln 2 / 2, E[energy²] = 1/8.
    np.testing.assert_allclose(result.mean("energy"), [np.log(2) / 2], rtol=1e-9)
    np.testing.assert_allclose(
        result.std("energy"), [np.sqrt(1 / 8 - np.log(2) ** 2 / 4)], rtol=1e-7
    )
    loaded = pcmb.load(output)
    assert loaded.axes == {"energy": None}
    np.testing.assert_array_equal(loaded.values["energy"], result.values["energy"])
    np.testing.assert_array_equal(loaded.mean("energy"), result.mean("energy"))
    np.testing.assert_array_equal(loaded.nominal["energy"], [0.5 / 1.5])


@pytest.mark.slow
def test_an_axis_output_goes_through_store_inspect_report_and_compare(swept, tmp_path, capsys):
    xarray = pytest.importorskip("xarray")
    path, result = swept
    with xarray.open_dataset(path, group="outputs/gain", engine="h5netcdf") as ds:
        assert ds["values"].dims == ("node", "frequency")
        assert ds["sobol_total"].dims == ("input", "frequency")
    with xarray.open_dataset(path, engine="h5netcdf") as ds:
        np.testing.assert_array_equal(ds["frequency"].values, FREQUENCIES)
        assert ds["frequency"].attrs["units"] == "Hz"
    loaded = pcmb.load(path)
    assert loaded.axes["gain"].same(result.axes["gain"]) and loaded.axes["peak"] is None
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "on frequency [Hz], 40 points" in out
    # A 200-run Monte Carlo twin: compare finds the chaos within its sampling noise.
    twin = tmp_path / "twin.h5"
    pcmb.Study(
        Resonance(),
        {"zeta": pcmb.Uniform(0.1, 0.3)},
        [0.0, 1.0],
        method="montecarlo",
        samples=200,
        jobs=1,
    ).run(twin)
    assert main(["compare", str(path), str(twin)]) == 0
    out = capsys.readouterr().out
    assert "gain" in out and "peak" in out
    comparison = compare(loaded, pcmb.load(twin))
    assert comparison.differences["gain"].verdict() == "within noise"
    assert comparison.differences["peak"].verdict() == "within noise"
    pytest.importorskip("matplotlib")
    assert main(["report", str(path), "-o", str(tmp_path / "r"), "--compare", str(twin)]) == 0
    written = {p.name for p in (tmp_path / "r").iterdir()}
    assert {"gain_frequency.png", "gain_compare.png", "peak_pdf.png"} <= written


# --------------------------------------------------------------------- the command adapter


SWEEP = """\
import json, math
params = json.load(open("params.json"))["params"]
zeta = params["zeta"]
with open("out.csv", "w") as file:
    file.write("f,gain\\n")
    for k in range(40):
        f = 0.02 * (0.5 / 0.02) ** (k / 39)
        w = 2 * math.pi * f
        file.write(f"{f!r},{1 / abs(complex(1 - w * w, 2 * zeta * w)) !r}\\n")
"""


@pytest.mark.slow
def test_the_command_adapter_reads_its_axis_from_a_column(tmp_path):
    script = tmp_path / "sweep.py"
    script.write_text(SWEEP)
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    config = tmp_path / "sweep.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: ac sweep
            model:
              kind: command
              command: [{sys.executable}, sweep.py]
              files: [sweep.py]
              params: {{zeta: 0.2}}
              outputs: [gain]
              output:
                file: out.csv
                axis: {{column: f, unit: Hz, start: 0.02, stop: 0.5, points: 40, spacing: log}}
            time: {{start: 0.0, stop: 1.0, points: 2}}
            inputs:
              zeta: {{dist: uniform, low: 0.1, high: 0.3}}
            method: {{kind: collocation, order: 6}}
            execution: {{jobs: 1}}
            """
        )
    )
    output = tmp_path / "sweep.h5"
    assert main(["run", str(config), "-o", str(output), "--quiet"]) == 0
    result = pcmb.load(output)
    np.testing.assert_allclose(result.axes["gain"].values, FREQUENCIES, rtol=1e-14)
    mean, std = uniform_moments(lambda z: gain(z, FREQUENCIES), 0.1, 0.3)
    # Order 6: ~1e-6 of the largest std (see the frequency-axis test at order 10).
    assert np.max(np.abs(result.mean("gain") - mean)) < 1e-5 * std.max()
    assert np.max(np.abs(result.std("gain") - std)) < 1e-5 * std.max()


def test_a_command_file_off_its_axis_is_a_failed_run(tmp_path):
    from pcmb.adapters.command.model import CommandModel
    from pcmb.axes import OutputAxis

    script = tmp_path / "sweep.py"
    script.write_text(SWEEP)
    model = CommandModel(
        [sys.executable, "sweep.py"],
        params={"zeta": 0.2},
        outputs=["gain"],
        output_file="out.csv",
        files=["sweep.py"],
        base_dir=tmp_path,
        axis=OutputAxis("frequency", np.linspace(0.02, 0.5, 40), "Hz"),
        axis_column="f",
        keep="none",
    )
    assert model.output_axes["gain"].name == "frequency"
    with pytest.raises(ModelError, match=r"'f' column of out\.csv does not match"):
        model.run_point({"zeta": 0.2}, np.array([0.0, 1.0]))


# ----------------------------------------------------------------- Python API and journal


def test_the_python_api_takes_derived_mappings_and_names_bad_keys():
    inputs = {"k": pcmb.Uniform(1.0, 2.0)}
    times = np.linspace(0.0, 1.0, 11)
    study = pcmb.Study(
        Decay(),
        inputs,
        times,
        order=4,
        backend="inprocess",
        validation=0,
        derived={"start": {"at": "x", "time": 0.0}},
    )
    result = study.run()
    np.testing.assert_allclose(result.values["start"][:, 0], 1.0)  # exp(-k·0)
    with pytest.raises(UsageError) as caught:
        pcmb.Study(Decay(), inputs, times, derived={"p": {"max_abs": "energy"}}).check_model()
    assert [p.path for p in caught.value.problems] == ["derived.p.max_abs"]
    assert "'energy' is not a time output" in caught.value.problems[0].message
    with pytest.raises(UsageError, match=r"derived\.p\.band"):
        pcmb.Study(Decay(), inputs, times, derived={"p": {"rms": "x", "band": 1}})


def test_the_journal_keeps_outputs_of_every_width(tmp_path):
    journal = Journal(tmp_path / "j", "fp", 4, ("x", "gain", "peak"), (5, 40, 1))
    values = {"x": np.ones((2, 5)), "gain": np.arange(80.0).reshape(2, 40), "peak": [[7.0], [8.0]]}
    journal.record([1, 3], values, [Status.OK, Status.OK])
    indices, found, status = Journal(
        tmp_path / "j", "fp", 4, ("x", "gain", "peak"), (5, 40, 1)
    ).completed()
    assert indices.tolist() == [1, 3] and status.tolist() == [1, 1]
    for name, array in values.items():
        np.testing.assert_array_equal(found[name], array)
    with pytest.raises(ValueError, match=r"output 'peak' must have shape \(2, 1\)"):
        journal.record([0, 2], {**values, "peak": np.ones((2, 5))}, [1, 1])


def test_the_diagnostics_flag_the_chaos_of_a_kinked_maximum():
    from output_models import Signals

    study = pcmb.Study(
        Signals(),
        {"c": pcmb.Uniform(0.0, 1.0)},
        np.linspace(0.0, 1.0, 101),
        order=4,
        backend="inprocess",
        outputs=["line"],
        derived={"peak": {"max_abs": "line"}},
        validation=32,  # 8 (the default for 5 runs) leave a 13 % error undecided
    )
    with pytest.warns(pcmb.PcmbWarning, match=r"^peak: polynomial chaos unreliable \("):
        result = study.run()
    # max(c, 1 - c) ~ U[1/2, 1]: mean 3/4, std 1/(4 √3); order 4 misses the kink.
    found = result.diagnostics["peak"]
    assert not found.reliable and found.failing_from == 0.0
    assert found.estimate[0] > found.tolerance
    assert result.diagnostics["line"].reliable  # the time series itself is linear in c
    # Rightly: the mean itself is off by more than the tolerance (0.05 of the std).
    exact_std = 0.25 / np.sqrt(3.0)
    assert abs(result.mean("peak")[0] - 0.75) > found.tolerance * exact_std


@pytest.mark.slow
def test_a_sweep_measures_scalar_and_derived_outputs(tmp_path):
    config = tmp_path / "decay.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: decay sweep
            model: {{kind: python, entry: "{MODELS}:Decay"}}
            time: {{start: 0.0, stop: 1.0, points: 11}}
            inputs:
              k: {{dist: uniform, low: 1.0, high: 2.0}}
            method: {{kind: collocation, order: 4}}
            execution: {{jobs: 1}}
            derived: {{x_end: {{at: x, time: 1.0}}}}
            sweep:
              methods: [{{kind: collocation, order: [1, 2, 4, 6]}}]
              reference: {{kind: collocation, order: 14}}
            """
        )
    )
    folder = tmp_path / "out"
    assert main(["sweep", str(config), "-o", str(folder), "--quiet"]) == 0
    with open(folder / "sweep.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    for output in ("x", "energy", "x_end"):
        errors = [float(r["err_mean"]) for r in rows if r["output"] == output]
        assert len(errors) == 4
        # energy = 1/(2k) and exp(-k): spectral convergence in the order, to round-off.
        assert errors[2] < 1e-4 and errors[3] < 1e-6, (output, errors)
        assert errors[0] > errors[1] > errors[2] > errors[3], (output, errors)
    table = read_sweep(folder / "sweep.h5")
    on_time = table.column("output") == "x"
    assert np.isfinite(table.mean_curves[on_time]).all()
    assert np.isnan(table.mean_curves[~on_time]).all()


def test_validate_lists_the_derived_figures(tmp_path, capsys):
    assert main(["validate", str(_config(tmp_path, DERIVED))]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "derived  x2_at: at of ramp, time 0.3333" in lines
    assert "derived  x3_settle: settling_time of step, band 0.02" in lines


def test_output_axes_are_checked():
    from pcmb.axes import OutputAxis

    with pytest.raises(ValueError, match="must be an identifier other than"):
        OutputAxis("time", [1.0, 2.0])
    with pytest.raises(ValueError, match="increase strictly"):
        OutputAxis("frequency", [1.0, 1.0])
    assert OutputAxis("omega", [1.0, 2.0], "rad/s").is_frequency

    class Stray(Decay):
        output_axes: ClassVar = {"energy": None, "power": None}

    study = pcmb.Study(Stray(), {"k": pcmb.Uniform(1.0, 2.0)}, [0.0, 1.0], backend="inprocess")
    with pytest.raises(ModelDefinitionError, match="output_axes names 'power'"):
        study.run()
