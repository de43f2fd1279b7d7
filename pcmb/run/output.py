"""Where a run writes: checking the output before anything runs, and naming write failures.

Every problem with the place a result goes (a folder that cannot be made or written, an
output path that is a folder, a full disk, a read-only file system, a quota) is a
:class:`~pcmb.errors.ResultFileError` (exit 2) naming the path and the problem: found
before the first node runs when it can be, and otherwise, when a journal record or the
result file cannot be written, without losing a finished node (the journal stays, so
``--resume`` writes the file once the problem is fixed).
"""

from __future__ import annotations

import errno
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from pcmb.errors import ResultFileError
from pcmb.run.files import remove_stale_temporaries

__all__ = ["SizeEstimate", "check_output", "estimate_size", "format_bytes", "write_error"]

# A journal record or result file holds more than its float arrays: HDF5 object headers,
# dimension scales and attributes (the config text), npz/zip headers. Measured on the linear
# test study (16 nodes × 5 times, 2 outputs) the overhead is about 60 kB for the HDF5 file;
# on the quarter car (216 × 301) it is a few percent.
_FILE_OVERHEAD = 128 * 1024
_RECORD_OVERHEAD = 4 * 1024
_CHUNK_ESTIMATE = 16  # chunks of a run (ceil(N / 16) nodes each, see the executor)

_NAMES = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EISDIR: "is a directory",
    errno.ENOTDIR: "a component of the path is not a directory",
}
_SPACE = (errno.ENOSPC, errno.EDQUOT)


@dataclass(frozen=True)
class SizeEstimate:
    """Bytes a run needs on the output's file system, at most (an upper estimate).

    ``result``: the HDF5 file; ``journal``: the journal of the nodes still to run, which
    stays until the result file is safely written, so both coexist at the end of a run.
    """

    result: int
    journal: int

    @property
    def total(self) -> int:
        return self.result + self.journal


def estimate_size(
    n_nodes: int,
    n_times: int,
    n_outputs: int,
    n_inputs: int,
    n_terms: int | None = None,
    *,
    journaled: int = 0,
) -> SizeEstimate:
    """An upper estimate of the space a run writes (8-byte floats throughout).

    Per output the result file holds the values (N × T), the chaos coefficients (S × T,
    with S ≤ N terms: ``n_terms``, else N), first and total Sobol' indices (2 n × T) and
    mean, std, nominal and the analysis bands (a few T each, counted as 8 T); plus the nodes
    (3 N n) and a fixed allowance for HDF5 metadata and the stored config. The journal holds
    the values once more (N × T per output, plus a small header per chunk record), minus
    ``journaled`` bytes already written by an interrupted run.
    """
    n, t, k = int(n_nodes), int(n_times), int(n_outputs)
    terms = n if n_terms is None else int(n_terms)
    per_output = (n * t + terms * t + 2 * int(n_inputs) * t + 8 * t) * 8
    result = k * per_output + 3 * n * int(n_inputs) * 8 + _FILE_OVERHEAD
    journal = k * n * t * 8 + min(n, _CHUNK_ESTIMATE) * _RECORD_OVERHEAD + n * 8 * 2
    return SizeEstimate(result=result, journal=max(0, journal - int(journaled)))


def format_bytes(size: float) -> str:
    """``1234567`` -> ``"1.2 MB"`` (powers of 1000)."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(size) < 1000 or unit == "TB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1000
    raise AssertionError("unreachable")


def write_error(
    error: OSError, path: str | os.PathLike[str], what: str, hint: str = ""
) -> ResultFileError:
    """A :class:`ResultFileError` for an ``OSError`` while writing ``what`` at ``path``:
    names the path, the problem and its errno symbol (``ENOSPC``), then ``hint``."""
    code = error.errno
    symbol = errno.errorcode.get(code, "") if code is not None else ""
    reason = _NAMES.get(code) or error.strerror or str(error)
    where = error.filename if error.filename is not None else path
    detail = f"{reason} ({symbol})" if symbol else reason
    message = f"cannot write {what} {path}: {detail}"
    if str(where) != str(path):
        message += f" at {where}"
    if code in _SPACE and not hint:
        hint = "free some space and run again"
    return ResultFileError(f"{message}; {hint}" if hint else message)


def _existing_ancestor(folder: Path) -> Path:
    """The nearest folder of ``folder`` (itself included) that exists."""
    current = folder
    while not current.exists() and current != current.parent:
        current = current.parent
    return current


def _journal_bytes(journal: Path) -> int:
    try:
        return sum(p.stat().st_size for p in journal.iterdir() if p.is_file())
    except OSError:
        return 0


def check_output(
    path: str | os.PathLike[str], estimate: SizeEstimate | None = None, *, create: bool = False
) -> int | None:
    """Check, before anything runs, that a run can write ``path`` and its journal.

    The output must not be a folder; its folder must exist or be creatable (every existing
    ancestor a folder), writable; its journal (``<path>.journal``) must be a folder if it
    exists; and the file system must have room for ``estimate`` (the bytes an existing
    journal already holds are not asked for again). With ``create`` the folder is created
    and writing is probed by creating and deleting a temporary file in it (``pcmb run``);
    without, nothing is created and writability is asked of the operating system
    (``os.access``; ``pcmb validate``). With ``create`` the temporaries of ``path`` that a
    killed writer left are removed too (:func:`~pcmb.run.files.remove_stale_temporaries`).

    Returns
    -------
    int or None
        The free bytes on the output's file system (None when unknown).

    Raises
    ------
    ResultFileError
        Naming the path and the problem.
    """
    path = Path(path)
    if path.is_dir():
        raise ResultFileError(f"output {path} is a directory; give a file name (e.g. -o out.h5)")
    folder = path.parent
    journal = Path(f"{path}.journal")
    if journal.exists() and not journal.is_dir():
        raise ResultFileError(f"journal {journal} exists and is not a directory; remove it")
    ancestor = _existing_ancestor(folder)
    if not ancestor.is_dir():
        raise ResultFileError(
            f"cannot write output {path}: {ancestor} is a file, not a folder "
            f"({errno.errorcode[errno.ENOTDIR]})"
        )
    if create:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            handle, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
            os.close(handle)
            os.unlink(probe)
        except OSError as error:
            raise write_error(error, path, "output", _fix(error)) from error
        remove_stale_temporaries(path)  # a killed run's last write: its space counts as free
    elif not os.access(ancestor, os.W_OK | os.X_OK):
        what = "" if ancestor == folder else f" (its folder {folder} would be made in {ancestor})"
        raise ResultFileError(
            f"cannot write output {path}: folder {ancestor} is not writable{what}; "
            "give another output (-o) or fix its permissions"
        )
    try:
        stats = os.statvfs(folder if folder.is_dir() else ancestor)
    except OSError:
        return None
    free = stats.f_bavail * stats.f_frsize
    if estimate is not None:
        kept = _journal_bytes(journal) if journal.is_dir() else 0
        need = estimate.result + max(0, estimate.journal - kept)
        if need > free:
            raise ResultFileError(
                f"not enough space for output {path}: the run needs about {format_bytes(need)} "
                f"(result file {format_bytes(estimate.result)} + journal "
                f"{format_bytes(max(0, estimate.journal - kept))}), {format_bytes(free)} free "
                f"on its file system ({errno.errorcode[errno.ENOSPC]}); free some space or "
                "give another output (-o)"
            )
    return free


def _fix(error: OSError) -> str:
    if error.errno in _SPACE:
        return "free some space or give another output (-o)"
    return "give another output (-o) or fix the folder's permissions"
