"""The design reports' records in the result file: the paths, scales and values of old, read
back whole (one definition, :class:`pcmb.result.RecordReport`, writes and reads them all)."""

import dataclasses

import h5py
import numpy as np
import pytest

import pcmb
from pcmb import store
from pcmb.designs import AdaptiveReport, RefinementReport, RegressionReport
from pcmb.result import AdaptiveFit, Refinement, RegressionFit

INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Uniform(-1.0, 1.0)}
TIMES = np.linspace(0.0, 1.0, 4)


@pcmb.pointwise(outputs=("y", "w"))
def model(params, times):
    return {"y": params["a"] * times + params["b"] ** 3, "w": np.cos(params["a"] * times)}


@pytest.fixture(scope="module")
def result():
    return pcmb.Study(model, INPUTS, TIMES, order=3, params={"a": 2.0, "b": 0.0}, jobs=1).run()


ADAPTIVE = AdaptiveFit(
    np.array([[0, 0], [1, 0], [0, 1]]),
    np.array([np.nan, 0.5, 0.25]),
    np.array([False, True, True]),
    np.array([[1.0, 0.5], [5.0, 0.1]]),
    np.array([2, 2]),
)
REFINEMENT = Refinement(np.array([[1, 1], [2, 3]]), np.array([4, 16]), np.array([0.3, 0.01]))
FITS = {
    "y": RegressionFit(np.array([[0, 0], [1, 0]]), np.array([0.1, np.nan, 0.2, 0.3]), 12.5),
    "w": RegressionFit(np.array([[0, 1]]), np.array([0.4, 0.5, 0.6, 0.7]), 3.0),
}
# path -> (value, scale of each axis): the layout the file had before the shared definition
CASES = {
    "adaptive": (
        AdaptiveReport(ADAPTIVE),
        {
            "adaptive/index_set": (ADAPTIVE.index_set, [None, "/input"]),
            "adaptive/indicators": (ADAPTIVE.indicators, [None]),
            "adaptive/active": (ADAPTIVE.active, [None]),
            "adaptive/history": (ADAPTIVE.history, [None, None]),
            "adaptive/orders": (ADAPTIVE.orders, ["/input"]),
        },
    ),
    "refinement": (
        RefinementReport(REFINEMENT),
        {
            "refinement/orders": (REFINEMENT.orders, [None, "/input"]),
            "refinement/runs": (REFINEMENT.runs, [None]),
            "refinement/indicator": (REFINEMENT.indicator, [None]),
        },
    ),
    "regression": (
        RegressionReport(FITS),
        {
            **{f"outputs/{n}/loo": (fit.loo, ["/time"]) for n, fit in FITS.items()},
            **{f"outputs/{n}/selected": (f.selected, [None, "/input"]) for n, f in FITS.items()},
        },
    ),
}


def _written(path):
    found = {}
    with h5py.File(path) as file:

        def visit(name, item):
            if isinstance(item, h5py.Dataset):
                scales = [next((s.name for s in axis.values()), None) for axis in item.dims]
                found[name] = (item[()], scales)

        file.visititems(visit)
        conditions = {n: file[f"outputs/{n}"].attrs.get("condition") for n in FITS}
    return found, conditions


@pytest.mark.parametrize("case", CASES)
def test_a_report_is_stored_at_its_paths_and_read_back_whole(result, tmp_path, case):
    report, expected = CASES[case]
    plain, _ = _written(_write(result, None, tmp_path / "plain.h5"))
    found, conditions = _written(_write(result, report, tmp_path / "report.h5"))
    assert set(found) - set(plain) == set(expected)
    for path, (value, scales) in expected.items():
        np.testing.assert_array_equal(found[path][0], value)
        assert found[path][0].dtype == value.dtype and found[path][1] == scales
    held = {n: fit.condition for n, fit in FITS.items()} if case == "regression" else {}
    assert {n: c for n, c in conditions.items() if c is not None} == held
    back = pcmb.load(tmp_path / "report.h5").report
    assert type(back) is type(report)
    for mine, theirs in zip(_records(back), _records(report), strict=True):
        for field in dataclasses.fields(mine):
            np.testing.assert_array_equal(getattr(mine, field.name), getattr(theirs, field.name))


def _write(result, report, path):
    store.write_result(path, dataclasses.replace(result, report=report), provenance={})
    return path


def _records(report):
    held = getattr(report, dataclasses.fields(report)[0].name)
    return [held[n] for n in sorted(held)] if isinstance(held, dict) else [held]
