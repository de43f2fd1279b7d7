"""A regression design's final fit: after the verdict, its expansions are refitted over the
design's runs and the held-out runs that succeeded (``docs/methods.md``, "The final fit")."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from test_sparse_regression import _settings

import pcmb
from pcmb.analysis.diagnostics import held_out_draws
from pcmb.chaos.basis import PolynomialBasis
from pcmb.chaos.nodes import join_nodes
from pcmb.chaos.sparse_regression import fit_sparse
from pcmb.cli import _inspect, _runs_made
from pcmb.designs.regression import SparseRegression, loo_statistics_error
from pcmb.errors import ModelRunError

TIMES = np.array([0.0, 0.5, 1.0])
#: One normal input (its held-out draws widened and weighted back) and one uniform.
MIXED = {"a": pcmb.Normal(0.0, 1.0), "b": pcmb.Uniform(-1.0, 1.0)}


def _lognormal(params, times):
    """y = exp(a/2 + 0.3 b) (1 + t), and p = (a + b²) (1 + t), a polynomial of the bases'."""
    a, b = params["a"][:, None], params["b"][:, None]
    return {"y": np.exp(0.5 * a + 0.3 * b) * (1.0 + times), "p": (a + b * b) * (1.0 + times)}


lognormal_ramp = pcmb.batched(outputs=("y", "p"))(_lognormal)
#: A tolerance no fit of y meets: the check vouches for p alone.
STRICT = {"tolerance": 1e-6}


def _study(method: dict, **changes) -> pcmb.Study:
    settings = {"backend": "inprocess", "method": method, "diagnostics": STRICT, **changes}
    return pcmb.Study(lognormal_ramp, MIXED, TIMES, **settings)


def _run(study: pcmb.Study, *args, **kwargs) -> pcmb.StudyResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        return study.run(*args, **kwargs)


def _all_runs(result: pcmb.StudyResult, name: str):
    """(germ, values, row weights) of the design's and the held-out runs that succeeded."""
    held_out, ok = result.held_out, result.status == pcmb.Status.OK
    germ = np.vstack([result.germ[ok], held_out.germ[held_out.ok]])
    values = np.vstack([result.values[name][ok], held_out.values[name][held_out.ok]])
    weights = np.concatenate([np.ones(ok.sum()), held_out.weights[held_out.ok]])
    return germ, values, weights


def test_least_squares_is_refitted_over_the_held_out_runs_weighted_back():
    """``selection: none``: the stored coefficients are the weighted least squares over the
    design's 40 runs and the 16 held-out runs, rows scaled by √w (numpy's lstsq)."""
    method = {"kind": "regression", "samples": 40, "order": 3, "selection": "none"}
    result = _run(_study({**method, "basis": "total", "validation": 16}))
    assert result.held_out.ok.sum() == 16 and np.ptp(result.held_out.weights) > 0.1
    expansion = result.expansions["y"]
    germ, values, weights = _all_runs(result, "y")
    matrix = PolynomialBasis(tuple(d.family for d in MIXED.values()), expansion.multi_index)
    root = np.sqrt(weights)[:, None]
    expected, *_ = np.linalg.lstsq(matrix.evaluate(germ) * root, values * root, rcond=None)
    np.testing.assert_allclose(expansion.coefficients, expected, rtol=0, atol=1e-10)
    assert result.regression["y"].held_out_fitted == 16 and result.design.samples == 40


def test_lars_reselects_its_terms_over_every_run():
    """LARS runs its path again over all runs (weighted): the stored terms and LOO errors are
    those of ``fit_sparse`` over them, not the design's 24 runs' selection."""
    method = {"kind": "regression", "samples": 24, "order": 5, "validation": 24}
    result = _run(_study(method))
    germ, values, weights = _all_runs(result, "y")
    design = result.expansions["y"]
    candidates = SparseRegression(MIXED, _settings(orders=(5, 5), q=1.0, samples=32)).candidates
    every = fit_sparse(candidates, germ, values, "lars", weights)
    own = fit_sparse(candidates, result.germ, result.values["y"], "lars")
    assert not np.array_equal(every.multi_index, own.multi_index)  # the runs change the terms
    np.testing.assert_array_equal(result.regression["y"].selected, every.multi_index)
    np.testing.assert_allclose(result.regression["y"].loo, every.loo_error, rtol=1e-9)
    np.testing.assert_allclose(design.mean(), every.coefficients[0], rtol=1e-12)


