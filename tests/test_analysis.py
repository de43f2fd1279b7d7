"""Quantile bands, PDFs, spectra and the nominal run, through the pipeline and the file."""

import h5py
import numpy as np
import pytest
from scipy.signal import periodogram as scipy_periodogram
from scipy.stats import gaussian_kde, norm

import pcmb
from pcmb.analysis.statistics import AnalysisSettings, analyse
from pcmb.chaos.density import kernel_density
from pcmb.errors import ConfigError, UsageError
from pcmb.references import damped_oscillator

# Low orders keep these tests fast; the diagnostics rightly call them unreliable, which is
# tested in tests/test_diagnostics*.py, not here.
pytestmark = [
    pytest.mark.filterwarnings("ignore:.*polynomial chaos unreliable:pcmb.errors.PcmbWarning"),
    pytest.mark.filterwarnings("ignore:.*chaos-undecided:pcmb.errors.PcmbWarning"),
]

# 400 points, step 0.05 (Nyquist 10 Hz); endpoint excluded so the record is periodic-ready.
TIMES = np.linspace(0.0, 20.0, 400, endpoint=False)


class Oscillator:
    """x'' + 0.2 x' + k x = 0, x(0) = x0, x'(0) = 0, in closed form (underdamped, k > 0.01)."""

    outputs = ("x", "x_squared")

    def __init__(self, k=2.0, x0=1.0):
        self.parameters = {"k": k, "x0": x0}

    def simulate(self, params, times):
        size = len(next(iter(params.values())))
        k = np.broadcast_to(params.get("k", self.parameters["k"]), size)
        x0 = np.broadcast_to(params.get("x0", self.parameters["x0"]), size)
        x = damped_oscillator(times, k, 0.2, x0)
        return {"x": x, "x_squared": x**2}


INPUTS = {"k": pcmb.Uniform(1.0, 4.0), "x0": pcmb.Uniform(0.5, 1.5)}


def _study(window="hann", **changes):
    settings = AnalysisSettings(
        psd=["x"], window=window, pdf_times=[5.0, 19.93], pdf_freqs=[0.2, 0.3], samples=20_000
    )
    arguments = {"order": {"k": 8, "x0": 2}, "jobs": 1, "analysis": settings, **changes}
    return pcmb.Study(Oscillator(), INPUTS, TIMES, **arguments)


@pytest.fixture(scope="module", params=["hann", "boxcar"])
def stored(request, tmp_path_factory):
    """A collocation study with spectra, written and read back."""
    path = tmp_path_factory.mktemp("analysis") / "oscillator.h5"
    result = _study(request.param).run(path)
    return result, pcmb.load(path), request.param


def _per_node_psd(values, window):
    _, psd = scipy_periodogram(values, fs=1 / (TIMES[1] - TIMES[0]), window=window, detrend=False)
    return psd


@pytest.mark.slow
def test_spectrum_matches_quadrature_of_per_node_psds(stored):
    result, loaded, window = stored
    per_node = _per_node_psd(result.values["x"], window)
    mean = result.weights @ per_node
    std = np.sqrt(result.weights @ (per_node - mean) ** 2)
    spectrum = loaded.analysis.outputs["x"].spectrum
    # Quadrature of the per-node PSDs is what the chaos mean (Σ|ĉ_α|²) and band equal
    # exactly on a tensor grid: only round-off separates them.
    scale = per_node.max()
    np.testing.assert_allclose(spectrum.mean, mean, atol=1e-10 * scale)
    np.testing.assert_allclose(spectrum.std, std, atol=1e-10 * scale)
    assert spectrum.window == window
    nominal = _per_node_psd(result.nominal["x"], window)
    np.testing.assert_allclose(spectrum.nominal, nominal, atol=1e-12 * nominal.max())


def test_parseval_holds_for_the_stored_mean_psd(tmp_path):
    # Parseval in this form holds for the rectangular window.
    result = _study("boxcar").run(tmp_path / "boxcar.h5")
    spectrum = pcmb.load(tmp_path / "boxcar.h5").analysis.outputs["x"].spectrum
    df = spectrum.frequency[1] - spectrum.frequency[0]
    mean_square = result.weights @ np.mean(result.values["x"] ** 2, axis=1)
    # Both sides are exact sums of the same numbers: round-off only.
    assert np.sum(spectrum.mean) * df == pytest.approx(mean_square, rel=1e-12)


def test_only_requested_spectra_are_stored(stored):
    path_result = stored[1]
    assert path_result.analysis.outputs["x_squared"].spectrum is None


def test_quantile_band_against_the_exact_law():
    """x_squared at t = 0 is x0², x0 ~ U[0.5, 1.5]: quantile q is (0.5 + q)²."""
    result = _study().run()
    bands = result.analysis.outputs["x_squared"].quantiles
    levels = np.array(result.analysis.settings.quantiles)
    exact = (0.5 + levels) ** 2
    # 20 000 surrogate draws: the empirical q-quantile has a standard error of
    # sqrt(q(1-q)/M) / f(x_q) with f = 1 / (2 sqrt(x)) here: < 0.0025; 5 of them.
    np.testing.assert_allclose(bands[:, 0], exact, atol=0.0125)
    assert np.all(bands[0] <= bands[1])


