"""The sweep's table of cost and error: ``sweep.csv`` and ``sweep.h5``.

One row per setting, replicate and output. ``sweep.h5`` holds the same columns under
``/table/<column>``, the per-time error curves ``/curves/mean_error`` and
``/curves/std_error`` (rows × time, on the ``/time`` scale), and per output the reference's
noise floor (``/floor/<output>`` attributes ``mean`` and ``std``). Both files are written
atomically.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pcmb.errors import ResultFileError
from pcmb.run.files import write_durably
from pcmb.run.output import write_error
from pcmb.sweep.accuracy import Errors

__all__ = [
    "COLUMNS",
    "SWEEP_KIND",
    "TARGETS",
    "SweepRow",
    "SweepTable",
    "cheapest",
    "is_sweep_file",
    "reach_text",
    "read_sweep",
    "summary",
    "write_sweep",
]

#: ``kind`` attribute of a ``sweep.h5`` file (``pcmb report`` tells it from a result by it).
SWEEP_KIND = "pcmb-sweep"


@dataclass(frozen=True)
class SweepRow:
    """Cost and error of one setting (one replicate) for one output.

    ``runs`` are the method's model runs, ``held_out`` the extra runs that check an
    expansion; ``seconds`` is the wall time of the whole study, ``model_seconds`` the part
    spent running the model (``pcmb_seconds`` the rest: recovery, statistics, writing).
    Errors are relative to the reference's largest std (:mod:`pcmb.sweep.accuracy`).
    """

    method: str
    setting: str
    runs: int
    seconds: float
    output: str
    err_mean: float
    err_std: float
    err_mean_rms: float
    err_std_rms: float
    replicate: int = 0
    held_out: int = 0
    model_seconds: float = float("nan")
    pcmb_seconds: float = float("nan")
    file: str = ""

    @classmethod
    def measured(cls, errors: Errors, **fields: Any) -> SweepRow:
        """A row with the errors of :func:`pcmb.sweep.accuracy.errors` and the other fields."""
        return cls(
            err_mean=errors.mean,
            err_std=errors.std,
            err_mean_rms=errors.mean_rms,
            err_std_rms=errors.std_rms,
            **fields,
        )


#: The columns of ``sweep.csv``, in order (the first seven are the documented contract).
COLUMNS = (
    "method",
    "setting",
    "runs",
    "seconds",
    "output",
    "err_mean",
    "err_std",
    "err_mean_rms",
    "err_std_rms",
    "replicate",
    "held_out",
    "model_seconds",
    "pcmb_seconds",
    "file",
)
_TYPES = {f.name: f.type for f in dataclasses.fields(SweepRow)}


@dataclass(frozen=True)
class SweepTable:
    """Rows with their error curves, and what they were measured against.

    Attributes
    ----------
    rows:
        One per setting, replicate and output.
    times:
        (T,) the time grid of the curves.
    mean_curves, std_curves:
        (rows, T) the per-time errors of each row (NaN for an output that is not on time,
        whose errors over its own points are in its row).
    reference:
        What the errors are measured against (a file and its method).
    reference_file:
        The reference's result file.
    floors:
        Output -> (mean, std) noise floor of the reference, relative to its largest std.
    """

    rows: tuple[SweepRow, ...]
    times: NDArray[np.float64]
    mean_curves: NDArray[np.float64]
    std_curves: NDArray[np.float64]
    reference: str
    reference_file: str = ""
    floors: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def extended(
        self,
        rows: Sequence[SweepRow],
        mean_curves: NDArray[np.float64],
        std_curves: NDArray[np.float64],
    ) -> SweepTable:
        """This table with more rows (e.g. a peer's) appended."""
        return dataclasses.replace(
            self,
            rows=(*self.rows, *rows),
            mean_curves=np.vstack(
                [self.mean_curves, np.reshape(mean_curves, (-1, self.times.size))]
            ),
            std_curves=np.vstack([self.std_curves, np.reshape(std_curves, (-1, self.times.size))]),
        )

    def column(self, name: str) -> NDArray:
        """One column over the rows."""
        return np.array([getattr(row, name) for row in self.rows])


#: Accuracies :func:`summary` reports the cost of.
TARGETS = (1e-2, 1e-4)


def cheapest(table: SweepTable, output: str, target: float) -> dict[str, SweepRow | None]:
    """Per method, its cheapest setting (in runs) whose median std error over replicates
    meets ``target`` (the row of its median seconds), ``None`` when none does."""
    settings: dict[tuple[str, str], list[SweepRow]] = {}
    for row in table.rows:
        if row.output == output:
            settings.setdefault((row.method, row.setting), []).append(row)
    found: dict[str, SweepRow | None] = {}
    for (method, _), rows in settings.items():
        found.setdefault(method, None)
        if np.median([r.err_std for r in rows]) > target:
            continue
        typical = sorted(rows, key=lambda r: r.seconds)[len(rows) // 2]
        best = found[method]
        if best is None or typical.runs < best.runs:
            found[method] = typical
    return found


def reach_text(row: SweepRow | None) -> str:
    """``"6 runs, 0.0287 s"``: the cost of a setting :func:`cheapest` found, or ``"not
    reached"``."""
    return "not reached" if row is None else f"{row.runs} runs, {row.seconds:.3g} s"


def summary(table: SweepTable) -> str:
    """The text ``pcmb inspect`` prints of a sweep: per output and method, the runs and
    seconds of the cheapest setting reaching each of :data:`TARGETS`."""
    lines = [f"sweep    {len(table.rows)} rows against {table.reference}"]
    for output in dict.fromkeys(row.output for row in table.rows):
        floor = table.floors.get(output, (0.0, 0.0))[1]
        lines.append(f"output   {output} (reference noise floor of the std: {floor:.2g})")
        reached = {target: cheapest(table, output, target) for target in TARGETS}
        header = "".join(f"{f'std error {t:g}':>26}" for t in TARGETS)
        lines.append(f"  {'method':<28}{header}")
        for method in reached[TARGETS[0]]:
            cells = []
            for target in TARGETS:
                cells.append(reach_text(reached[target][method]))
            lines.append(f"  {method:<28}" + "".join(f"{cell:>26}" for cell in cells))
    return "\n".join(lines)


def _csv_text(table: SweepTable) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in table.rows:
        writer.writerow(
            [f"{v:.6g}" if isinstance(v, float) else v for v in (getattr(row, c) for c in COLUMNS)]
        )
    return buffer.getvalue()


def _h5_image(table: SweepTable) -> bytes:
    import h5py

    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as file:
        file.attrs["kind"] = SWEEP_KIND
        file.attrs["reference"] = table.reference
        file.attrs["reference_file"] = table.reference_file
        time = file.create_dataset("time", data=table.times)
        time.make_scale("time")
        group = file.create_group("table")
        for name in COLUMNS:
            values = table.column(name)
            if _TYPES[name] == "str":
                group.create_dataset(name, data=values.astype(object), dtype=h5py.string_dtype())
            else:
                group.create_dataset(
                    name, data=values.astype(float if "float" in _TYPES[name] else int)
                )
        curves = file.create_group("curves")
        for name, data in (("mean_error", table.mean_curves), ("std_error", table.std_curves)):
            dataset = curves.create_dataset(name, data=np.reshape(data, (-1, table.times.size)))
            dataset.dims[1].attach_scale(time)
        floors = file.create_group("floor")
        for output, (mean, std) in table.floors.items():
            floors.create_group(output).attrs.update({"mean": mean, "std": std})
    return buffer.getvalue()


def _write_bytes(path: Path, data: bytes, what: str) -> None:
    try:
        write_durably(path, data)
    except OSError as error:
        raise write_error(error, path, what, "the settings' result files are kept") from error


def write_sweep(table: SweepTable, folder: str | os.PathLike[str]) -> tuple[Path, Path]:
    """Write ``sweep.csv`` and ``sweep.h5`` into ``folder``; their paths."""
    folder = Path(folder)
    paths = folder / "sweep.csv", folder / "sweep.h5"
    _write_bytes(paths[0], _csv_text(table).encode(), "sweep table")
    _write_bytes(paths[1], _h5_image(table), "sweep file")
    return paths


def _value(name: str, value: object) -> object:
    kind = _TYPES[name]
    if kind == "str":
        return value.decode() if isinstance(value, bytes) else str(value)
    return float(value) if "float" in kind else int(value)


def read_sweep(path: str | os.PathLike[str]) -> SweepTable:
    """Read a ``sweep.h5`` back.

    Raises
    ------
    ResultFileError
        The file is missing or not a sweep file.
    """
    import h5py

    try:
        with h5py.File(path, "r") as file:
            if file.attrs.get("kind") != SWEEP_KIND:
                raise ResultFileError(f"{path}: not a pcmb sweep file")
            group = file["table"]
            columns = {name: group[name][()] for name in COLUMNS}
            rows = tuple(
                SweepRow(**{name: _value(name, columns[name][i]) for name in COLUMNS})
                for i in range(group["method"].shape[0])
            )
            floors = {
                name: (float(item.attrs["mean"]), float(item.attrs["std"]))
                for name, item in file["floor"].items()
            }
            return SweepTable(
                rows,
                file["time"][()],
                file["curves/mean_error"][()],
                file["curves/std_error"][()],
                str(file.attrs["reference"]),
                str(file.attrs["reference_file"]),
                floors,
            )
    except (OSError, KeyError) as error:
        raise ResultFileError(f"{path}: not a readable pcmb sweep file ({error})") from error


def is_sweep_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a readable ``sweep.h5`` (False for a result file or no file)."""
    import h5py

    try:
        with h5py.File(path, "r") as file:
            return file.attrs.get("kind") == SWEEP_KIND
    except OSError:
        return False