def test_the_final_fit_is_closer_to_the_closed_form_than_the_design_s_alone():
    """Least squares (``selection: none``, total order 2) of exp(x0 + x1/2), x ~ U[0, 1]², on
    24 random points and 24 held-out draws, 200 seeds: the error of the mean and std is the
    aliasing of the terms beyond order 2, whose variance falls as 1/N, so twice the runs
    should cut its RMS by √2 (0.71); it must cut it below 0.85 (the RMS over 200 seeds is
    known to about 5 %)."""
    inputs = {"x0": pcmb.Uniform(0.0, 1.0), "x1": pcmb.Uniform(0.0, 1.0)}
    mean = np.expm1(1.0) * 2.0 * np.expm1(0.5)
    sigma = np.sqrt(np.expm1(2.0) / 2.0 * np.expm1(1.0) - mean**2)
    errors = {"design": [], "final": []}
    for seed in range(200):
        changes = dict(orders=(2, 2), basis="total", q=1.0, selection="none", sampling="random")
        design = SparseRegression(inputs, _settings(samples=24, seed=seed, **changes))
        nodes = design.nodes()
        draws, weights = held_out_draws(tuple(inputs.values()), 24, seed + 7919)
        every = join_nodes(nodes, draws)
        ok = np.ones(every.size, dtype=bool)
        values = {"y": np.exp(every.params @ [1.0, 0.5])}
        own = design.recover(nodes, {"y": values["y"][: nodes.size]}, ok[: nodes.size])
        final = design.refit(every, values, ok, np.concatenate([ok[: nodes.size], weights]))
        for name, found in (("design", own), ("final", final)):
            expansion = found.expansions["y"]
            errors[name].append(max(abs(expansion.mean() - mean), abs(expansion.std() - sigma)))
    rms = {name: float(np.sqrt(np.mean(np.square(e)))) / sigma for name, e in errors.items()}
    assert rms["final"] < 0.85 * rms["design"], rms


class _SwitchedLognormal:
    """The lognormal ramp, raising at held-out run parameters ``bad`` while ``switch`` exists."""

    outputs = ("y",)

    def __init__(self, bad: list[float], switch: str) -> None:
        self.bad, self.switch = np.asarray(bad), switch

    def simulate(self, params, times):
        if np.isin(params["a"], self.bad).any() and Path(self.switch).exists():
            raise ValueError("switched off")
        return _lognormal(params, times)


def test_a_resumed_study_makes_the_same_final_fit(tmp_path):
    """Stopped by a failed held-out run (``on_failure: abort``), resumed from its journal: the
    final fit over the design's and the held-out runs equals an uninterrupted study's."""
    method = {"kind": "regression", "samples": 32, "order": 4, "validation": 12}
    settings = {"backend": "inprocess", "method": method, "on_failure": "abort"}
    settings["diagnostics"] = STRICT
    switch = tmp_path / "switch"
    params = {"bad": [], "switch": str(switch)}
    whole = _run(pcmb.Study(_SwitchedLognormal, MIXED, TIMES, params=params, **settings))
    # A run in the middle of a's range (a failed tail draw would not stop the study).
    params["bad"] = [
        float(whole.held_out.params[np.argmin(np.abs(whole.held_out.params[:, 0])), 0])
    ]
    switch.touch()
    study = pcmb.Study(_SwitchedLognormal, MIXED, TIMES, params=params, **settings)
    with pytest.raises(ModelRunError, match="held-out run"):
        _run(study, tmp_path / "r.h5")
    switch.unlink()
    resumed = _run(study, tmp_path / "r.h5", resume=True)
    assert resumed.regression["y"].held_out_fitted == whole.regression["y"].held_out_fitted == 12
    np.testing.assert_array_equal(
        resumed.expansions["y"].coefficients, whole.expansions["y"].coefficients
    )
    np.testing.assert_array_equal(resumed.regression["y"].loo, whole.regression["y"].loo)
    back = pcmb.load(tmp_path / "r.h5")
    np.testing.assert_array_equal(
        back.expansions["y"].coefficients, whole.expansions["y"].coefficients
    )
    assert back.regression["y"].held_out_fitted == 12


def test_an_output_the_check_vouches_for_keeps_the_fit_it_checked(monkeypatch):
    """p is a polynomial of the candidates: the check vouches for its design-only fit, which
    stays (bit for bit the design's ``recover``) and is not fitted again; y is refitted."""
    refitted = []
    refit = SparseRegression.refit

    def spied(self, nodes, values, *args, **kwargs):
        refitted.extend(values)
        return refit(self, nodes, values, *args, **kwargs)

    monkeypatch.setattr(SparseRegression, "refit", spied)
    method = {"kind": "regression", "samples": 32, "order": 3, "validation": 10}
    result = _run(_study(method))
    assert refitted == ["y"]
    assert result.diagnostics["p"].vouched and not result.diagnostics["y"].vouched
    assert result.regression["p"].held_out_fitted == 0
    assert result.regression["y"].held_out_fitted == 10
    design = SparseRegression(MIXED, _settings(orders=(3, 3), q=1.0, samples=32))
    nodes = design.nodes()
    own = design.recover(nodes, result.values, np.ones(nodes.size, dtype=bool))
    p = own.expansions["p"]
    kept = result.expansions["p"]
    np.testing.assert_array_equal(own.regression["p"].selected, result.regression["p"].selected)
    assert p.coefficients[np.any(p.coefficients != 0, axis=1)].tobytes() == (
        kept.coefficients[np.any(kept.coefficients != 0, axis=1)].tobytes()
    )


