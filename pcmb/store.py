"""The result file: one HDF5 file per study, written atomically (layout in
``docs/architecture.md``). The only module that imports h5py.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import io
import json
import os
import platform
from collections.abc import Iterable, Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from pcmb.analysis.diagnostics import CODES, HeldOut, HeldOutCheck, OutputDiagnostics
from pcmb.analysis.statistics import Analysis, AnalysisSettings, Density, OutputAnalysis, Spectrum
from pcmb.axes import OutputAxis
from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import from_description
from pcmb.chaos.process import RandomProcess, covariance_from_description, germ_names
from pcmb.errors import ResultFileError
from pcmb.result import (
    NOTE,
    WARNING,
    Design,
    DesignReport,
    ModelTraceback,
    NodeFailure,
    Status,
    StudyResult,
    WarningRecord,
)
from pcmb.run.files import durable_temporary, write_durably
from pcmb.run.memory import DEFAULT_MEMORY, available_memory, parse_memory
from pcmb.run.output import write_error

__all__ = [
    "SCHEMA_VERSION",
    "check_replaceable",
    "is_result_file",
    "load",
    "write_result",
    "write_streamed",
]

SCHEMA_VERSION = 1
#: The scale of an output's points: /time, /<axis name>, or None for a scalar output.
_Trail = h5py.Dataset | None
_VERSIONED = ("numpy", "scipy", "h5py", "joblib", "pydantic", "pyyaml", "mujoco")


def _versions() -> dict[str, str]:
    found = {"python": platform.python_version()}
    for package in _VERSIONED:
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            continue
    return found


def _scale(file: h5py.File, name: str, data: np.ndarray) -> h5py.Dataset:
    dataset = file.create_dataset(name, data=data)
    dataset.make_scale(name)
    return dataset


def _attach(dataset: h5py.Dataset, *scales: h5py.Dataset) -> h5py.Dataset:
    for axis, scale in enumerate(scales):
        dataset.dims[axis].attach_scale(scale)
    return dataset


def _points(
    group: h5py.Group, key: str, data: Any, scales: tuple[h5py.Dataset, ...], trail: _Trail
) -> h5py.Dataset:
    """A dataset whose last axis is an output's points, on scale ``trail``; a scalar output's
    (``trail`` None) is stored without that axis."""
    if trail is None:
        return _attach(group.create_dataset(key, data=np.asarray(data)[..., 0]), *scales)
    return _attach(group.create_dataset(key, data=data), *scales, trail)


def _columns(data: np.ndarray, scalar: bool) -> np.ndarray:
    """The last axis a scalar output's datasets were stored without, back (length 1)."""
    return data[..., None] if scalar else data


def _output_scales(file: h5py.File, result: StudyResult, time_: h5py.Dataset) -> dict[str, _Trail]:
    """Output name -> the scale of its points: ``/time``, ``/<axis name>`` (attribute
    ``units``), or ``None`` for a scalar."""
    trails: dict[str, _Trail] = {}
    for name in result.values:
        if result.on_time(name):
            trails[name] = time_
            continue
        axis = result.axes[name]
        if axis is None:
            trails[name] = None
            continue
        if axis.name not in file:
            _scale(file, axis.name, axis.values).attrs["units"] = axis.unit
        trails[name] = file[axis.name]
    return trails


def _read_axes(file: h5py.File, outputs: list[str]) -> dict[str, OutputAxis | None]:
    """Output name -> its own axis or ``None`` (scalar), from each group's ``axis``
    attribute; the outputs without one are on time."""
    axes: dict[str, OutputAxis | None] = {}
    for name in outputs:
        group = file["outputs"][name]
        if "axis" not in group.attrs:
            continue
        key = _text(group.attrs["axis"])
        scale = file[key] if key else None
        axes[name] = (
            None if scale is None else OutputAxis(key, scale[()], _text(scale.attrs["units"]))
        )
    return axes


