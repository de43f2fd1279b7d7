"""The result file: its layout, round trip, named dimensions, atomic writes."""

import dataclasses
import json
from typing import ClassVar

import h5py
import numpy as np
import pytest

import pcmb
from pcmb import store
from pcmb.designs import REPORTS
from pcmb.errors import ResultFileError
from pcmb.result import DesignReport, WarningRecord

INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Beta(2.0, 3.0, -1.0, 1.0)}
TIMES = np.linspace(0.0, 1.0, 4)


@pcmb.pointwise(outputs=("y", "w"))
def model(params, times):
    return {"y": params["a"] * times + params["b"] ** 3, "w": np.cos(params["a"] * times)}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("store") / "sub" / "result.h5"
    study = pcmb.Study(model, INPUTS, TIMES, order=3, params={"a": 2.0, "b": 0.0}, jobs=1)
    result = study.run()
    store.write_result(path, result, provenance={"config": "name: x\n", "config_sha256": "abc"})
    return path, result


def test_layout_follows_the_spec(written):
    path = written[0]
    with h5py.File(path) as f:
        assert f.attrs["schema_version"] == store.SCHEMA_VERSION
        assert f.attrs["config"] == "name: x\n" and f.attrs["config_sha256"] == "abc"
        assert "numpy" in json.loads(f.attrs["versions"])
        assert f["time"].shape == (4,)
        assert json.loads(f["inputs"].attrs["names"]) == ["a", "b"]
        assert f["nodes/germ"].shape == f["nodes/params"].shape == (16, 2)
        assert f["nodes/weights"][()].sum() == pytest.approx(1.0)
        assert f["nodes/status"].dtype == np.int8
        assert f["basis/multi_index"].shape == (16, 2)
        for name in ("y", "w"):
            group = f[f"outputs/{name}"]
            assert group["values"].shape == (16, 4)
            assert group["coefficients"].shape == (16, 4)
            assert group["mean"].shape == group["std"].shape == (4,)
            assert group["sobol_first"].shape == group["sobol_total"].shape == (2, 4)


def test_round_trip_through_load(written):
    path, result = written
    loaded = pcmb.load(path)
    assert loaded.input_names == ("a", "b") and loaded.method == "collocation"
    for name in ("y", "w"):
        np.testing.assert_array_equal(loaded.values[name], result.values[name])
        np.testing.assert_array_equal(loaded.mean(name), result.mean(name))
        np.testing.assert_array_equal(loaded.sobol_total(name), result.sobol_total(name))
    np.testing.assert_array_equal(
        loaded.distributions[1].to_physical([0.3]), INPUTS["b"].to_physical([0.3])
    )


def test_xarray_sees_named_dimensions(written):
    xarray = pytest.importorskip("xarray")
    path, result = written
    with xarray.open_dataset(path, group="outputs/y", engine="h5netcdf") as ds:
        assert ds["values"].dims == ("node", "time")
        assert ds["coefficients"].dims == ("term", "time")
        assert ds["sobol_first"].dims == ("input", "time")
        np.testing.assert_array_equal(ds["mean"].values, result.mean("y"))


def test_a_failed_write_leaves_nothing_behind(written, tmp_path, monkeypatch):
    _, result = written
    target = tmp_path / "crash.h5"

    def explode(*args):
        raise RuntimeError("disk full")

    monkeypatch.setattr(store, "_write", explode)
    with pytest.raises(RuntimeError, match="disk full"):
        store.write_result(target, result, provenance={})
    assert list(tmp_path.iterdir()) == []


def test_an_existing_file_is_replaced_whole(written, tmp_path):
    _, result = written
    target = tmp_path / "again.h5"
    target.write_bytes(b"old contents")
    store.write_result(target, result, provenance={})
    assert pcmb.load(target).outputs == ("y", "w")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.h5"]


