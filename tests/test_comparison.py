"""Differences of mean and std between results, against closed forms; ``pcmb compare``."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import binom, norm

import pcmb
from pcmb.analysis.comparison import DRAWS, LEVEL, compare, method_label
from pcmb.cli import main
from pcmb.errors import UsageError
from pcmb.store import write_result

TIMES = np.linspace(0.0, 2.0, 21)


@pcmb.pointwise(outputs=("y", "z"))
def ramp(params, times):
    """y = a t, z = a: with a ~ U[lo, hi], mean (lo + hi) t / 2, std (hi - lo) t / √12."""
    return {"y": params["a"] * times, "z": params["a"] + 0.0 * times}


def _run(high, **options):
    inputs = {"a": pcmb.Uniform(1.0, high)}
    return pcmb.Study(ramp, inputs, TIMES, order=1, params={"a": 2.0}, jobs=1, **options).run()


@pytest.mark.slow
def test_differences_of_two_chaos_results_match_the_closed_form():
    reference, other = _run(3.0), _run(4.0)
    found = compare(reference, other).differences["y"]
    # Order 1 is exact for a linear output, so these are the closed forms to round-off.
    mean_gap = 0.5 * TIMES
    std_gap = (3.0 - 2.0) / np.sqrt(12.0) * TIMES
    assert found.mean_max == pytest.approx(mean_gap.max(), rel=1e-12)
    assert found.mean_rms == pytest.approx(np.sqrt(np.mean(mean_gap**2)), rel=1e-12)
    assert found.std_max == pytest.approx(std_gap.max(), rel=1e-12)
    assert found.std_rms == pytest.approx(np.sqrt(np.mean(std_gap**2)), rel=1e-12)
    assert found.scale == pytest.approx(2.0 * 2.0 / np.sqrt(12.0), rel=1e-12)
    assert found.mean_relative == pytest.approx(found.mean_max / found.scale)
    assert found.verdict() == "beyond tolerance"  # 0.5 t over 1.155: 43 % at t = 1


@pytest.mark.slow
def test_chaos_against_chaos_is_judged_by_the_stored_tolerance():
    # Order 1 is exact for y = a t: the means differ by (high - 3) t / 2, the stds by
    # (high - 3) t / √12, over a scale of 4 / √12 = 1.155. At high = 3.1 the mean gap is
    # 0.0433 t of the scale: past the default tolerance 0.05 from t = 1.155 on, so at the
    # grid time 1.2; at high = 3.05 it stays below 0.0433 up to t = 2.
    reference = _run(3.0)
    found = compare(reference, _run(3.1)).differences["y"]
    assert found.tolerance == 0.05 and np.isnan(found.critical) and found.runs == ()
    assert found.departure == pytest.approx(1.2) and found.verdict() == "beyond tolerance"
    assert "departs at t = 1.2 (difference above the chaos tolerance 0.05" in (
        compare(reference, _run(3.1)).table()
    )
    assert compare(reference, _run(3.05)).differences["y"].verdict() == "within tolerance"
    # The tolerance stored in the files: 0.1 accepts the 0.087 of high = 3.1 ...
    loose = compare(_run(3.0, diagnostics_tolerance=0.1), _run(3.1, diagnostics_tolerance=0.1))
    assert loose.differences["y"].tolerance == 0.1
    assert loose.differences["y"].verdict() == "within tolerance"
    # ... and two files' tolerances: the stricter one counts.
    strict = compare(_run(3.0, diagnostics_tolerance=0.1), _run(3.1)).differences["y"]
    assert strict.tolerance == 0.05 and strict.verdict() == "beyond tolerance"


@pytest.mark.slow
def test_monte_carlo_noise_and_the_verdict():
    chaos = _run(3.0)
    same = _run(3.0, method="montecarlo", samples=4000, seed=2)
    found = compare(chaos, same).differences["y"]
    runs = 4000
    std = same.std("y")
    assert found.mean_noise == pytest.approx(np.max(std / np.sqrt(runs)), rel=1e-12)
    # y = a t with a uniform: kurtosis 9/5, so the std's standard error is σ √(0.8 / 4N).
    assert found.std_noise == pytest.approx(np.max(std) * np.sqrt(0.2 / runs), rel=0.05)
    # Same law: the worst time is within the family-wise critical value (fixed seed).
    assert found.mean_z <= found.critical and found.verdict() == "within noise"
    # A law whose mean differs by 5 % of the band is many standard errors away.
    shifted = _run(3.1, method="montecarlo", samples=4000, seed=2)
    assert compare(chaos, shifted).differences["y"].verdict() == "beyond noise"


def test_departure_is_when_the_difference_leaves_the_noise():
    @pcmb.pointwise(outputs=("y",))
    def late(params, times):
        return {"y": params["a"] * np.maximum(times - 1.0, 0.0)}

    def run(high, **options):
        inputs = {"a": pcmb.Uniform(1.0, high)}
        return pcmb.Study(late, inputs, TIMES, order=1, params={"a": 2}, **options).run()

    chaos = run(3.0)
    # Two chaos results: a mean gap of 0.2 (t - 1) against a scale of 2 / √12 = 0.577 passes
    # the tolerance 0.05 after t - 1 = 0.144, at the grid time 1.2.
    assert compare(chaos, run(3.4)).differences["y"].departure == pytest.approx(TIMES[12])
    found = compare(chaos, run(3.4, method="montecarlo", samples=4000, seed=2)).differences["y"]
    # Identical (zero) up to t = 1; after it the means differ by 0.2 (t - 1) against a
    # standard error of about 0.69 (t - 1) / √4000 = 0.011 (t - 1): ~18 standard errors at
    # every later time, so the first grid time after 1 is where they part.
    assert found.departure == pytest.approx(TIMES[11])
    assert found.verdict() == "beyond noise"


def test_the_critical_value_of_fully_correlated_times():
    """y = a t: every time carries the same standardised runs, so the 2T z-scores reduce to
    two, of the mean and of the std; for a symmetric law these are uncorrelated, hence
    independent normals, and P(max(|Z1|, |Z2|) <= c) = (2Φ(c) - 1)² = 1 - LEVEL."""
    found = compare(_run(3.0), _run(3.0, method="montecarlo", samples=4000, seed=2))
    exact = norm.ppf((1.0 + np.sqrt(1.0 - LEVEL)) / 2.0)  # 2.236
    # Standard error of a quantile of DRAWS draws: √(p (1 - p) / DRAWS) / density of the
    # maximum at c, 4 (2Φ(c) - 1) φ(c) = 0.127: 0.038; four of them.
    density = 4.0 * (2.0 * norm.cdf(exact) - 1.0) * norm.pdf(exact)
    margin = 4.0 * np.sqrt(LEVEL * (1.0 - LEVEL) / DRAWS) / density
    assert found.differences["y"].critical == pytest.approx(exact, abs=margin)


WAVE_TIMES = np.linspace(0.0, 2.0, 51)
RUNS = 400


def _wave(a):
    """(N, T) exp(a) cos(8π a t): the times decorrelate within 1/(8σ_a) = 0.25, so the grid
    holds many nearly independent tests, and the law is skewed (lognormal amplitude)."""
    return {"y": np.exp(a)[:, None] * np.cos(8.0 * np.pi * a[:, None] * WAVE_TIMES)}


@pytest.fixture(scope="module")
def wave_template():
    """A Monte Carlo result of RUNS runs whose values the tests replace by their own draws."""

    @pcmb.batched(outputs=("y",))
    def wave(params, times):
        return _wave(params["a"])

    inputs = {"a": pcmb.Normal(0.0, 0.5)}
    study = pcmb.Study(wave, inputs, WAVE_TIMES, method="montecarlo", samples=RUNS, jobs=1)
    return study.run()


def _twin(template, generator, shift=0.0):
    """A synthetic Monte Carlo result: RUNS fresh draws of a, the output moved by ``shift``."""
    values = _wave(generator.normal(0.0, 0.5, RUNS))["y"] + shift
    return dataclasses.replace(template, values={"y": values})


@pytest.mark.slow  # 200 comparisons, about 15 s
def test_two_monte_carlo_runs_of_one_law_are_within_noise_at_the_stated_level(wave_template):
    seeds = 200
    alarms = 0
    for seed in range(seeds):
        generator = np.random.default_rng(seed)
        found = compare(_twin(wave_template, generator), _twin(wave_template, generator))
        alarms += found.differences["y"].verdict() == "beyond noise"
    # The level is LEVEL up to the normal approximation; the count is binomial(seeds, LEVEL),
    # whose 99.9 % range is 2..21 of 200.
    low, high = binom.ppf([0.0005, 0.9995], seeds, LEVEL)
    assert low <= alarms <= high, alarms


def test_a_known_shift_of_the_mean_is_beyond_noise_from_where_it_starts(wave_template):
    generator = np.random.default_rng(7)
    reference = _twin(wave_template, generator)
    # From t = 1 on, the mean moves by 8 standard errors of the difference (the output's
    # std is about 1.3 at most, the difference's standard error √2 σ / √RUNS <= 0.09): past
    # any critical value of 51 x 2 tests; before t = 1 the two are the same law.
    noise = np.sqrt(2.0 / RUNS) * reference.std("y")
    shift = np.where(WAVE_TIMES >= 1.0, 8.0 * noise, 0.0)
    found = compare(reference, _twin(wave_template, generator, shift)).differences["y"]
    assert found.critical < 4.5 and found.runs == (RUNS, RUNS)
    assert found.departure == pytest.approx(1.0) and found.verdict() == "beyond noise"
    assert found.resolution == pytest.approx(
        found.critical * max(found.mean_noise, found.std_noise) / found.scale
    )


def test_round_off_at_a_fixed_state_is_not_a_difference():
    @pcmb.pointwise(outputs=("y",))
    def offset(params, times):
        return {"y": 0.1 + params["a"] * times}

    study = pcmb.Study(offset, {"a": pcmb.Uniform(1.0, 3.0)}, TIMES, order=1, params={"a": 2})
    chaos, same = study.run(), study.replace(method="sobol", samples=1024).run()
    # At t = 0 every run gives 0.1: the sample mean and std are off by ~1e-15 of round-off,
    # which is many of its own (round-off sized) standard errors, yet no difference.
    assert abs(same.mean("y")[0] - chaos.mean("y")[0]) > 0.0
    found = compare(chaos, same).differences["y"]
    assert found.mean_z < found.critical and found.verdict() == "within noise"


def test_results_that_cannot_be_compared():
    other_grid = pcmb.Study(
        ramp, {"a": pcmb.Uniform(1.0, 3.0)}, TIMES[:-1], order=1, params={"a": 2.0}, jobs=1
    ).run()
    with pytest.raises(UsageError, match="different time grids"):
        compare(_run(3.0), other_grid)

    @pcmb.pointwise(outputs=("w",))
    def other_model(params, times):
        return {"w": params["a"] * times}

    unrelated = pcmb.Study(
        other_model, {"a": pcmb.Uniform(1.0, 3.0)}, TIMES, order=1, params={"a": 2.0}, jobs=1
    ).run()
    with pytest.raises(UsageError, match="share no output"):
        compare(_run(3.0), unrelated)


def test_method_labels():
    assert method_label(_run(3.0)) == "chaos order 1 (2 runs)"
    assert method_label(_run(3.0, method="lhs", samples=50)) == "lhs (50 runs)"

    @pcmb.pointwise(outputs=("y",))
    def plane(params, times):
        return {"y": params["a"] + params["b"] * times}

    inputs = {"a": pcmb.Uniform(0.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)}
    study = pcmb.Study(plane, inputs, TIMES, order={"a": 1, "b": 2}, params={"a": 0, "b": 0})
    assert method_label(study.run()) == "chaos orders 1x2 (6 runs)"
    total = study.replace(order=2, basis="total").run()
    assert method_label(total) == "chaos total order 2 (9 runs)"
    with pytest.warns(pcmb.PcmbWarning, match="least-squares chaos"):
        fitted = study.replace(method="sobol", samples=32, fit="regression", order=1).run()
    assert method_label(fitted).startswith("sobol + chaos fit, total order 1 (32 runs)")


@pytest.mark.slow
def test_pcmb_compare_prints_the_table_and_writes_figures(tmp_path, capsys):
    paths = []
    for name, result in [("chaos", _run(3.0)), ("wide", _run(4.0))]:
        paths.append(write_result(tmp_path / f"{name}.h5", result, provenance={}))
    figures = tmp_path / "figures"
    assert main(["compare", str(paths[0]), str(paths[1]), "-o", str(figures)]) == 0
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert lines[0] == f"reference  {paths[0]}: chaos order 1 (2 runs)"
    row = next(line for line in lines if line.startswith("y "))
    assert float(row.split()[1]) == pytest.approx(1.0, rel=1e-3)  # max |Δmean| = 0.5 · 2
    assert sorted(p.name for p in figures.iterdir()) == ["y_compare.png", "z_compare.png"]
    assert "wrote 2 figures" in captured.err


def test_pcmb_compare_states_the_resolution_of_the_monte_carlo_twin(tmp_path, capsys):
    chaos, twin = _run(3.0), _run(3.2, method="montecarlo", samples=1000, seed=2)
    found = compare(chaos, twin).differences["y"]
    paths = [
        write_result(tmp_path / f"{name}.h5", result, provenance={})
        for name, result in (("chaos", chaos), ("twin", twin))
    ]
    assert main(["compare", *map(str, paths)]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("y: "))
    assert note.startswith(f"y: departs at t = {found.departure:.4g} (resolution of a Monte ")
    assert f"twin of 1000 runs: differences up to {found.resolution:.2g} of the" in note


def test_pcmb_compare_usage_errors(tmp_path, capsys):
    path = write_result(tmp_path / "one.h5", _run(3.0), provenance={})
    assert main(["compare", str(path)]) == 2  # needs two files
    assert main(["compare", str(path), str(tmp_path / "missing.h5")]) == 2
    assert "missing.h5: no such file" in capsys.readouterr().err
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    assert main(["compare", str(path), str(tmp_path / "junk.h5")]) == 2


def test_comparisons_of_huge_outputs_do_not_overflow():
    """The same laws at 1 and at 1e200: the same verdicts, every figure scaled by 1e200."""

    def studies(magnitude):
        @pcmb.pointwise(outputs=("y",))
        def scaled(params, times):
            return {"y": magnitude * (1.0 + params["a"] * times)}

        study = pcmb.Study(scaled, {"a": pcmb.Uniform(1.0, 3.0)}, TIMES, order=1, params={"a": 2})
        return study.run(), study.replace(method="montecarlo", samples=4000, seed=2).run()

    plain = compare(*studies(1.0)).differences["y"]
    with pytest.warns(pcmb.PcmbWarning, match=r"\[square-overflow\]"):
        huge = compare(*studies(1e200)).differences["y"]
    assert huge.not_finite == 0 and huge.verdict() == plain.verdict() == "within noise"
    for field in ("mean_max", "mean_rms", "std_max", "std_rms", "scale", "mean_noise"):
        assert getattr(huge, field) == pytest.approx(1e200 * getattr(plain, field), rel=1e-9)
    assert huge.std_noise == pytest.approx(1e200 * plain.std_noise, rel=1e-9)
    assert huge.mean_z == pytest.approx(plain.mean_z, rel=1e-6)
