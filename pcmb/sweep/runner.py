"""Run a sweep: every setting an ordinary study with its own result file, then the table.

Each setting runs through the same workers (one pool for the whole sweep), its own journal
and failure policy, and writes ``<folder>/<stem>.h5``. A ledger ``<folder>/sweep.ledger.json``
records every finished setting (its fingerprint and timing) as soon as it is written, so a
sweep stopped midway continues with ``resume=True`` where it stopped: finished settings are
read back, an interrupted one resumes from its journal; ``fresh=True`` discards the ledger
and the journals instead. The ledger is removed once ``sweep.csv``, ``sweep.h5`` and
``sweep.png`` are written. One sweep at a time writes a folder: it holds the lock
``<folder>/sweep.lock`` (:class:`~pcmb.run.lock.FolderLock`) while it runs.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pcmb.errors import ResultFileError, UsageError
from pcmb.run.files import write_durably
from pcmb.run.fingerprint import changed_files
from pcmb.run.journal import FRESH
from pcmb.run.lock import FolderLock
from pcmb.run.output import write_error
from pcmb.run.progress import Progress
from pcmb.sweep.accuracy import noise_floor, result_errors
from pcmb.sweep.plan import Setting, SweepPlan, plan_sweep
from pcmb.sweep.table import SweepRow, SweepTable, write_sweep

if TYPE_CHECKING:
    from pcmb.config.schema import StudyConfig
    from pcmb.result import StudyResult
    from pcmb.study import Study

__all__ = ["LEDGER", "LOCK", "SweepOutcome", "run_sweep"]

#: File of the finished settings while a sweep runs.
LEDGER = "sweep.ledger.json"
#: The lock file a running sweep holds in its folder.
LOCK = "sweep.lock"


@dataclass(frozen=True)
class SweepOutcome:
    """What :func:`run_sweep` wrote: the table and the files (``sweep.csv``, ``sweep.h5``,
    ``sweep.png``, then one result file per setting)."""

    table: SweepTable
    files: tuple[Path, ...]


@dataclass(frozen=True)
class _Finished:
    result: StudyResult
    seconds: float


def _study(config: StudyConfig, setting: Setting) -> Study:
    from pcmb.study import Study

    execution = config.execution.model_copy(update={"nominal_run": False})
    changes = {"method": setting.spec, "execution": execution, "analysis": None}
    return Study.from_config(config.model_copy(update=changes))


def _identity(study: Study, pool: Any) -> tuple[str, dict[str, str]]:
    """What a finished setting's result belongs to: a digest of everything that changes its
    values, and the digests of the model's files (the modules it loads too, asked of a
    worker of ``pool`` that built it)."""
    from pcmb.run.executor import describe_model

    loaded = describe_model(study.model_factory, pool).loaded_files
    found = study.fingerprint(study.node_set(), study.outputs or (), loaded)
    return found.digest, dict(found.files)


class _Ledger:
    """The finished settings of a sweep, rewritten atomically after each one."""

    def __init__(self, folder: Path, resume: bool, fresh: bool):
        self.path = folder / LEDGER
        self.entries: dict[str, dict[str, Any]] = {}
        if self.path.exists() and not fresh:
            if not resume:
                raise UsageError(
                    f"{self.path} lists the finished settings of an interrupted sweep: "
                    f"continue with --resume, or delete it or {FRESH} (which runs every "
                    "setting again)"
                )
            try:
                self.entries = json.loads(self.path.read_text(encoding="utf-8"))["settings"]
            except (OSError, ValueError, KeyError, TypeError) as error:
                raise ResultFileError(
                    f"{self.path}: unreadable sweep ledger ({error}); delete it or {FRESH}"
                ) from error
        self._save()

    def finished(self, stem: str, study: Study, path: Path, pool: Any) -> _Finished | None:
        """The stored result of a setting finished earlier with the same fingerprint."""
        from pcmb.store import load

        entry = self.entries.get(stem)
        if entry is None or not path.is_file():
            return None
        digest, files = _identity(study, pool)
        if entry["digest"] != digest:
            return None  # the setting itself changed: run it again
        changed = changed_files(entry["files"], files)
        if changed:
            raise UsageError(
                f"cannot resume the sweep: model file {changed[0]} changed since {path} was "
                f"written; restore it, or delete {self.path} or {FRESH}"
            )
        return _Finished(load(path), float(entry["seconds"]))

    def add(self, stem: str, study: Study, seconds: float, pool: Any) -> None:
        digest, files = _identity(study, pool)
        self.entries[stem] = {"digest": digest, "files": files, "seconds": seconds}
        self._save()

    def _save(self) -> None:
        write_durably(self.path, json.dumps({"settings": self.entries}, indent=1).encode())

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


@contextmanager
def _holding(folder: Path) -> Iterator[None]:
    """Hold the lock of the sweep ``folder`` while the block runs (made if missing).

    Raises
    ------
    UsageError
        Another sweep holds it (the message names its PID and command).
    ResultFileError
        The folder or its lock file cannot be made.
    """
    path = folder / LOCK
    try:
        lock = FolderLock.acquire(path, f"the sweep folder {folder}")
    except OSError as error:
        raise write_error(error, folder, "sweep folder", "give another folder (-o)") from error
    try:
        yield
    finally:
        path.unlink(missing_ok=True)  # still held: a sweep starting meanwhile locks a new file
        lock.release()


def _check_reference(reference: StudyResult, config: StudyConfig, source: str) -> None:
    times = config.times
    if reference.times.shape != times.shape or not np.allclose(reference.times, times):
        raise UsageError(
            f"reference {source} is on another time grid ({reference.times[0]}..."
            f"{reference.times[-1]}, {reference.times.size} points) than the config "
            f"({times[0]}..{times[-1]}, {times.size} points)"
        )


def _outputs(plan: SweepPlan, reference: StudyResult, source: str) -> tuple[str, ...]:
    names = plan.outputs or reference.outputs
    missing = [name for name in names if name not in reference.outputs]
    if missing:
        raise UsageError(f"reference {source} has no output {', '.join(missing)}")
    return tuple(names)


def _rows(
    setting: Setting,
    finished: _Finished,
    reference: StudyResult,
    outputs: tuple[str, ...],
    file: str,
) -> tuple[list[SweepRow], list[np.ndarray], list[np.ndarray]]:
    result = finished.result
    runs = int(result.status.size)
    held_out = 0 if result.held_out is None else int(result.held_out.ok.size)
    rows, means, stds = [], [], []
    for output in outputs:
        found = result_errors(result, reference, output)
        rows.append(
            SweepRow.measured(
                found,
                method=setting.method,
                setting=setting.setting,
                runs=runs,
                seconds=finished.seconds,
                output=output,
                replicate=setting.replicate,
                held_out=held_out,
                model_seconds=result.seconds,
                pcmb_seconds=max(finished.seconds - result.seconds, 0.0),
                file=file,
            )
        )
        # The table's curves are over time: an output off the time grid (a scalar, an axis
        # of its own) has its errors in the row only.
        blank = np.full(reference.times.size, np.nan)
        means.append(found.mean_curve if result.on_time(output) else blank)
        stds.append(found.std_curve if result.on_time(output) else blank)
    return rows, means, stds


def _table(
    plan: SweepPlan, finished: list[_Finished], reference: StudyResult, source: str
) -> SweepTable:
    """The rows and error curves of the finished settings against ``reference``."""
    outputs = _outputs(plan, reference, source)
    rows: list[SweepRow] = []
    means: list[np.ndarray] = []
    stds: list[np.ndarray] = []
    for setting, done in zip(plan.settings, finished, strict=True):
        found = _rows(setting, done, reference, outputs, f"{setting.stem}.h5")
        rows += found[0]
        means += found[1]
        stds += found[2]
    label = f"{source} ({reference.design.label}, {int(reference.status.size)} runs)"
    return SweepTable(
        tuple(rows),
        reference.times,
        np.reshape(means, (-1, reference.times.size)),
        np.reshape(stds, (-1, reference.times.size)),
        label,
        str(Path(source).resolve()),
        {output: noise_floor(reference, output) for output in outputs},
    )


def _run_setting(
    config: StudyConfig,
    setting: Setting,
    folder: Path,
    ledger: _Ledger,
    pool: Any,
    provenance: Mapping[str, str],
    *,
    fresh: bool,
    force: bool,
) -> _Finished:
    study = _study(config, setting)
    path = folder / f"{setting.stem}.h5"
    finished = ledger.finished(setting.stem, study, path, pool)
    if finished is not None:
        return finished
    journal = Path(f"{path}.journal")
    start = time.perf_counter()
    result = study.run(
        path,
        resume=not fresh and journal.exists(),
        fresh=fresh,
        force=force,
        progress=False,
        provenance=provenance,
        pool=pool,
    )
    seconds = time.perf_counter() - start
    ledger.add(setting.stem, study, seconds, pool)
    return _Finished(result, seconds)


def run_sweep(
    config: StudyConfig,
    folder: str | os.PathLike[str],
    *,
    reference: str | os.PathLike[str] | None = None,
    resume: bool = False,
    fresh: bool = False,
    force: bool = False,
    progress: bool | None = None,
    jobs: int | None = None,
    backend: str | None = None,
    address: str | None = None,
    command_line: str = "",
) -> SweepOutcome:
    """Run every setting of a config's sweep and measure it against the reference.

    Parameters
    ----------
    config:
        A validated config; its ``sweep:`` section (else the default sweep of
        :func:`pcmb.sweep.plan.default_sweep`) says what runs.
    folder:
        Where ``sweep.csv``, ``sweep.h5``, ``sweep.png`` and the settings' result files go.
    reference:
        A result file to measure against (instead of ``sweep.reference``, which is then
        not run).
    resume:
        Continue a sweep stopped midway in ``folder``.
    fresh:
        Start over: discard the ledger and the settings' journals a sweep stopped midway
        left in ``folder`` (see :meth:`pcmb.study.Study.run`).
    force:
        Overwrite files at the settings' result paths that are not pcmb results.
    progress:
        One progress line over the settings on stderr (default: when stderr is a terminal).
    jobs, backend:
        Override ``execution.jobs`` and ``execution.backend``.
    address:
        Overrides ``execution.address`` (``--address``) and implies backend dask; the
        settings then run on every thread of the cluster unless ``jobs`` is given.
    command_line:
        Stored with every result file.

    Raises
    ------
    UsageError
        No reference (neither ``sweep.reference`` nor ``reference``), a reference on another
        time grid or without the outputs, an unfinished sweep in ``folder`` without
        ``resume`` or ``fresh``, both of them, or another sweep running in ``folder`` (the
        message names its PID and command).
    MissingDependencyError
        matplotlib is missing (the chart needs it), before anything runs.
    ClusterError
        No dask scheduler answers at the address (``address`` or ``execution.address``).
    ModelRunError
        A setting's nodes failed and its policy does not allow going on; the finished
        settings are kept for ``resume``.
    """
    from pcmb.run.backends import open_pool
    from pcmb.store import load
    from pcmb.sweep.chart import draw_sweep, plotting

    if resume and fresh:
        raise UsageError("resume continues a sweep, fresh starts it over: give one")
    plotting()  # the chart needs matplotlib: say so before anything runs
    folder = Path(folder)
    plan = plan_sweep(config)
    if reference is None and plan.reference is None:
        raise UsageError(
            "no reference to measure against: set sweep.reference in the config or give "
            "--reference REF.h5"
        )
    given = None
    if reference is not None:
        given = load(reference)
        _check_reference(given, config, str(reference))
        _outputs(plan, given, str(reference))
    if jobs is not None or backend is not None or address is not None:
        changes = {
            # With an address, every thread of the cluster unless jobs is given.
            "jobs": jobs if address is not None else jobs or config.execution.jobs,
            "backend": "dask" if address is not None else backend or config.execution.backend,
            "address": address or config.execution.address,
        }
        config = config.model_copy(
            update={"execution": config.execution.model_copy(update=changes)}
        )
    with _holding(folder):
        ledger = _Ledger(folder, resume, fresh)
        provenance = {
            "config": config.source_text or "",
            "config_sha256": config.sha256,
            "command_line": command_line,
        }
        todo = ([] if given is not None or plan.reference is None else [plan.reference]) + list(
            plan.settings
        )
        show = sys.stderr.isatty() if progress is None else progress
        bar = Progress(len(todo), 0, sys.stderr if show else None, unit="settings")
        finished: list[_Finished] = []
        execution = config.execution
        key = "execution.address" if address is None else "--address"
        with open_pool(execution.backend, execution.jobs, execution.address, key=key) as pool:
            for setting in todo:
                finished.append(
                    _run_setting(
                        config, setting, folder, ledger, pool, provenance, fresh=fresh, force=force
                    )
                )
                bar.advance(1)
        bar.close()
        if given is None:
            given, finished = finished[0].result, finished[1:]
            source = str(folder / "reference.h5")
        else:
            source = str(reference)
        table = _table(plan, finished, given, source)
        csv_path, h5_path = write_sweep(table, folder)
        chart = draw_sweep(table, folder / "sweep.png")
        ledger.remove()
        files = (csv_path, h5_path, chart, *(folder / f"{s.stem}.h5" for s in plan.settings))
        return SweepOutcome(table, files)