def test_load_refuses_other_files(tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    with pytest.raises(ResultFileError, match="not a pcmb result"):
        pcmb.load(other)
    with pytest.raises(ResultFileError, match="no such file"):
        pcmb.load(tmp_path / "absent.h5")
    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(b"not hdf5 at all")
    with pytest.raises(ResultFileError, match="not a readable pcmb result file"):
        pcmb.load(garbage)


def test_design_and_warnings_round_trip(written):
    path, result = written
    loaded = pcmb.load(path)
    assert loaded.design == result.design
    assert loaded.design.kind == "collocation" and loaded.design.grid == "tensor-gauss"
    records = (
        WarningRecord("study-wide", "about everything"),
        WarningRecord("per-output", "about x", output=result.outputs[0], time_range=(0.5, 1.0)),
    )
    again = path.with_name("again.h5")
    store.write_result(again, dataclasses.replace(result, warnings=records), provenance={})
    assert set(pcmb.load(again).warnings) == set(records)


def test_the_file_mode_follows_the_umask(written, tmp_path):
    import os
    import stat

    _, result = written
    umask = os.umask(0o022)
    try:
        target = store.write_result(tmp_path / "mode.h5", result, provenance={})
    finally:
        os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o644


def test_the_diagnostics_round_trip_and_older_files_load(written, tmp_path):
    path, result = written
    for name in ("y", "w"):
        found, back = result.diagnostics[name], pcmb.load(path).diagnostics[name]
        for key in ("error", "upper", "mean_error", "std_error", "spread"):
            np.testing.assert_array_equal(getattr(back.holdout, key), getattr(found.holdout, key))
        np.testing.assert_array_equal(back.estimate, found.estimate)
    # A file from before the statistics' errors were stored judged the surrogate only: it
    # loads, with NaN where those arrays would be.
    old = tmp_path / "old.h5"
    old.write_bytes(path.read_bytes())
    with h5py.File(old, "r+") as file:
        for key in ("mean_error", "std_error", "spread"):
            del file[f"diagnostics/y/{key}"]
    holdout = pcmb.load(old).diagnostics["y"].holdout
    assert np.isnan(holdout.mean_error).all() and np.isnan(holdout.spread).all()
    np.testing.assert_array_equal(holdout.error, result.diagnostics["y"].holdout.error)


@dataclasses.dataclass(frozen=True)
class _Surpluses(DesignReport):
    """A design report no part of pcmb knows, as a new design would bring its own."""

    key: ClassVar[str] = "surpluses"

    surpluses: np.ndarray

    def write(self, file):
        file.dataset("surpluses", self.surpluses, "node")

    @classmethod
    def read(cls, file):
        found = file.read("surpluses")
        return None if found is None else cls(found)

    def summary(self, result):
        return [("surplus", f"largest {self.surpluses.max():g}")]


def test_a_registered_design_report_is_written_read_and_inspected(written, tmp_path, monkeypatch):
    from pcmb.cli import _inspect

    monkeypatch.setitem(REPORTS, _Surpluses.key, _Surpluses)
    path, result = written
    assert result.report is None and result.regression == {} and result.adaptive is None
    reported = dataclasses.replace(result, report=_Surpluses(np.arange(16.0)))
    store.write_result(tmp_path / "r.h5", reported, provenance={})
    with h5py.File(tmp_path / "r.h5") as file:
        assert file["surpluses"].dims[0][0].name == "/node"
    back = pcmb.load(tmp_path / "r.h5").report
    assert isinstance(back, _Surpluses)
    np.testing.assert_array_equal(back.surpluses, np.arange(16.0))
    assert "surplus  largest 15" in _inspect(str(tmp_path / "r.h5")).splitlines()
    assert pcmb.load(path).report is None  # a file without it: none


@pcmb.pointwise(outputs=("y", "w"))
def model_failing_at_nominal(params, times):
    if params["a"] == 2.0:  # the nominal value, never a node nor a drawn held-out run
        raise ValueError("no run at the nominal point")
    return model(params, times)


def _stored_severities(path):
    """(code, output) -> the severity stored with each warning record of the file."""
    with h5py.File(path) as file:
        group = file["diagnostics"]
        owners = [group, *(g for g in group.values() if isinstance(g, h5py.Group))]
        return {
            (record["code"], record["output"]): record["severity"]
            for owner in owners
            for record in json.loads(owner.attrs.get("warnings", "[]"))
        }


def _inspected_records(path):
    from pcmb.cli import _inspect

    return [
        line for line in _inspect(str(path)).splitlines() if line.startswith(("note ", "warning "))
    ]


def test_the_file_holds_each_records_severity_as_inspect_shows_it(tmp_path):
    path = tmp_path / "r.h5"
    study = pcmb.Study(
        model_failing_at_nominal, INPUTS, TIMES, order=3, params={"a": 2.0, "b": 0.0}, jobs=1
    )
    with pytest.warns(pcmb.PcmbWarning, match="nominal"):
        result = study.run(path)
    stored = _stored_severities(path)
    assert stored[("nominal-failed", None)] == "warning"
    assert stored[("sobol-undefined", "w")] == "note"
    loaded = pcmb.load(path)
    assert [w.severity for w in loaded.warnings] == [
        stored[w.code, w.output] for w in loaded.warnings
    ]
    assert _inspected_records(path) == [f"{w.severity:<9}{w}" for w in loaded.warnings]
    # An indicator's severity follows the verdict: a note about an output it vouches for.
    assert result.diagnostics["y"].vouched
    indicator = WarningRecord("element-decay", "an indicator", output="y")
    store.write_result(
        path, dataclasses.replace(result, warnings=(*result.warnings, indicator)), provenance={}
    )
    assert _stored_severities(path)[("element-decay", "y")] == "note"
    assert "note     y: an indicator [element-decay]" in _inspected_records(path)
    # Read from the file, not derived again: a record the file calls a note is shown as one.
    with h5py.File(path, "r+") as file:
        records = json.loads(file["diagnostics"].attrs["warnings"])
        (failed,) = [record for record in records if record["code"] == "nominal-failed"]
        failed["severity"] = "note"
        file["diagnostics"].attrs["warnings"] = json.dumps(records)
    assert any(
        line.startswith("note ") and "[nominal-failed]" in line for line in _inspected_records(path)
    )


def test_a_file_without_severities_derives_them_as_before(written, tmp_path):
    result = written[1]
    records = (
        WarningRecord("nominal-failed", "the nominal run failed"),
        WarningRecord("sobol-undefined", "w does not vary", output="w", time_range=(0.0, 0.0)),
        WarningRecord("element-decay", "an indicator", output="y"),
    )
    old = tmp_path / "old.h5"
    store.write_result(old, dataclasses.replace(result, warnings=records), provenance={})
    with h5py.File(old, "r+") as file:
        for owner in (file["diagnostics"], file["diagnostics/w"], file["diagnostics/y"]):
            kept = json.loads(owner.attrs["warnings"])
            for record in kept:
                record.pop("severity", None)
            owner.attrs["warnings"] = json.dumps(kept)
    loaded = pcmb.load(old)
    assert [loaded.is_note(w) for w in loaded.warnings] == [False, True, True]
    assert _inspected_records(old) == [
        "warning  the nominal run failed [nominal-failed]",
        "note     w: t in [0, 0]: w does not vary [sobol-undefined]",
        "note     y: an indicator [element-decay]",
    ]


def test_a_stored_severity_that_is_neither_warning_nor_note_is_refused(written, tmp_path):
    """A file's severity is read, not trusted: an unknown word is a result-file error naming
    the record, never a record shown as neither."""
    path = tmp_path / "odd.h5"
    store.write_result(path, written[1], provenance={})
    with h5py.File(path, "r+") as file:
        owner = next(
            g for g in (file["diagnostics"], *file["diagnostics"].values()) if "warnings" in g.attrs
        )
        kept = json.loads(owner.attrs["warnings"])
        kept[0]["severity"] = "fatal"
        owner.attrs["warnings"] = json.dumps(kept)
    with pytest.raises(ResultFileError, match="severity 'fatal'"):
        pcmb.load(path)


@pytest.mark.parametrize(
    ("inputs", "method", "source"),
    [
        (INPUTS, {"order": 3}, "held-out"),
        ({"a": pcmb.Normal(2.0, 0.5)}, {"order": 6}, "placed"),
        ({"a": pcmb.Uniform(1.0, 3.0)}, {"order": 4, "validation": 0}, "decay"),
        ({"a": pcmb.Uniform(1.0, 3.0)}, {"order": "auto", "validation": 0}, "design"),
    ],
    ids=["drawn", "placed", "decay", "design"],
)
def test_where_an_estimate_comes_from_is_stored_and_older_files_tell_it(
    tmp_path, inputs, method, source
):
    """``estimated_by`` is an attribute of /diagnostics/<output>; a file written before it
    loads with the source its held-out check and arrays tell, for each source (of ``w``:
    ``y``, linear in ``a``, is read from the decay under ``order: auto`` too)."""
    study = pcmb.Study(
        model,
        inputs,
        TIMES,
        method={"kind": "collocation", **method},
        params={"a": 2.0, "b": 0.0},
        execution={"backend": "inprocess"},
    )
    result = study.run()
    assert result.diagnostics["w"].estimated_by == source
    path = tmp_path / "result.h5"
    store.write_result(path, result, provenance={})
    with h5py.File(path) as file:
        assert file["diagnostics/w"].attrs["estimated_by"] == source
    assert pcmb.load(path).diagnostics["w"].estimated_by == source
    with h5py.File(path, "r+") as file:
        del file["diagnostics/w"].attrs["estimated_by"]
    assert pcmb.load(path).diagnostics["w"].estimated_by == source
