"""A crash-safe journal of finished model runs, so that an interrupted study can resume.

A directory beside the output (``OUT.h5.journal/``): ``journal.json`` says what it belongs
to (a :class:`~pcmb.run.fingerprint.Fingerprint`: a settings digest and a table of the
model files' digests), each ``record-NNNNNN.npz`` holds one finished chunk; every file is
written atomically. ``lock`` holds an exclusive ``flock`` (and the holder's PID) for as long
as a process writes the journal, so two runs never write the same journal.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import time
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.errors import ResultFileError, UsageError
from pcmb.run.files import replace_durably
from pcmb.run.fingerprint import Fingerprint, changed_files
from pcmb.run.lock import FolderLock
from pcmb.run.output import write_error
from pcmb.run.status import ModelTraceback, Status

__all__ = ["FRESH", "Journal"]

_FORMAT = 3
_META = "journal.json"
_LOCK = "lock"
_RECORD = re.compile(r"record-(\d{6,})\.npz")
_TEMP_PREFIX = ".tmp-"
#: The folders of a journal's later parts (an adaptive design's rounds, the held-out runs'
#: batches).
_PART = re.compile(r"round-\d+|validation(-\d+)?")
#: How to start over when a journal cannot be continued (the flag of pcmb run and sweep).
FRESH = "start over with --fresh"


def _strangers(directory: Path, parts: bool = True) -> list[Path]:
    """What ``directory`` holds that a journal does not: its files, and its part folders
    (when ``parts``) holding a journal's files."""
    found = []
    for entry in sorted(directory.iterdir()):
        if entry.is_symlink():
            found.append(entry)
        elif parts and entry.is_dir() and _PART.fullmatch(entry.name):
            found += _strangers(entry, parts=False)
        elif not entry.is_file() or not (
            entry.name in (_META, _LOCK)
            or _RECORD.fullmatch(entry.name)
            or entry.name.startswith(_TEMP_PREFIX)
        ):
            found.append(entry)
    return found


def _delete(directory: Path, lock: FolderLock | None) -> None:
    """Delete a journal ``directory``, then let go of its ``lock``.

    The directory is first renamed aside, so that a run starting meanwhile finds no journal
    (or makes a new one) instead of a half-deleted one.
    """
    doomed = directory.with_name(f".{directory.name}.removed-{os.getpid()}-{time.monotonic_ns()}")
    try:
        os.rename(directory, doomed)
        shutil.rmtree(doomed, ignore_errors=False)
    except FileNotFoundError:
        pass
    finally:
        if lock is not None:
            lock.release()


