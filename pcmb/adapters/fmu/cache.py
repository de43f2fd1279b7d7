"""The per-user cache of extracted FMUs, trusted only once checked.

An FMU's binaries (and a pythonfmu FMU's Python code) run inside the worker that loads them,
so the folder they are loaded from must hold the archive's files as they are in the archive,
put there by this user. The cache lives in the user's cache folder (``platformdirs.user_cache_dir``:
``$XDG_CACHE_HOME/pcmb/fmu`` or ``~/.cache/pcmb/fmu`` on Linux), never in a folder shared
with other users; its folders are made private (mode 0700). Before every use:

- the cache folders (``pcmb`` and ``pcmb/fmu``) and the entry must be real folders (not
  symbolic links) owned by this user and writable by no one else, or the FMU is refused;
- the entry must be private (mode 0700) and hold every file of the archive as a regular
  file (no symbolic link on its way) with the size and SHA-256 of its archive member; an
  entry that does not (half deleted, tampered with) is replaced by a fresh extraction.
  Other files in it are left alone: an FMU may write into its own folder while it runs.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import tempfile
import zipfile
from pathlib import Path
from typing import IO

import platformdirs

__all__ = ["CacheError", "cache_root", "extracted"]

_CHUNK = 1 << 20
_APP = "pcmb"


class CacheError(Exception):
    """The cache cannot be used (not this user's, open to others, unwritable), or an archive
    cannot be extracted into it; the message says which folder and why."""


def _sha256(handle: IO[bytes]) -> tuple[int, str]:
    """Size and SHA-256 of what ``handle`` (a binary file) reads."""
    digest, size = hashlib.sha256(), 0
    while block := handle.read(_CHUNK):
        digest.update(block)
        size += len(block)
    return size, digest.hexdigest()


def _private(folder: Path) -> None:
    """Raise unless ``folder`` is a real folder owned by this user and writable by no one else."""
    info = os.lstat(folder)
    if not stat.S_ISDIR(info.st_mode):
        raise CacheError(f"the FMU cache folder {folder} is not a folder (a link, a file)")
    if info.st_uid != os.getuid():
        raise CacheError(
            f"the FMU cache folder {folder} is owned by uid {info.st_uid}, not by this user "
            f"(uid {os.getuid()}): pcmb loads no code from it; remove it, or set "
            "XDG_CACHE_HOME to a folder of your own"
        )
    if info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise CacheError(
            f"the FMU cache folder {folder} is writable by other users (mode "
            f"{stat.S_IMODE(info.st_mode):04o}): pcmb loads no code from it; make it private "
            f"(chmod 700 {folder}) or remove it"
        )


def cache_root() -> Path:
    """The cache folder of extracted FMUs, made private if new, checked if not.

    Raises
    ------
    CacheError
        A folder of it is not this user's, is writable by others, or cannot be made.
    """
    top = Path(platformdirs.user_cache_dir(_APP))
    root = top / "fmu"
    for folder in (top, root):
        try:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError as error:
            raise CacheError(
                f"cannot make the FMU cache folder {folder} ({error.strerror}); set "
                "XDG_CACHE_HOME to a writable folder of your own"
            ) from error
        _private(folder)
    return root


def _target(name: str) -> Path:
    """Where :meth:`zipfile.ZipFile.extractall` puts member ``name`` (relative)."""
    parts = [part for part in name.split("/") if part not in ("", ".", "..")]
    return Path(*parts)


def _members(archive: zipfile.ZipFile) -> dict[Path, tuple[int, str]]:
    """Relative path -> (size, SHA-256) of every file member of ``archive``."""
    members = {}
    for info in archive.infolist():
        if info.is_dir():
            continue
        if "\\" in info.filename or ":" in info.filename:
            raise CacheError(f"the archive holds an illegal file name {info.filename!r}")
        with archive.open(info) as handle:
            members[_target(info.filename)] = _sha256(handle)
    return members


def _matches(folder: Path, members: dict[Path, tuple[int, str]]) -> bool:
    """Whether ``folder`` is a private folder of this user (mode 0700 or less) holding every
    member as a regular file of the right size and content, with no link on the way.

    Other files are allowed: an FMU may write into its own folder while it runs.
    """
    try:
        _private(folder)
        if stat.S_IMODE(os.lstat(folder).st_mode) & 0o077:
            return False
        real = folder.resolve()
        for relative, expected in members.items():
            path = real / relative
            if Path(os.path.realpath(path)) != path:  # a link in the way
                return False
            with open(path, "rb", opener=_no_links) as handle:
                if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                    return False
                if _sha256(handle) != expected:
                    return False
    except (OSError, CacheError):
        return False
    return True


def _no_links(path: str, flags: int) -> int:
    return os.open(path, flags | os.O_NOFOLLOW)


def _moved(source: Path, target: Path) -> bool:
    """Rename ``source`` to ``target``; False if ``target`` exists (another worker was first)."""
    try:
        os.rename(source, target)
    except OSError:
        return False
    return True


def extracted(archive: Path) -> Path:
    """The cache folder holding ``archive``'s content, extracted into it first if needed.

    The entry (``<cache>/<SHA-256 of the archive>``) is made under a temporary name and
    renamed into place, so a worker never sees a half-extracted FMU; workers of one machine
    share it. An entry that does not hold the archive's files intact (or is not private) is
    removed and extracted again.

    Raises
    ------
    CacheError
        The cache is not this user's or is open to others, the archive cannot be read or
        extracted, or the entry still does not match it after extraction.
    """
    root = cache_root()
    try:
        with open(archive, "rb") as handle:
            folder = root / _sha256(handle)[1][:32]
        with zipfile.ZipFile(archive) as zipped:
            members = _members(zipped)
            if _matches(folder, members):
                return folder
            staging = Path(tempfile.mkdtemp(prefix=".extracting-", dir=root))
            zipped.extractall(staging)
        if not _moved(staging, folder) and not _matches(folder, members):
            # Tampered with or damaged: put aside (atomically), removed, replaced.
            doomed = Path(tempfile.mkdtemp(prefix=".stale-", dir=root))
            _moved(folder, doomed / "entry")
            shutil.rmtree(doomed, ignore_errors=True)
            _moved(staging, folder)
        shutil.rmtree(staging, ignore_errors=True)  # what another worker's entry made useless
    except (OSError, zipfile.BadZipFile) as error:
        raise CacheError(f"cannot extract {archive} into {root}: {error}") from error
    if not _matches(folder, members):
        raise CacheError(f"the FMU cache entry {folder} does not match {archive}")
    return folder
