"""Differences of mean and std between results, against closed forms; ``pcmb compare``."""

import numpy as np
import pytest

import pcmb
from pcmb.analysis.comparison import NOISE_FACTOR, compare, method_label
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
    assert found.verdict() == "no sampling noise"


def test_monte_carlo_noise_and_the_verdict():
    chaos = _run(3.0)
    same = _run(3.0, method="montecarlo", samples=4000, seed=2)
    found = compare(chaos, same).differences["y"]
    runs = 4000
    std = same.std("y")
    assert found.mean_noise == pytest.approx(np.max(std / np.sqrt(runs)), rel=1e-12)
    # y = a t with a uniform: kurtosis 9/5, so the std's standard error is σ √(0.8 / 4N).
    assert found.std_noise == pytest.approx(np.max(std) * np.sqrt(0.2 / runs), rel=0.05)
    # Same law: the worst time is a few standard errors off at most (fixed seed).
    assert found.mean_z <= NOISE_FACTOR and found.verdict() == "within noise"
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
    assert np.isnan(compare(chaos, run(3.4)).differences["y"].departure)  # no noise: no verdict
    found = compare(chaos, run(3.4, method="montecarlo", samples=4000, seed=2)).differences["y"]
    # Identical (zero) up to t = 1; after it the means differ by 0.2 (t - 1) against a
    # standard error of about 0.69 (t - 1) / √4000 = 0.011 (t - 1): ~18 standard errors at
    # every later time, so the first grid time after 1 is where they part.
    assert found.departure == pytest.approx(TIMES[11])
    assert found.verdict() == "beyond noise"


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
    assert found.mean_z < NOISE_FACTOR and found.verdict() == "within noise"


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