class Journal:
    """Open the journal in ``directory``, creating it if it does not exist yet, and lock it.

    The lock (an exclusive ``flock`` on ``<directory>/lock``, which holds the PID) is held
    until :meth:`remove` or :meth:`close`, until every journal of the directory opened by
    this process is gone, or until the process ends, however it ends. Journals of one
    directory opened by one process share the lock.

    Parameters
    ----------
    directory:
        The journal directory (created with its parents when missing).
    fingerprint:
        Identifies everything that changes the results: a
        :class:`~pcmb.run.fingerprint.Fingerprint` (a settings digest and the digests of the
        model's files) or a plain string (a digest, no files). An existing journal is only
        reopened for the same digest and the same file contents.
    n_nodes:
        N, the number of nodes of the study.
    outputs:
        Names of the recorded outputs, in order.
    n_times:
        T, the length of the output time grid: the columns of every output; or each
        output's columns (T on time, K on its own axis, 1 for a scalar, see
        :mod:`pcmb.axes`).

    Raises
    ------
    UsageError
        If another process holds the journal's lock ("another pcmb run (PID N) is writing
        ..."), or if a model file changed since the journal was written (the message names
        it): the journal is intact, but this run cannot continue it.
    ResultFileError
        If the directory holds a journal written for a different digest, node count, output
        list or time grid, or by another journal format, or something that is not a pcmb
        journal.
    ValueError
        If ``n_nodes`` or ``n_times`` is not positive, or ``outputs`` is empty or repeats a name.
    """

    def __init__(
        self,
        directory: str | os.PathLike[str],
        fingerprint: str | Fingerprint,
        n_nodes: int,
        outputs: Sequence[str],
        n_times: int | Sequence[int],
    ) -> None:
        outputs = tuple(outputs)
        widths = (
            tuple(int(w) for w in n_times)
            if isinstance(n_times, Sequence)
            else (int(n_times),) * len(outputs)
        )
        if int(n_nodes) < 1 or min(widths, default=1) < 1 or len(widths) != len(outputs):
            raise ValueError(
                f"n_nodes and n_times must be positive (one per output), got {n_nodes} and "
                f"{n_times}"
            )
        if not outputs or len(set(outputs)) != len(outputs):
            raise ValueError(f"outputs must be non-empty and distinct, got {list(outputs)}")
        if not isinstance(fingerprint, Fingerprint):
            fingerprint = Fingerprint(str(fingerprint))
        self.directory = Path(directory)
        self.fingerprint = fingerprint.digest
        self.files = dict(sorted(fingerprint.files.items()))
        self.n_nodes = int(n_nodes)
        self.outputs = outputs
        self.widths = widths
        self._next_record = 0
        self._lock: FolderLock | None = None
        try:
            self._open()
        except BaseException:
            self.close()  # the lock goes with the last journal holding it, not this one's
            raise

    @staticmethod
    def exists(directory: str | os.PathLike[str]) -> bool:
        """Whether ``directory`` holds a journal (with or without records)."""
        return (Path(directory) / _META).is_file()

    @staticmethod
    def check_free(directory: str | os.PathLike[str]) -> None:
        """Raise if another process is writing the journal in ``directory`` (holds its lock).

        Raises
        ------
        UsageError
            Naming the PID of the run that holds it.
        """
        FolderLock.check_free(Path(directory) / _LOCK, str(directory))

    @staticmethod
    def discard(directory: str | os.PathLike[str]) -> None:
        """Delete the journal in ``directory`` whatever its state (unreadable, of another
        config or format), to start a run over; nothing to do when there is none.

        Raises
        ------
        UsageError
            Another process holds its lock (a live run writes it): nothing is deleted.
        ResultFileError
            ``directory`` holds something a journal does not (a file of another name, a
            link, a folder other than a round's or the held-out runs'): nothing is deleted.
        """
        directory = Path(directory)
        if not directory.is_dir() or directory.is_symlink():
            if directory.exists() or directory.is_symlink():
                raise ResultFileError(
                    f"{directory} is not a journal folder; pcmb leaves it alone: move it away "
                    "or give another output (-o)"
                )
            return
        try:
            lock = FolderLock.acquire(directory / _LOCK, str(directory))
        except OSError as error:  # a read-only file system, a missing permission
            raise write_error(error, directory, "journal", "delete it by hand") from error
        strangers = _strangers(directory)
        if strangers:
            lock.release()
            named = ", ".join(str(p.relative_to(directory)) for p in strangers[:3])
            more = f" and {len(strangers) - 3} more" if len(strangers) > 3 else ""
            raise ResultFileError(
                f"{directory} holds what a pcmb journal does not ({named}{more}); pcmb does "
                "not discard it: move it away or give another output (-o)"
            )
        _delete(directory, lock)

    # -- opening -------------------------------------------------------------------------------

    def _metadata(self) -> dict[str, object]:
        return {
            "format": _FORMAT,
            "fingerprint": self.fingerprint,
            "n_nodes": self.n_nodes,
            "outputs": list(self.outputs),
            "widths": list(self.widths),
            "files": self.files,
        }

    def _open(self) -> None:
        if self.directory.exists() and not self.directory.is_dir():
            raise ResultFileError(f"journal {self.directory} exists and is not a directory")
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            self._lock = FolderLock.acquire(self.directory / _LOCK, str(self.directory))
        except OSError as error:  # a read-only or full file system, a missing permission
            raise write_error(
                error, self.directory, "journal", "give another output (-o) or free space"
            ) from error
        records = self._record_paths()
        meta_path = self.directory / _META
        if not meta_path.is_file():
            if records:
                raise ResultFileError(
                    f"journal {self.directory} has records but no {_META}: it is not a pcmb "
                    f"journal; delete it or {FRESH}"
                )
            meta = json.dumps(self._metadata(), indent=1).encode()
            self._write_atomically(meta_path, lambda handle: handle.write(meta))
            return
        try:
            found = json.loads(meta_path.read_text())
        except (OSError, ValueError) as exc:
            raise ResultFileError(
                f"journal {self.directory}: cannot read {_META} ({exc}); delete it or {FRESH}"
            ) from exc
        if not isinstance(found, dict):
            found = {}
        if found.get("format") != _FORMAT:
            raise ResultFileError(
                f"journal {self.directory} was written by another version of pcmb (journal "
                f"format {found.get('format')!r}, this one reads {_FORMAT}); delete it or {FRESH}"
            )
        if found.get("fingerprint") != self.fingerprint:
            raise ResultFileError(
                f"journal {self.directory} was written for a different config; delete it or "
                f"{FRESH} (the model, inputs, method, time grid, outputs or chunk_size differ)"
            )
        expected = self._metadata()
        differing = [key for key in expected if key != "files" and found.get(key) != expected[key]]
        if differing:
            detail = ", ".join(f"{k}: {found.get(k)!r} != {expected[k]!r}" for k in differing)
            raise ResultFileError(
                f"journal {self.directory} does not match this run ({detail}); delete it or {FRESH}"
            )
        recorded = found.get("files")
        changed = changed_files(recorded if isinstance(recorded, dict) else {}, self.files)
        if changed:
            what = (
                f"model file {changed[0]} has"
                if len(changed) == 1
                else f"model files {', '.join(changed)} have"
            )
            raise UsageError(
                f"cannot resume: {what} changed since {self.directory} was written, so its "
                "finished nodes may not be what this run would compute; restore the old "
                f"contents, or delete {self.directory} or {FRESH}"
            )
        if records:
            self._next_record = int(_RECORD.fullmatch(records[-1].name).group(1)) + 1

    def _record_paths(self) -> list[Path]:
        paths = [p for p in self.directory.iterdir() if _RECORD.fullmatch(p.name)]
        return sorted(paths, key=lambda p: int(_RECORD.fullmatch(p.name).group(1)))

    # -- writing -------------------------------------------------------------------------------

    def _write_atomically(self, path: Path, write: Callable[[BinaryIO], object]) -> None:
        """Write ``path`` through ``write(handle)`` so that it appears complete or not at all."""
        temp = self.directory / f"{_TEMP_PREFIX}{os.getpid()}-{path.name}"
        try:
            with open(temp, "wb") as handle:
                write(handle)
            replace_durably(temp, path)
        except OSError as error:
            if error.errno is None:  # not the operating system's answer: not ours to name
                raise
            # A full disk (ENOSPC, EDQUOT), a file system turned read-only, ...: the records
            # written so far stay; only this one is lost, and its partial file is removed.
            with contextlib.suppress(OSError):
                temp.unlink(missing_ok=True)
            raise write_error(
                error,
                path,
                "journal record" if _RECORD.fullmatch(path.name) else "journal file",
                f"the nodes finished before are kept in {self.directory}; free some space "
                "and run again with --resume",
            ) from error

    def record(
        self,
        indices: ArrayLike,
        values: Mapping[str, ArrayLike],
        status: ArrayLike,
        messages: Mapping[int, str] | None = None,
        tracebacks: Mapping[int, ModelTraceback] | None = None,
    ) -> None:
        """Persist one finished chunk durably and atomically.

        Parameters
        ----------
        indices:
            (B,) node indices in the full node set, distinct.
        values:
            Output name -> (B, T) values, for every output of the journal (rows of failed
            nodes are stored as given, normally NaN).
        status:
            (B,) int, ``Status.OK`` or ``Status.FAILED`` for each node.
        messages:
            Node index -> failure message, for the failed nodes.
        tracebacks:
            Node index -> where the model's code raised, for the failed nodes where it did
            (kept in the record as JSON, :meth:`ModelTraceback.describe`, "" for the others).

        Raises
        ------
        ValueError
            If the shapes, indices, status codes or output names do not match the journal.
        ResultFileError
            If this process no longer holds the journal's lock (it was closed or removed, or
            its folder was deleted from outside).
        """
        if self._lock is None or not self._lock.valid():
            raise ResultFileError(
                f"journal {self.directory} is no longer locked by this process (closed, or "
                "deleted from outside); nothing more is written to it"
            )
        idx = np.asarray(indices, dtype=np.int64)
        codes = np.asarray(status, dtype=np.int8)
        if idx.ndim != 1 or idx.size == 0 or codes.shape != idx.shape:
            raise ValueError(
                f"indices and status must be equal (B,) arrays, got {idx.shape} and {codes.shape}"
            )
        if idx.min() < 0 or idx.max() >= self.n_nodes or np.unique(idx).size != idx.size:
            raise ValueError(f"indices must be distinct and in [0, {self.n_nodes})")
        if not np.isin(codes, (Status.OK, Status.FAILED)).all():
            raise ValueError("status must be Status.OK (1) or Status.FAILED (2) for every node")
        if set(values) != set(self.outputs):
            raise ValueError(f"values must hold exactly the outputs {list(self.outputs)}")
        arrays = [np.asarray(values[name], dtype=np.float64) for name in self.outputs]
        for name, array, width in zip(self.outputs, arrays, self.widths, strict=True):
            if array.shape != (idx.size, width):
                raise ValueError(f"output {name!r} must have shape ({idx.size}, {width})")
        stacked = np.concatenate(arrays, axis=1)
        messages = messages or {}
        text = np.array([messages.get(int(i), "") for i in idx], dtype=np.str_)
        raised = [(tracebacks or {}).get(int(i)) for i in idx]
        described = np.array([json.dumps(t.describe()) if t else "" for t in raised], dtype=np.str_)
        path = self.directory / f"record-{self._next_record:06d}.npz"
        self._write_atomically(
            path,
            lambda handle: np.savez(
                handle,
                indices=idx,
                status=codes,
                values=stacked,
                messages=text,
                tracebacks=described,
            ),
        )
        self._next_record += 1

    # -- reading -------------------------------------------------------------------------------

    def _read(self, path: Path, keys: Sequence[str]) -> list[NDArray]:
        """Arrays ``keys`` of record ``path`` (only those are read), checked against the
        journal's shape."""
        try:
            # Opened here, not by np.load, so that a damaged file is closed on error too.
            with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
                found = [data[key] for key in keys]
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            raise ResultFileError(
                f"journal record {path} is unreadable ({exc}); delete the journal or {FRESH}"
            ) from exc
        named = dict(zip(keys, found, strict=True))
        idx = named["indices"]
        shapes = {"status": idx.shape, "values": (idx.size, sum(self.widths))}
        if any(named[key].shape != shape for key, shape in shapes.items() if key in named):
            raise ResultFileError(f"journal record {path} does not match the journal's shape")
        return found

    def _owners(self) -> tuple[list[Path], NDArray[np.int64], NDArray[np.int8]]:
        """The record paths, and per node the position of its latest record among them (-1:
        none) and its latest status; reads no values."""
        paths = self._record_paths()
        owner = np.full(self.n_nodes, -1, dtype=np.int64)
        status = np.zeros(self.n_nodes, dtype=np.int8)
        for k, path in enumerate(paths):
            idx, codes = self._read(path, ("indices", "status"))
            owner[idx], status[idx] = k, codes
        return paths, owner, status

    def statuses(self) -> tuple[NDArray[np.int64], NDArray[np.int8]]:
        """:meth:`completed` without the values: (K,) sorted node indices, (K,) statuses."""
        _, owner, status = self._owners()
        indices = np.flatnonzero(owner >= 0)
        return indices, status[indices]

    def chunks(
        self,
    ) -> Iterator[tuple[NDArray[np.int64], dict[str, NDArray[np.float64]], NDArray[np.int8]]]:
        """Every journaled node once, with its latest values and status, in increasing node
        order, a run of consecutive nodes of one record at a time: a pass that never holds
        more than two records (a chunk, and the nodes re-run alone within it on a resume).

        Yields
        ------
        indices, values, status
            (B,) consecutive node indices, output name -> (B, T) values, (B,) statuses.
        """
        paths, owner, status = self._owners()
        known = np.flatnonzero(owner >= 0)
        breaks = np.flatnonzero((np.diff(owner[known]) != 0) | (np.diff(known) != 1)) + 1
        ends = np.cumsum([0, *self.widths]).tolist()
        held: dict[int, tuple[NDArray[np.int64], NDArray[np.float64]]] = {}
        for segment in np.split(known, breaks) if known.size else ():
            k = int(owner[segment[0]])
            if k not in held:
                if len(held) == 2:
                    del held[next(iter(held))]
                idx, values = self._read(paths[k], ("indices", "values"))
                order = np.argsort(idx)
                held[k] = (idx[order], values[order])
            idx, values = held[k]
            rows = values[np.searchsorted(idx, segment)]
            bounds = zip(self.outputs, ends, ends[1:], strict=False)
            yield segment, {name: rows[:, a:b] for name, a, b in bounds}, status[segment]

    def _latest(self) -> dict[int, tuple[int, NDArray[np.float64], str]]:
        """Node index -> (status, (W,) values of every output side by side, message), later
        records winning."""
        latest: dict[int, tuple[int, NDArray[np.float64], str]] = {}
        for path in self._record_paths():
            idx, codes, values, text = self._read(path, ("indices", "status", "values", "messages"))
            for i, code, row, message in zip(idx, codes, values, text, strict=True):
                latest[int(i)] = (int(code), row, str(message))
        return latest

    def completed(
        self,
    ) -> tuple[NDArray[np.int64], dict[str, NDArray[np.float64]], NDArray[np.int8]]:
        """Every journaled node, with its latest values and status.

        Returns
        -------
        indices:
            (K,) sorted node indices.
        values:
            Output name -> (K, T) values.
        status:
            (K,) ``Status.OK`` or ``Status.FAILED``.

        Raises
        ------
        ResultFileError
            If a record cannot be read or does not match the journal.
        """
        latest = self._latest()
        indices = np.array(sorted(latest), dtype=np.int64)
        stacked = np.empty((indices.size, sum(self.widths)))
        status = np.empty(indices.size, dtype=np.int8)
        for row, i in enumerate(indices):
            status[row], stacked[row], _ = latest[int(i)]
        ends = np.cumsum([0, *self.widths]).tolist()
        values = {
            name: stacked[:, a:b] for name, a, b in zip(self.outputs, ends, ends[1:], strict=False)
        }
        return indices, values, status

    def messages(self) -> dict[int, str]:
        """Node index -> failure message, for the nodes whose latest record is a failure.

        Raises
        ------
        ResultFileError
            If a record cannot be read or does not match the journal.
        """
        return {i: text for i, (code, _, text) in self._latest().items() if code == Status.FAILED}

    def remove(self) -> None:
        """Delete the journal directory (once the result file is safely written), then let go
        of the lock (for every journal of this process too: nothing is left to guard)."""
        _delete(self.directory, self._lock)
        self._lock = None

    def close(self) -> None:
        """Stop writing: the journal can still be read, not written. The lock is released
        once no journal of this process holds it (at once, for a journal opened alone)."""
        self._lock = None
