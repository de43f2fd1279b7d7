"""Durable file replacement, shared by the result store, the sweep's files and the journal."""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = [
    "durable_temporary",
    "process_running",
    "remove_stale_temporaries",
    "replace_durably",
    "write_durably",
]


def write_durably(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its folder (created if needed),
    moved into place by :func:`replace_durably`: ``path`` never holds a partial file. The
    file gets the mode the umask gives a new file (mkstemp's are private).

    The temporary, ``.<name>.<pid>.<random>.tmp``, is ``flock``-ed until it is in place: one
    left by a writer killed meanwhile is known to be stale (:func:`remove_stale_temporaries`).

    Raises
    ------
    OSError
        As the file system reports it; the temporary file is removed.
    """
    with durable_temporary(path) as (file, _):
        file.write(data)
        file.flush()


@contextlib.contextmanager
def durable_temporary(path: Path) -> Iterator[tuple[BinaryIO, Path]]:
    """The temporary file of :func:`write_durably` (its open handle and path), moved onto
    ``path`` when the block ends without an error and removed when it raises: for a writer
    that fills the file piece by piece (a streamed result file, by its path)."""
    temporary: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, name = tempfile.mkstemp(
            prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent
        )
        temporary = Path(name)
        with os.fdopen(handle, "wb") as file:
            fcntl.flock(file.fileno(), fcntl.LOCK_EX)
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(file.fileno(), 0o666 & ~umask)
            yield file, temporary
            file.flush()
            replace_durably(temporary, path)
    except BaseException:
        if temporary is not None:
            with contextlib.suppress(OSError):
                temporary.unlink(missing_ok=True)
        raise


def replace_durably(temporary: Path, path: Path) -> None:
    """Move a fully written ``temporary`` file onto ``path`` so that, even after a crash or a
    power loss, ``path`` holds either its old contents or the complete new file.

    The file's data is flushed to disk before the rename, and the rename itself is only
    durable once the directory entry is: both are fsynced. ``temporary`` must be in the same
    directory as ``path`` (a rename does not cross file systems).
    """
    with open(temporary, "rb") as written:
        os.fsync(written.fileno())
    os.replace(temporary, path)
    directory = os.open(Path(path).parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


def remove_stale_temporaries(path: Path) -> None:
    """Remove the temporaries :func:`write_durably` left beside ``path`` when its writer was
    killed (``kill -9``, a power loss) before moving them into place.

    Only the provably stale ones go: this user's regular files named like its temporaries
    whose writer process is gone (the pid in the name is not running) and whose lock nobody
    holds. Temporaries named without a pid (by earlier versions) go when nobody locks them.
    """
    pattern = re.compile(rf"\.{re.escape(path.name)}\.(?:(\d+)\.)?[a-z0-9_]{{8}}\.tmp")
    try:
        names = os.listdir(path.parent)
    except OSError:
        return
    for name in names:
        found = pattern.fullmatch(name)
        if found is None or (found[1] is not None and process_running(int(found[1]))):
            continue
        with contextlib.suppress(OSError):
            _remove_if_unlocked(path.parent / name)


def process_running(pid: int) -> bool:
    """Whether a process has this pid (another user's counts; a pid no system has does not)."""
    try:
        os.kill(pid, 0)  # no signal: only whether the process exists
    except (ProcessLookupError, OverflowError):
        return False
    except PermissionError:  # another user's process
        pass
    return True


def _remove_if_unlocked(temporary: Path) -> None:
    """Remove ``temporary`` if it is this user's regular file and nobody holds its lock."""
    handle = os.open(temporary, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        status = os.fstat(handle)
        if not stat.S_ISREG(status.st_mode) or status.st_uid != os.geteuid():
            return
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # its writer is still at work
            return
        temporary.unlink()
    finally:
        os.close(handle)
