"""An exclusive lock on what one pcmb process writes: a run's journal, a sweep's folder.

A lock file holds an exclusive ``flock`` and the holder's PID for as long as the process
writes, so two processes never write the same thing; a second one is refused with the
holder's PID and command. The operating system drops a ``flock`` with its process however
that ends: a killed process leaves the lock file, never a stale lock.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import time
import weakref
from pathlib import Path
from typing import ClassVar

from pcmb.errors import UsageError

__all__ = ["FolderLock"]

# How long taking the lock is retried before the holder is reported: long enough for a
# process that only probes it (FolderLock.check_free) to let go, short enough to go unnoticed.
_LOCK_PATIENCE = 0.25
_PID_PATIENCE = 0.5


def _command(pid: str) -> str:
    """The command line of process ``pid``, or "" when it cannot be known."""
    import psutil

    try:
        return shlex.join(psutil.Process(int(pid)).cmdline())
    except (ValueError, psutil.Error):
        return ""


def _busy(what: str, path: Path) -> UsageError:
    """The refusal naming the process that holds the lock at ``path`` (its PID, once it has
    written it, and its command when known)."""
    deadline = time.monotonic() + _PID_PATIENCE
    pid = ""
    while True:
        try:
            pid = path.read_text().strip()
        except OSError:
            pid = ""
        # The holder writes its PID just after taking the lock: give it a moment.
        if pid or time.monotonic() >= deadline:
            break
        time.sleep(0.01)
    command = _command(pid) if pid else ""
    running = f" (it runs: {command})" if command else ""
    return UsageError(
        f"another pcmb run (PID {pid or 'unknown'}) is writing {what}; wait for it to "
        f"finish{running}, or give this run another output (-o)"
    )


class FolderLock:
    """An exclusive ``flock`` on a lock file, held by this process.

    Every user of one lock file in one process shares it (so a process can reopen its own
    journal); it is released when the last of them lets go of it, by :meth:`release`, or by
    the operating system when the process ends, however it ends.
    """

    _held: ClassVar[weakref.WeakValueDictionary[str, FolderLock]] = weakref.WeakValueDictionary()

    def __init__(self, path: Path, fd: int) -> None:
        self.path, self.fd = path, fd
        self._close = weakref.finalize(self, os.close, fd)

    def valid(self) -> bool:
        """Whether the lock is still held on the file at ``path`` (not deleted or replaced)."""
        if not self._close.alive:
            return False
        try:
            held, current = os.fstat(self.fd), os.stat(self.path)
        except OSError:
            return False
        return (held.st_dev, held.st_ino) == (current.st_dev, current.st_ino)

    def release(self) -> None:
        """Let go of the lock (closing the file releases the ``flock``)."""
        if FolderLock._held.get(str(self.path)) is self:
            del FolderLock._held[str(self.path)]
        self._close()

    @staticmethod
    def _absolute(path: str | os.PathLike[str]) -> Path:
        # Absolute, so that valid() does not depend on the working directory.
        path = Path(path)
        return path.parent.resolve() / path.name

    @classmethod
    def _mine(cls, path: Path) -> FolderLock | None:
        lock = cls._held.get(str(cls._absolute(path)))
        return lock if lock is not None and lock.valid() else None

    @classmethod
    def acquire(cls, path: str | os.PathLike[str], what: str) -> FolderLock:
        """Take the lock file ``path`` (its folder is created if missing) or share this
        process's, and write this process's PID into it.

        Raises
        ------
        UsageError
            Another process holds it ("another pcmb run (PID N) is writing ``what``; ...").
        OSError
            The folder or the lock file cannot be made.
        """
        mine = cls._mine(Path(path))
        if mine is not None:
            return mine
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        path = cls._absolute(path)
        deadline = time.monotonic() + _LOCK_PATIENCE
        while True:
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except FileNotFoundError:  # the folder was just removed by the process that held it
                path.parent.mkdir(parents=True, exist_ok=True)
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                if time.monotonic() >= deadline:
                    raise _busy(what, path) from None
                time.sleep(0.01)
                continue
            lock = cls(path, fd)
            # The file may have been deleted (with its folder, by the process that held it
            # until now) between opening and locking it: a lock on it would guard nothing.
            if not lock.valid():
                lock.release()
                continue
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            cls._held[str(path)] = lock
            return lock

    @classmethod
    def check_free(cls, path: str | os.PathLike[str], what: str) -> None:
        """Raise if another process holds the lock file ``path`` (this one may).

        Probes with a shared lock, released at once, so that two probes never see each other.

        Raises
        ------
        UsageError
            Naming the PID (and command) of the process that holds it.
        """
        path = Path(path)
        if cls._mine(path) is not None:
            return
        try:
            fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
        except OSError:  # no lock file (or no folder): nobody holds it
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _busy(what, path) from None
        finally:
            os.close(fd)