def test_pdfs_are_kdes_of_surrogate_draws(stored):
    loaded = stored[1]
    pdf = loaded.analysis.outputs["x"].pdf
    np.testing.assert_allclose(pdf.at, [5.0, 19.95])  # the nearest grid times
    for row in range(2):
        area = np.trapezoid(pdf.density[row], pdf.value[row])
        # The table spans the draws ± 3 bandwidths (or ends where they pile up, the kernel
        # mass reflected back): it holds all but ~0.3 % of the mass.
        assert area == pytest.approx(1.0, abs=5e-3)


def test_psd_pdfs_at_the_chosen_frequencies(stored):
    loaded = stored[1]
    spectrum = loaded.analysis.outputs["x"].spectrum
    np.testing.assert_allclose(spectrum.pdf.at, [0.2, 0.3])
    assert np.all(spectrum.pdf.value >= 0.0)
    for row, frequency in enumerate(spectrum.pdf.at):
        k = int(np.argmin(np.abs(spectrum.frequency - frequency)))
        value, density = spectrum.pdf.value[row], spectrum.pdf.density[row]
        # The mean of the tabulated law is the mean PSD: KDE smoothing keeps the mean (the
        # reflection at the least draw moves mass by < 1 bandwidth), 20 000 draws give ~1 %
        # noise. The table is piecewise linear: the trapezoidal rule is its exact integral.
        mean = np.trapezoid(value * density, value) / np.trapezoid(density, value)
        assert mean == pytest.approx(spectrum.mean[k], rel=0.05)


def test_sampling_spectrum_is_the_mean_and_std_of_per_run_periodograms():
    result = _study(method="lhs", samples=64, order=0).run()
    per_run = _per_node_psd(result.values["x"], "hann")
    spectrum = result.analysis.outputs["x"].spectrum
    scale = per_run.max()
    np.testing.assert_allclose(spectrum.mean, per_run.mean(axis=0), atol=1e-12 * scale)
    np.testing.assert_allclose(spectrum.std, per_run.std(axis=0, ddof=1), atol=1e-12 * scale)
    # PDFs of a sampling study come from the runs themselves.
    _, draws = pcmb.analysis.statistics.output_draws(result, "x", [5.0], result.analysis.settings)
    assert draws.shape == (64, 1)


def test_the_nominal_run_uses_config_values_else_means():
    study = pcmb.Study(
        Oscillator, INPUTS, TIMES, order=2, params={"k": 3.0}, jobs=1, nominal={"x0": 0.7}
    )
    assert study.nominal_params() == {"k": 3.0, "x0": 0.7}
    assert pcmb.Study(Oscillator(), INPUTS, TIMES).nominal_params() == {"k": 2.5, "x0": 1.0}
    result = study.run()
    exact = Oscillator().simulate({"k": np.array([3.0]), "x0": np.array([0.7])}, TIMES)
    np.testing.assert_array_equal(result.nominal["x"], exact["x"][0])
    # The oscillator is nonlinear in k: its mean response is not the nominal response.
    assert np.max(np.abs(result.mean("x") - result.nominal["x"])) > 0.1
    with pytest.raises(UsageError, match="unknown input"):
        pcmb.Study(Oscillator(), INPUTS, TIMES, nominal={"m": 1.0})


def test_a_failing_nominal_run_is_a_warning():
    @pcmb.pointwise(outputs=("x",))
    def fragile(params, times):
        if params["k"] == 2.4:  # the nominal value: no node or held-out run hits it
            raise RuntimeError("singular at the nominal point")
        return {"x": params["k"] * times}

    study = pcmb.Study(fragile, {"k": INPUTS["k"]}, TIMES, order=1, jobs=1, params={"k": 2.4})
    with pytest.warns(pcmb.PcmbWarning, match=r"nominal run failed.*\[nominal-failed\]"):
        result = study.run()
    assert result.nominal == {}
    assert any(w.code == "nominal-failed" and "singular" in w.message for w in result.warnings)


