"""Durable file replacement, shared by the result store, the sweep's files and the journal."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["replace_durably", "write_durably"]


def write_durably(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its folder (created if needed),
    moved into place by :func:`replace_durably`: ``path`` never holds a partial file. The
    file gets the mode the umask gives a new file (mkstemp's are private).

    Raises
    ------
    OSError
        As the file system reports it; the temporary file is removed.
    """
    temporary: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        temporary = Path(name)
        with os.fdopen(handle, "wb") as file:
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(file.fileno(), 0o666 & ~umask)
            file.write(data)
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