def test_inspect_and_the_report_say_which_runs_the_fit_used(tmp_path):
    method = {"kind": "regression", "samples": 32, "order": 3, "validation": 10}
    _run(_study(method), tmp_path / "r.h5")
    result = pcmb.load(tmp_path / "r.h5")
    assert result.regression["y"].held_out_fitted == 10
    assert "the fit of y used 32 design + 10 held-out runs" in _runs_made(result)
    from pcmb.analysis.report import _runs_text

    assert "the fit of y used 32 design + 10 held-out runs" in _runs_text(result)
    (line,) = [text for label, text in result.report.summary(result) if text.startswith("y:")]
    assert "(final fit, with 10 held-out runs)" in line
    shown = _inspect(str(tmp_path / "r.h5")).splitlines()
    (checked,) = [line for line in shown if line.startswith("checked  y:")]
    assert checked.endswith("; of the fit before the final fit)")
    (checked,) = [line for line in shown if line.startswith("checked  p:")]
    assert "final fit" not in checked
    from pcmb.analysis.report import _Labels, _verdict

    labels = _Labels(pcmb.AnalysisSettings(), float(TIMES[-1]))
    assert "; of the fit before the final fit)" in _verdict(result, "y", labels)[1]
    assert "final fit" not in _verdict(result, "p", labels)[1]
    vouched = _run(_study(method, diagnostics={}))
    assert not vouched.fitted_runs and "the fit" not in _runs_made(vouched)


def test_the_bands_and_pdfs_are_drawn_from_the_final_fit():
    settings = pcmb.AnalysisSettings(psd=(), quantiles=(0.1, 0.9), samples=4000)
    method = {"kind": "regression", "samples": 32, "order": 3, "validation": 10}
    result = _run(_study(method, analysis=settings))
    assert result.regression["y"].held_out_fitted == 10
    again = pcmb.analyse(result, settings)
    for name in ("y", "p"):
        drawn, expected = result.analysis.outputs[name], again.outputs[name]
        np.testing.assert_array_equal(drawn.quantiles, expected.quantiles)


def test_a_file_written_before_the_final_fit_reads_as_fitted_to_the_design_alone(tmp_path):
    import h5py

    method = {"kind": "regression", "samples": 32, "order": 3, "validation": 10}
    _run(_study(method), tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5", "r+") as file:
        for name in ("y", "p"):
            del file[f"outputs/{name}"].attrs["held_out_fitted"]
    back = pcmb.load(tmp_path / "r.h5")
    assert back.regression["y"].held_out_fitted == 0 and not back.fitted_runs


def test_the_budget_record_names_the_output_that_missed_the_tolerance():
    """``regression-budget`` is about the output whose estimate missed ``method.tolerance``: y,
    not p (an exact polynomial of the candidates, its estimate at round-off)."""
    method = {"kind": "regression", "samples": 32, "order": 3, "tolerance": 1e-3}
    result = _run(_study({**method, "max_samples": 64, "validation": 0}))
    records = [w for w in result.warnings if w.code == "regression-budget"]
    assert [w.output for w in records] == ["y"]


def test_the_budget_record_is_the_final_fit_s_own():
    """A refitted output's ``regression-budget`` is judged on its final fit: at a tolerance
    between y's estimate over the design's 64 runs (its budget) and over those and 32 held-out
    runs, the design's record does not stay; below both, its figure is the final fit's."""
    method = {"kind": "regression", "samples": 32, "order": 3, "max_samples": 64}
    probe = _run(_study({**method, "tolerance": 1e-9, "validation": 32}))
    design = SparseRegression(MIXED, _settings(orders=(3, 3), q=1.0, samples=64))
    nodes = design.nodes()
    ok = probe.status == pcmb.Status.OK
    own = design.recover(nodes, {"y": probe.values["y"]}, ok)
    germ, values, weights = _all_runs(probe, "y")
    every = pcmb.chaos.nodes.NodeSet(nodes.distributions, germ, germ)
    final = design.refit(every, {"y": values}, np.ones(len(weights), dtype=bool), weights)
    effective = np.sum(weights) ** 2 / np.sum(weights**2)  # the runs the rows count as
    before, after = _estimate(own, "y", nodes.size), _estimate(final, "y", effective)
    assert after < before / 1.5  # the premise: the held-out runs lower the estimate
    between = _run(_study({**method, "tolerance": np.sqrt(before * after), "validation": 32}))
    assert not [w for w in between.warnings if w.code == "regression-budget"]
    (record,) = [w for w in probe.warnings if w.code == "regression-budget"]
    assert f"{after:.3g} > 1e-09" in record.message


def _estimate(found, name: str, runs: float) -> float:
    """The estimated error of the mean and std of a recovery's fit of ``name`` to ``runs``."""
    fit = found.report.regression[name]
    return loo_statistics_error(fit.loo, found.expansions[name].std(), runs)