def test_file_layout_and_named_dimensions(stored, tmp_path):
    xarray = pytest.importorskip("xarray")
    result = stored[0]
    path = tmp_path / "layout.h5"
    pcmb.store.write_result(path, result, provenance={})
    with h5py.File(path) as f:
        assert f["quantile"][()].tolist() == [0.05, 0.95]
        assert f["outputs/x/quantiles"].shape == (2, TIMES.size)
        assert f["outputs/x/nominal"].shape == TIMES.shape
        assert f["outputs/x/spectrum/mean"].shape == (TIMES.size // 2 + 1,)
        assert "spectrum" not in f["outputs/x_squared"]
    with xarray.open_dataset(path, group="outputs/x", engine="h5netcdf") as ds:
        assert ds["quantiles"].dims == ("quantile", "time")
        assert ds["nominal"].dims == ("time",)
    with xarray.open_dataset(path, group="outputs/x/spectrum", engine="h5netcdf") as ds:
        assert ds["std"].dims == ("frequency",)
    with xarray.open_dataset(path, group="outputs/x/pdf", engine="h5netcdf") as ds:
        assert ds["density"].dims == ("pdf_time", "point")


def test_replace_builds_the_monte_carlo_twin():
    study = _study()
    twin = study.replace(method={"kind": "montecarlo", "samples": 32, "seed": 3})
    assert twin.method.kind == "montecarlo" and twin.node_set().size == 32
    assert twin.analysis is study.analysis and twin.nominal_params() == study.nominal_params()
    assert study.method.kind == "collocation"
    with pytest.raises(UsageError, match="unknown argument"):
        study.replace(colour="blue")
    with pytest.raises(UsageError, match="samples"):
        study.replace(method="sobol", samples=None)


def test_analyse_a_result_after_the_fact_equals_the_stored_one(stored):
    loaded = stored[1]
    again = analyse(loaded, loaded.analysis.settings)
    for name in ("x", "x_squared"):
        np.testing.assert_array_equal(
            again.outputs[name].quantiles, loaded.analysis.outputs[name].quantiles
        )
        np.testing.assert_array_equal(
            again.outputs[name].pdf.density, loaded.analysis.outputs[name].pdf.density
        )


def test_kernel_density_matches_scipy_and_the_gaussian_closed_form():
    rng = np.random.default_rng(5)
    samples = rng.normal(size=100_000)
    value, density, h = kernel_density(samples)
    # Linear binning at >= 60 cells per bandwidth: error O((1/60)²) of the peak.
    reference = gaussian_kde(samples, bw_method=h / samples.std(ddof=1))(value)
    np.testing.assert_allclose(density, reference, atol=1e-3 * reference.max())
    # In expectation a Gaussian KDE of N(0, 1) data is N(0, 1 + h²); 1e5 draws: ~1 % noise.
    np.testing.assert_allclose(density, norm(0, np.sqrt(1 + h**2)).pdf(value), atol=0.01)
    # Draws piled up against their least, ~0: the kernel mass below it is reflected back.
    positive = rng.exponential(size=50_000)
    value, density, h = kernel_density(positive, nonnegative=True)
    kde = gaussian_kde(positive, bw_method=h / positive.std(ddof=1))
    reference = kde(value) + kde(2.0 * positive.min() - value)
    assert value[0] == positive.min()
    np.testing.assert_allclose(density, reference, atol=1e-3 * reference.max())
    # A point mass has no density.
    value, density, h = kernel_density(np.full(10, 3.0))
    assert np.all(value == 3.0) and np.all(np.isnan(density)) and np.isnan(h)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"quantiles": (0.5, 1.5)}, "analysis.quantiles"),
        ({"quantiles": (0.5, 0.5)}, "twice"),
        ({"samples": 10}, "analysis.samples"),
        ({"window": "no-such-window"}, "analysis.window"),
        ({"pdf_freqs": (-1.0,)}, "analysis.pdf_freqs"),
    ],
)
def test_impossible_settings_are_rejected(settings, message):
    with pytest.raises(ConfigError, match=message):
        AnalysisSettings(**settings)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"psd": ("v",)}, r"analysis.psd\[0\]: 'v' is not an output"),
        ({"pdf_times": (5.0, 21.0)}, r"analysis.pdf_times\[1\]: 21.0 is outside"),
        ({"pdf_freqs": (10.5,)}, r"analysis.pdf_freqs\[0\].*Nyquist frequency 10 Hz"),
        ({"units": {"v": "m"}}, "analysis.units.v"),
    ],
)
def test_settings_that_do_not_fit_the_study_fail_before_running(settings, message):
    calls = []

    @pcmb.pointwise(outputs=("x",))
    def model(params, times):
        calls.append(1)
        return {"x": params["k"] * times}

    study = pcmb.Study(
        model, {"k": INPUTS["k"]}, TIMES, order=1, jobs=1, analysis=AnalysisSettings(**settings)
    )
    with pytest.raises(ConfigError, match=message):
        study.run()
    assert calls == []


def test_a_spectrum_needs_a_uniform_grid():
    uneven = np.array([0.0, 0.1, 0.3, 0.6])
    with pytest.raises(ConfigError, match="uniform"):
        AnalysisSettings(psd=("x",)).check(uneven, ("x",))
    # By default spectra are simply left out on such a grid.
    assert AnalysisSettings().spectrum_outputs(uneven, ("x",)) == []


@pytest.mark.parametrize("n", [1, 2, 3, 20_000])
@pytest.mark.parametrize("levels", [(0.05, 0.95), (0.5,), (1e-300, 1 - 1e-16)])
def test_column_quantiles_are_numpys(n, levels):
    from pcmb.analysis.statistics import _column_quantiles

    values = np.random.default_rng(n).normal(size=(n, 7))
    values[:, 3] = 0.0  # a constant column, where numpy's sign of zero is its own choice
    values[: n // 2, 5] = np.nan
    expected = np.quantile(values, levels, axis=0)
    found = _column_quantiles(values, levels)
    np.testing.assert_array_equal(found, expected)
    finite = np.isfinite(expected)
    assert found[finite].tobytes() == expected[finite].tobytes()
