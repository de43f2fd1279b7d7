"""Durable file replacement, shared by the result store and the resume journal."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["replace_durably"]


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