def _write_density(group: h5py.Group, at_name: str, density: Density) -> None:
    at = _scale(group, at_name, density.at)
    point = _scale(group, "point", np.arange(density.value.shape[1]))
    _attach(group.create_dataset("value", data=density.value), at, point)
    _attach(group.create_dataset("density", data=density.density), at, point)
    _attach(group.create_dataset("bandwidth", data=density.bandwidth), at)


def _read_density(group: h5py.Group, at_name: str) -> Density:
    return Density(
        group[at_name][()], group["value"][()], group["density"][()], group["bandwidth"][()]
    )


def _write_analysis(
    file: h5py.File, output: h5py.Group, analysis: OutputAnalysis, time_: _Trail, unit: str
) -> None:
    _points(output, "quantiles", analysis.quantiles, (file["quantile"],), time_)
    _write_density(output.create_group("pdf"), "pdf_time", analysis.pdf)
    spectrum = analysis.spectrum
    if spectrum is None:
        return
    group = output.create_group("spectrum")
    group.attrs["window"] = spectrum.window
    group.attrs["units"] = f"({unit})^2/Hz" if unit else "(output unit)^2/Hz"
    frequency = _scale(group, "frequency", spectrum.frequency)
    for key in ("mean", "std", "nominal"):
        if getattr(spectrum, key) is not None:
            _attach(group.create_dataset(key, data=getattr(spectrum, key)), frequency)
    if spectrum.pdf is not None:
        _write_density(group.create_group("pdf"), "pdf_frequency", spectrum.pdf)


def _read_analysis(
    file: h5py.File, names: list[str], axes: Mapping[str, OutputAxis | None]
) -> Analysis | None:
    if "analysis" not in file.attrs:
        return None
    outputs = {}
    for name in names:
        group = file["outputs"][name]
        spectrum = None
        if "spectrum" in group:
            part = group["spectrum"]
            spectrum = Spectrum(
                frequency=part["frequency"][()],
                mean=part["mean"][()],
                std=part["std"][()],
                nominal=part["nominal"][()] if "nominal" in part else None,
                window=_text(part.attrs["window"]),
                pdf=_read_density(part["pdf"], "pdf_frequency") if "pdf" in part else None,
            )
        outputs[name] = OutputAnalysis(
            quantiles=_columns(group["quantiles"][()], name in axes and axes[name] is None),
            pdf=_read_density(group["pdf"], "pdf_time"),
            spectrum=spectrum,
        )
    return Analysis(AnalysisSettings.from_description(_text(file.attrs["analysis"])), outputs)


def _tracebacks_text(failures: Sequence[NodeFailure]) -> str:
    """The JSON of the root attribute ``failure_tracebacks``: each distinct traceback once,
    with the failed nodes it belongs to."""
    nodes: dict[ModelTraceback, list[int]] = {}
    for failure in failures:
        if failure.traceback is not None:
            nodes.setdefault(failure.traceback, []).append(failure.index)
    return json.dumps([{"nodes": found, **raised.describe()} for raised, found in nodes.items()])


def _read_tracebacks(attrs: h5py.AttributeManager) -> dict[int, ModelTraceback]:
    """Node index -> its traceback, from ``failure_tracebacks`` (none in older files)."""
    found = {}
    for entry in json.loads(_text(attrs.get("failure_tracebacks", "[]"))):
        raised = ModelTraceback.from_description(entry)
        found.update(dict.fromkeys(entry["nodes"], raised))
    return found


