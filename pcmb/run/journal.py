"""A crash-safe journal of finished model runs, so that an interrupted study can resume.

A directory beside the output (``OUT.h5.journal/``): ``journal.json`` says what it belongs
to, each ``record-NNNNNN.npz`` holds one finished chunk; every file is written atomically.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.errors import ResultFileError
from pcmb.result import Status
from pcmb.run.files import replace_durably

__all__ = ["Journal"]

_FORMAT = 1
_META = "journal.json"
_RECORD = re.compile(r"record-(\d{6,})\.npz")
_TEMP_PREFIX = ".tmp-"


class Journal:
    """Open the journal in ``directory``, creating it if it does not exist yet.

    Parameters
    ----------
    directory:
        The journal directory (created with its parents when missing).
    fingerprint:
        Identifies everything that changes the results: the config hash plus, for example, an
        explicit chunk size. An existing journal is only reopened for the same fingerprint.
    n_nodes:
        N, the number of nodes of the study.
    outputs:
        Names of the recorded outputs, in order.
    n_times:
        T, the length of the output time grid.

    Raises
    ------
    ResultFileError
        If the directory holds a journal written for a different fingerprint, node count,
        output list or time grid ("delete it or drop --resume"), or something that is not a
        pcmb journal.
    ValueError
        If ``n_nodes`` or ``n_times`` is not positive, or ``outputs`` is empty or repeats a name.
    """

    def __init__(
        self,
        directory: str | os.PathLike[str],
        fingerprint: str,
        n_nodes: int,
        outputs: Sequence[str],
        n_times: int,
    ) -> None:
        outputs = tuple(outputs)
        if int(n_nodes) < 1 or int(n_times) < 1:
            raise ValueError(f"n_nodes and n_times must be positive, got {n_nodes} and {n_times}")
        if not outputs or len(set(outputs)) != len(outputs):
            raise ValueError(f"outputs must be non-empty and distinct, got {list(outputs)}")
        self.directory = Path(directory)
        self.fingerprint = str(fingerprint)
        self.n_nodes = int(n_nodes)
        self.outputs = outputs
        self.n_times = int(n_times)
        self._next_record = 0
        self._open()

    @staticmethod
    def exists(directory: str | os.PathLike[str]) -> bool:
        """Whether ``directory`` holds a journal (with or without records)."""
        return (Path(directory) / _META).is_file()

    # -- opening -------------------------------------------------------------------------------

    def _metadata(self) -> dict[str, object]:
        return {
            "format": _FORMAT,
            "fingerprint": self.fingerprint,
            "n_nodes": self.n_nodes,
            "outputs": list(self.outputs),
            "n_times": self.n_times,
        }

    def _open(self) -> None:
        if self.directory.exists() and not self.directory.is_dir():
            raise ResultFileError(f"journal {self.directory} exists and is not a directory")
        self.directory.mkdir(parents=True, exist_ok=True)
        records = self._record_paths()
        meta_path = self.directory / _META
        if not meta_path.is_file():
            if records:
                raise ResultFileError(
                    f"journal {self.directory} has records but no {_META}: it is not a pcmb "
                    "journal; delete it or drop --resume"
                )
            meta = json.dumps(self._metadata(), indent=1).encode()
            self._write_atomically(meta_path, lambda handle: handle.write(meta))
            return
        try:
            found = json.loads(meta_path.read_text())
        except (OSError, ValueError) as exc:
            raise ResultFileError(
                f"journal {self.directory}: cannot read {_META} ({exc}); delete it or drop --resume"
            ) from exc
        expected = self._metadata()
        if not isinstance(found, dict) or found.get("fingerprint") != self.fingerprint:
            raise ResultFileError(
                f"journal {self.directory} was written for a different config; "
                "delete it or drop --resume"
            )
        differing = [key for key in expected if found.get(key) != expected[key]]
        if differing:
            detail = ", ".join(f"{k}: {found.get(k)!r} != {expected[k]!r}" for k in differing)
            raise ResultFileError(
                f"journal {self.directory} does not match this run ({detail}); "
                "delete it or drop --resume"
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
        with open(temp, "wb") as handle:
            write(handle)
        replace_durably(temp, path)

    def record(
        self,
        indices: ArrayLike,
        values: Mapping[str, ArrayLike],
        status: ArrayLike,
        messages: Mapping[int, str] | None = None,
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

        Raises
        ------
        ValueError
            If the shapes, indices, status codes or output names do not match the journal.
        """
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
        stacked = np.stack([np.asarray(values[name], dtype=np.float64) for name in self.outputs], 1)
        if stacked.shape != (idx.size, len(self.outputs), self.n_times):
            raise ValueError(f"each output must have shape ({idx.size}, {self.n_times})")
        messages = messages or {}
        text = np.array([messages.get(int(i), "") for i in idx], dtype=np.str_)
        path = self.directory / f"record-{self._next_record:06d}.npz"
        self._write_atomically(
            path,
            lambda handle: np.savez(
                handle, indices=idx, status=codes, values=stacked, messages=text
            ),
        )
        self._next_record += 1

    # -- reading -------------------------------------------------------------------------------

    def _latest(self) -> dict[int, tuple[int, NDArray[np.float64], str]]:
        """Node index -> (status, (n_outputs, T) values, message), later records winning."""
        latest: dict[int, tuple[int, NDArray[np.float64], str]] = {}
        shape = (len(self.outputs), self.n_times)
        for path in self._record_paths():
            try:
                # Opened here, not by np.load, so that a damaged file is closed on error too.
                with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
                    idx, codes = data["indices"], data["status"]
                    values, text = data["values"], data["messages"]
            except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
                raise ResultFileError(
                    f"journal record {path} is unreadable ({exc}); delete the journal or drop "
                    "--resume"
                ) from exc
            if values.shape != (idx.size, *shape) or codes.shape != idx.shape:
                raise ResultFileError(f"journal record {path} does not match the journal's shape")
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
        stacked = np.empty((indices.size, len(self.outputs), self.n_times))
        status = np.empty(indices.size, dtype=np.int8)
        for row, i in enumerate(indices):
            status[row], stacked[row], _ = latest[int(i)]
        values = {name: stacked[:, k, :] for k, name in enumerate(self.outputs)}
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
        """Delete the journal directory (once the result file is safely written)."""
        shutil.rmtree(self.directory, ignore_errors=False)