def _write(
    file: h5py.File, result: StudyResult, provenance: Mapping[str, str], streamed: bool = False
) -> None:
    """Everything of ``result`` into ``file``; ``streamed``: the values datasets are made
    (N, W) and left unwritten, to be filled run by run (:func:`write_streamed`)."""
    from pcmb import __version__

    n_nodes = result.n_nodes
    attrs = file.attrs
    attrs["pcmb_version"] = __version__
    attrs["schema_version"] = SCHEMA_VERSION
    attrs["name"] = result.name
    attrs["method"] = result.method
    attrs["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    attrs["versions"] = json.dumps(_versions())
    attrs["seconds"] = result.seconds
    attrs["failures"] = json.dumps(
        [{"index": f.index, "params": f.params, "message": f.message} for f in result.failures]
    )
    attrs["failure_tracebacks"] = _tracebacks_text(result.failures)
    for key in ("config", "config_sha256", "command_line"):
        attrs[key] = provenance.get(key, "")

    file.create_group("design").attrs["record"] = result.design.describe()
    _write_warnings(file, result)
    time_ = _scale(file, "time", result.times)
    node = _scale(file, "node", np.arange(n_nodes))
    input_ = _scale(file, "input", np.array(result.input_names, dtype=h5py.string_dtype()))
    trails = _output_scales(file, result, time_)
    _write_diagnostics(file, result, trails, input_)

    inputs = file.create_group("inputs")
    inputs.attrs["names"] = json.dumps(list(result.input_names))
    inputs.attrs["distributions"] = json.dumps([d.describe() for d in result.distributions])
    inputs.attrs["nominal"] = json.dumps(result.nominal_params)

    nodes = file.create_group("nodes")
    _attach(nodes.create_dataset("germ", data=result.germ), node, input_)
    _attach(nodes.create_dataset("params", data=result.params), node, input_)
    _attach(nodes.create_dataset("status", data=result.status.astype(np.int8)), node)
    if result.weights is not None:
        _attach(nodes.create_dataset("weights", data=result.weights), node)
    _write_elements(file, result, input_)
    _write_processes(file, result, trails)

    index = result.multi_index
    term = None
    if index is not None:
        term = _scale(file, "term", np.arange(index.shape[0]))
        _attach(file.create_dataset("basis/multi_index", data=index), term, input_)

    analysis = result.analysis
    if analysis is not None:
        attrs["analysis"] = json.dumps(analysis.settings.describe())
        _scale(file, "quantile", np.array(analysis.settings.quantiles, dtype=float))

    # HDF5 lists groups alphabetically: keep the model's output order explicitly.
    file.create_group("outputs").attrs["names"] = json.dumps(list(result.values))
    for name, values in result.values.items():
        group = file.create_group(f"outputs/{name}")
        trail = trails[name]
        if not result.on_time(name):
            group.attrs["axis"] = "" if trail is None else result.axes[name].name
        if streamed:
            shape = (n_nodes,) if trail is None else (n_nodes, values.shape[1])
            # Every row is written from the journal (every node has a record by then): no
            # fill is written first (16 GB for the 10⁶-run twin).
            empty = group.create_dataset(
                "values", shape=shape, dtype=float, fillvalue=np.nan, fill_time="never"
            )
            _attach(empty, node, *(() if trail is None else (trail,)))
        else:
            _points(group, "values", values, (node,), trail)
        _points(group, "mean", result.mean(name), (), trail)
        _points(group, "std", result.std(name), (), trail)
        expansion = result.expansions.get(name)
        if expansion is not None and term is not None:
            scales = (*_element_scale(file, expansion), term)
            _points(group, "coefficients", expansion.coefficients, scales, trail)
            _points(group, "sobol_first", expansion.sobol_first(), (input_,), trail)
            _points(group, "sobol_total", expansion.sobol_total(), (input_,), trail)
        if name in result.nominal:
            _points(group, "nominal", result.nominal[name], (), trail)
        if analysis is not None:
            unit = analysis.settings.units.get(name, "")
            _write_analysis(file, group, analysis.outputs[name], trail, unit)
    if result.report is not None:
        result.report.write(_ReportFile(file, trails=trails, scalars=set()))


def _write_elements(file: h5py.File, result: StudyResult, input_: h5py.Dataset) -> None:
    """A multi-element study's ``/elements/bounds`` (E, n, 2) in physical units and
    ``/elements/probability`` (E,); its coefficients are (E, S, T)."""
    partition = result.partition
    if partition is None:
        return
    element = _scale(file, "element", np.arange(partition.size))
    group = file.create_group("elements")
    _attach(group.create_dataset("bounds", data=partition.bounds), element, input_)
    _attach(group.create_dataset("probability", data=partition.probability), element)


def _write_processes(file: h5py.File, result: StudyResult, trails: dict[str, _Trail]) -> None:
    """Each random process input under ``/processes/<name>``: ``grid`` (m,), ``eigenvalues``
    (K,), ``modes`` (K, m) (the field is germs @ modes), ``variance_error`` (m,), and per
    output the total Sobol' index of its germs as a group, ``sobol_total/<output>`` (T,) (or
    on the output's own axis);
    attributes ``settings`` (JSON), ``germs`` (JSON names), ``captured_energy``,
    ``truncation_error``, ``total_variance``, ``eigenvalue_error``, ``nystrom_points``."""
    for name, found in result.processes.items():
        group = file.create_group(f"processes/{name}")
        group.attrs["settings"] = json.dumps(found.describe())
        group.attrs["germs"] = json.dumps(list(germ_names(name, found.terms)))
        for key in ("captured_energy", "truncation_error", "total_variance"):
            group.attrs[key] = getattr(found, key)
        group.attrs["eigenvalue_error"] = found.eigenvalue_error
        group.attrs["nystrom_points"] = found.nystrom_points
        grid = group.create_dataset("grid", data=found.grid)
        grid.make_scale("grid")
        group.create_dataset("eigenvalues", data=found.eigenvalues)
        group.create_dataset("modes", data=found.modes).dims[1].attach_scale(grid)
        _attach(group.create_dataset("variance_error", data=found.variance_error), grid)
        for output, expansion in result.expansions.items():
            if isinstance(expansion, ChaosExpansion):
                data = result.sobol_process(output, name)
                _points(group, f"sobol_total/{output}", data, (), trails[output])


def _read_processes(file: h5py.File) -> dict[str, RandomProcess]:
    if "processes" not in file:
        return {}
    found = {}
    for name, group in file["processes"].items():
        settings = json.loads(_text(group.attrs["settings"]))
        found[name] = RandomProcess(
            covariance=covariance_from_description(settings["covariance"]),
            grid=group["grid"][()],
            eigenvalues=group["eigenvalues"][()],
            modes=group["modes"][()],
            energy=settings.get("energy"),
            total_variance=float(group.attrs["total_variance"]),
            eigenvalue_error=float(group.attrs["eigenvalue_error"]),
            nystrom_points=int(group.attrs["nystrom_points"]),
        )
    return found


class _ReportFile:
    """The open result file as a design report writes and reads it
    (:class:`pcmb.result.ReportFile`); ``trails``: each output's scale (writing only)."""

    def __init__(
        self,
        file: h5py.File,
        trails: Mapping[str, _Trail] | None,
        scalars: set[str],
        runs: bool = True,
    ) -> None:
        self.file, self.trails, self.scalars, self.runs = file, trails, scalars, runs

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(json.loads(_text(self.file["outputs"].attrs["names"])))

    def dataset(self, path: str, data: np.ndarray, *scales: str | None) -> None:
        dataset = self.file.create_dataset(path, data=data)
        for axis, scale in enumerate(scales):
            if scale is not None:
                dataset.dims[axis].attach_scale(self.file[scale])

    def points(self, path: str, data: np.ndarray, output: str, *scales: str) -> None:
        _points(self.file, path, data, tuple(self.file[s] for s in scales), self.trails[output])

    def attrs(self, path: str) -> h5py.AttributeManager:
        return self.file[path].attrs

    def read(self, path: str) -> np.ndarray | None:
        return self.file[path][()] if path in self.file else None

    def shape(self, path: str) -> tuple[int, ...] | None:
        return self.file[path].shape if path in self.file else None

    def read_points(self, path: str, output: str) -> np.ndarray | None:
        found = self.read(path)
        return None if found is None else _columns(found, output in self.scalars)


def _runs_fit(file: h5py.File, outputs: Sequence[str]) -> bool:
    """Whether the runs' values are read with the result: always where an expansion carries
    the statistics, else while they fit in the default ``execution.memory`` of what is
    available (a streamed study's may not: its statistics are then the stored ones)."""
    if any("coefficients" in file["outputs"][name] for name in outputs):
        return True
    size = sum(file["outputs"][name]["values"].size for name in outputs) * np.dtype(float).itemsize
    return size <= parse_memory(DEFAULT_MEMORY).limit(available_memory())


def _read_report(file: _ReportFile) -> DesignReport | None:
    """The design report the file holds, if any (each registered report looks for its own)."""
    from pcmb.designs import REPORTS

    for report in REPORTS.values():
        if (found := report.read(file)) is not None:
            return found
    return None


def _element_scale(file: h5py.File, expansion: ChaosExpansion) -> tuple[h5py.Dataset, ...]:
    """The ``element`` axis of a piecewise expansion's coefficients (none otherwise)."""
    return (file["element"],) if isinstance(expansion, PiecewiseExpansion) else ()


def _read_expansion(
    group: h5py.Group,
    index: np.ndarray,
    partition: Partition | None,
    dists: tuple,
    names: tuple,
    scalar: bool,
) -> ChaosExpansion | PiecewiseExpansion:
    """An output's expansion: piecewise on ``partition`` (from ``/elements``) if given."""
    coefficients = _columns(group["coefficients"][()], scalar)
    if partition is None:
        return ChaosExpansion(coefficients, index, dists, names)
    return PiecewiseExpansion(partition, coefficients, index, names)


def _write_warnings(file: h5py.File, result: StudyResult) -> None:
    """Warning records as JSON attributes, each with its severity (``StudyResult.severity``):
    the study's on /diagnostics, an output's on /diagnostics/<output> (attributes, so no
    output name can collide with them)."""
    group = file.create_group("diagnostics")
    warnings = result.warnings
    for output in dict.fromkeys(w.output for w in warnings):
        records = [
            {**dataclasses.asdict(w), "severity": result.severity(w)}
            for w in warnings
            if w.output == output
        ]
        owner = group if output is None else group.require_group(output)
        owner.attrs["warnings"] = json.dumps(records)


#: The per-time arrays of /diagnostics/<output>, each named as its OutputDiagnostics field.
_DIAGNOSTIC_ARRAYS = ("decay", "out_of_range", "estimate", "noise", "undecided")
#: ... and those of its held-out check: the estimated errors of the mean and the std, the
#: standard error of the larger, and the mean and std the held-out runs correct with their
#: standard errors (same names in the file as on HeldOutCheck).
_HOLDOUT_STATISTICS = (
    "mean_error",
    "std_error",
    "spread",
    "corrected_mean",
    "corrected_std",
    "corrected_mean_se",
    "corrected_std_se",
)


def _write_diagnostics(
    file: h5py.File, result: StudyResult, trails: Mapping[str, _Trail], input_: h5py.Dataset
) -> None:
    """/diagnostics/<output>: per-time (per-point) indicators and the verdict; /validation:
    the held-out runs (germ, params, status, and values per output)."""
    for name, found in result.diagnostics.items():
        group = file["diagnostics"].require_group(name)
        time_ = trails[name]
        for key in _DIAGNOSTIC_ARRAYS:
            _points(group, key, getattr(found, key), (), time_)
        if found.holdout is not None:
            _points(group, "holdout_error", found.holdout.error, (), time_)
            _points(group, "holdout_upper", found.holdout.upper, (), time_)
            for key in _HOLDOUT_STATISTICS:
                _points(group, key, getattr(found.holdout, key), (), time_)
            group.attrs["holdout_count"] = found.holdout.count
            group.attrs["confidence"] = found.holdout.confidence
        group.attrs["failing_from"] = found.failing_from
        group.attrs["estimated_by"] = found.estimated_by
        group.attrs["tolerance"] = found.tolerance
        group.attrs["scale"] = found.scale
    held_out = result.held_out
    if held_out is None:
        return
    group = file.create_group("validation")
    group.attrs["seed"] = held_out.seed
    group.attrs["placed"] = held_out.placed
    group.attrs["batches"] = held_out.batches
    run = _scale(file, "validation_run", np.arange(held_out.germ.shape[0]))
    _attach(group.create_dataset("germ", data=held_out.germ), run, input_)
    _attach(group.create_dataset("params", data=held_out.params), run, input_)
    status = np.where(held_out.ok, Status.OK, Status.FAILED).astype(np.int8)
    _attach(group.create_dataset("status", data=status), run)
    _attach(group.create_dataset("weights", data=held_out.weights), run)
    for name, values in held_out.values.items():
        _points(group, f"{name}/values", values, (run,), trails[name])


def _estimated_by(
    file: h5py.File, arrays: Mapping[str, np.ndarray], holdout: HeldOutCheck | None
) -> str:
    """Where the estimate of a file written before ``estimated_by`` was stored comes from, as
    its contents tell: the held-out runs (placed or drawn, by /validation), else the design's
    own estimate where it lies below the decay, else the decay."""
    if holdout is not None:
        return "placed" if file["validation"].attrs.get("placed", False) else "held-out"
    return "design" if np.any(arrays["estimate"] < arrays["decay"]) else "decay"


def _read_diagnostics(
    file: h5py.File, warnings: tuple[WarningRecord, ...], scalars: set[str]
) -> tuple[dict[str, OutputDiagnostics], HeldOut | None]:
    found: dict[str, OutputDiagnostics] = {}
    for name, group in file.get("diagnostics", {}).items():
        if not isinstance(group, h5py.Group) or "decay" not in group:
            continue
        attrs = group.attrs
        scalar = name in scalars
        holdout = None
        if "holdout_error" in group:
            error = _columns(group["holdout_error"][()], scalar)
            holdout = HeldOutCheck(
                error,
                _columns(group["holdout_upper"][()], scalar),
                *(  # older files judged the surrogate only
                    _columns(group[key][()], scalar) if key in group else np.nan * error
                    for key in _HOLDOUT_STATISTICS
                ),
                int(attrs["holdout_count"]),
                float(attrs["confidence"]),
            )
        absent = np.zeros(group["decay"].shape)  # older files have no noise (nor undecided)
        arrays = {
            key: _columns(group[key][()] if key in group else absent, scalar)
            for key in _DIAGNOSTIC_ARRAYS
        }
        arrays["undecided"] = arrays["undecided"].astype(bool)
        found[name] = OutputDiagnostics(
            output=name,
            scale=float(attrs["scale"]),
            holdout=holdout,
            estimated_by=str(attrs.get("estimated_by", "")) or _estimated_by(file, arrays, holdout),
            tolerance=float(attrs["tolerance"]),
            failing_from=float(attrs["failing_from"]),
            warnings=tuple(w for w in warnings if w.output == name and w.code in CODES),
            **arrays,
        )
    if "validation" not in file:
        return found, None
    group = file["validation"]
    held_out = HeldOut(
        seed=int(group.attrs["seed"]),
        germ=group["germ"][()],
        params=group["params"][()],
        values={
            name: _columns(group[name]["values"][()], name in scalars)
            for name in group
            if isinstance(group[name], h5py.Group)
        },
        ok=group["status"][()] == Status.OK,
        weights=group["weights"][()] if "weights" in group else np.ones(len(group["status"])),
        placed=bool(group.attrs.get("placed", False)),  # older files drew theirs
        batches=int(group.attrs.get("batches", 1)),  # and in one batch
    )
    return found, held_out


def _read_warnings(file: h5py.File) -> tuple[WarningRecord, ...]:
    if "diagnostics" not in file:  # files of pcmb 0.1 kept them as text in a root attribute
        texts = json.loads(_text(file.attrs.get("warnings", "[]")))
        return tuple(WarningRecord("legacy", text) for text in texts)
    group = file["diagnostics"]
    owners = [group, *(g for g in group.values() if isinstance(g, h5py.Group))]
    records = []
    for owner in owners:
        for record in json.loads(_text(owner.attrs.get("warnings", "[]"))):
            if record.get("severity") not in (None, WARNING, NOTE):
                raise ValueError(
                    f"warning record {record.get('code')!r} has severity "
                    f"{record['severity']!r}, neither {WARNING!r} nor {NOTE!r}"
                )
            span = record.pop("time_range")
            records.append(
                WarningRecord(**record, time_range=None if span is None else tuple(span))
            )
    return tuple(records)


def _read_design(file: h5py.File, index: np.ndarray | None) -> Design:
    """The design record; for pcmb 0.1 files, rebuilt from what they hold."""
    if "design" in file:
        return Design.from_description(_text(file["design"].attrs["record"]))
    kind = _text(file.attrs["method"])
    if kind == "collocation":
        orders = tuple(int(q) - 1 for q in (np.unique(c).size for c in file["nodes/germ"][()].T))
        full = index is not None and index.shape[0] == int(np.prod(np.add(orders, 1)))
        basis = "tensor" if full else "total"
        return Design(kind, "tensor-gauss", basis, orders, fit="projection", label=kind)
    orders = None if index is None else tuple(int(p) for p in index.max(axis=0))
    return Design(
        kind,
        "random",
        None if index is None else "total",
        orders,
        samples=int(file["nodes/germ"].shape[0]),
        fit="none" if index is None else "regression",
        label=kind,
    )


def write_result(
    path: str | os.PathLike[str], result: StudyResult, *, provenance: Mapping[str, str]
) -> Path:
    """Write a study result atomically.

    Parameters
    ----------
    path:
        Destination ``.h5`` file (its folder is created if needed); replaced if it exists.
    result:
        What the study produced.
    provenance:
        ``config`` (the YAML text), ``config_sha256``, ``command_line`` (any may be absent).

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    journal = Path(f"{path}.journal")
    # Built in memory, then written by ordinary Python I/O: a full disk (or a quota, or a
    # file system turned read-only) is then an OSError here, never a failure inside HDF5's
    # C code (h5py crashed with SIGSEGV on ENOSPC while flushing to a full disk).
    image = _image(result, provenance)
    try:
        write_durably(path, image)
    except OSError as error:
        kept = (
            f"the finished nodes are kept in {journal}: free some space (or fix the folder) "
            "and run again with --resume, which runs no node again"
            if journal.is_dir()
            else "free some space (or fix the folder) and write it again"
        )
        raise write_error(error, path, "result file", kept) from error
    return path


def write_streamed(
    path: str | os.PathLike[str],
    result: StudyResult,
    chunks: Iterable[tuple[np.ndarray, Mapping[str, np.ndarray], np.ndarray]],
    *,
    provenance: Mapping[str, str],
) -> Path:
    """Write the result of a streamed study atomically: ``result`` holds its statistics and no
    runs (``values`` without rows), ``chunks`` the runs, (B,) increasing node indices and
    output name -> (B, W) values (:meth:`pcmb.run.journal.Journal.chunks`), written to
    ``/outputs/<name>/values`` one chunk at a time. The file is built on disk beside ``path``
    (a temporary of :func:`pcmb.run.files.durable_temporary`, HDF5's own file locking off
    since that temporary is locked already) and renamed into place once complete.

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    try:
        with (
            durable_temporary(path) as (_, temporary),
            h5py.File(temporary, "w", locking=False) as file,
        ):
            _write(file, result, provenance, streamed=True)
            for indices, values, _status in chunks:
                rows = slice(int(indices[0]), int(indices[-1]) + 1)
                if rows.stop - rows.start != indices.size:
                    rows = indices
                for name, part in values.items():
                    dataset = file[f"outputs/{name}/values"]
                    dataset[rows] = part if dataset.ndim == 2 else part[:, 0]
    except OSError as error:
        kept = (
            f"the finished nodes are kept in {path}.journal: free some space (or fix the "
            "folder) and run again with --resume, which runs no node again"
        )
        raise write_error(error, path, "result file", kept) from error
    return path


def is_result_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is an HDF5 file pcmb wrote as a result (its root carries the
    ``pcmb_version`` and ``schema_version`` attributes); False for anything else."""
    try:
        with h5py.File(path, "r") as file:
            return "pcmb_version" in file.attrs and "schema_version" in file.attrs
    except (OSError, ValueError):
        return False


def check_replaceable(path: str | os.PathLike[str]) -> None:
    """Raise unless the file at ``path`` (if any) is a pcmb result, which a run may replace.

    Raises
    ------
    ResultFileError
        Naming the path: it is not a pcmb result, and is left as it is.
    """
    if Path(path).exists() and not is_result_file(path):
        raise ResultFileError(
            f"{path} exists and is not a pcmb result; pcmb does not overwrite it: give "
            "another output (-o), move it away, or overwrite it with --force"
        )


def _image(result: StudyResult, provenance: Mapping[str, str]) -> bytes:
    """The bytes of the HDF5 file of ``result``, built in memory (HDF5's core driver)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as file:
        _write(file, result, provenance)
    return buffer.getvalue()


def _text(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def load(path: str | os.PathLike[str]) -> StudyResult:
    """Read a result file back: values, expansions and statistics, without knowing the layout.

    Raises
    ------
    ResultFileError
        The file is missing, unreadable, not a pcmb result, or written by a newer schema.
    """
    if not Path(path).is_file():
        raise ResultFileError(f"{path}: no such file")
    try:
        return _read(path)
    except ResultFileError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ResultFileError(f"{path}: not a readable pcmb result file ({error})") from error


def _read(path: str | os.PathLike[str]) -> StudyResult:
    with h5py.File(path, "r") as file:
        attrs = file.attrs
        if "schema_version" not in attrs:
            raise ResultFileError(f"{path} is not a pcmb result file")
        if int(attrs["schema_version"]) > SCHEMA_VERSION:
            raise ResultFileError(
                f"{path} has schema version {int(attrs['schema_version'])}; this pcmb reads "
                f"up to {SCHEMA_VERSION}: upgrade pcmb"
            )
        names = tuple(json.loads(_text(file["inputs"].attrs["names"])))
        dists = tuple(
            from_description(d) for d in json.loads(_text(file["inputs"].attrs["distributions"]))
        )
        index = file["basis/multi_index"][()] if "basis" in file else None
        partition = Partition(dists, file["elements/bounds"][()]) if "elements" in file else None
        values: dict[str, np.ndarray] = {}
        expansions: dict[str, ChaosExpansion] = {}
        nominal: dict[str, np.ndarray] = {}
        outputs = json.loads(_text(file["outputs"].attrs["names"]))
        axes = _read_axes(file, outputs)
        scalars = {name for name, axis in axes.items() if axis is None}
        runs = _runs_fit(file, outputs)
        for name in outputs:
            group = file["outputs"][name]
            scalar = name in scalars
            stored = group["values"]
            kept = stored[()] if runs else np.empty((0, *stored.shape[1:]))
            values[name] = _columns(kept, scalar)
            if "coefficients" in group and index is not None:
                expansions[name] = _read_expansion(group, index, partition, dists, names, scalar)
            if "nominal" in group:
                nominal[name] = _columns(group["nominal"][()], scalar)
        raised = _read_tracebacks(attrs)
        failures = tuple(
            NodeFailure(f["index"], f["params"], f["message"], raised.get(f["index"]))
            for f in json.loads(_text(attrs.get("failures", "[]")))
        )
        warnings = _read_warnings(file)
        diagnostics, held_out = _read_diagnostics(file, warnings, scalars)
        return StudyResult(
            name=_text(attrs["name"]),
            design=_read_design(file, index),
            times=file["time"][()],
            input_names=names,
            distributions=dists,
            germ=file["nodes/germ"][()],
            params=file["nodes/params"][()],
            weights=file["nodes/weights"][()] if "weights" in file["nodes"] else None,
            status=file["nodes/status"][()],
            values=values,
            expansions=expansions,
            failures=failures,
            warnings=warnings,
            seconds=float(attrs.get("seconds", 0.0)),
            nominal_params=json.loads(_text(file["inputs"].attrs.get("nominal", "{}"))),
            nominal=nominal,
            analysis=_read_analysis(file, outputs, axes),
            report=_read_report(_ReportFile(file, trails=None, scalars=scalars, runs=runs)),
            diagnostics=diagnostics,
            held_out=held_out,
            processes=_read_processes(file),
            axes=axes,
        )
