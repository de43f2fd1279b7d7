"""Processes that die with their parent: pcmb's workers and the programs they start.

A worker killed with its parent (``kill -9`` of pcmb, a crash) must not go on running a model,
and an external simulator must not outlive the worker that started it. On Linux the kernel
does this: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` makes it send SIGKILL to the process when its
parent exits, whatever the process is doing (strictly: when the parent's thread that started
it ends, so workers meant to outlive a thread must be started by the main thread). Elsewhere
a daemon thread polls the parent's pid (it cannot interrupt native code that holds the GIL, so
there it is a best effort).

The kernel's signal reaches only the direct child: what a model's program starts in turn (a
shell script's ``sleep``, a python model's ``subprocess.run``) would be left running. So the
workers are *tagged*: :func:`tag` gives the environment entry ``PCMB_LIFELINE=<token>`` they
are started with, which every process they start inherits, whatever its process group or
session. The first call starts this process's watchdog: this file run as a small program in a
session of its own, holding the read end of a pipe whose write end only this process holds.
When this process ends (``kill -9`` included) the pipe closes; the watchdog then kills every
process of the machine whose environment carries the token (until a scan finds none) and
exits. A process started with an environment that drops the entry escapes.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import secrets
import select
import signal
import sys
import threading
import time

__all__ = ["TAG", "die_with_parent", "kernel_kills_orphans", "tag"]

#: The environment variable that marks the processes to end with the process that tagged them.
TAG = "PCMB_LIFELINE"

_PR_SET_PDEATHSIG = 1
_POLL_SECONDS = 0.5
# Scans of the watchdog: each kills what the previous let fork; a bound so that it ends.
_SCANS = 20


def _prctl() -> object | None:
    """libc's ``prctl``, bound once (before any fork, so a ``preexec_fn`` only calls it)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _prctl()


def kernel_kills_orphans() -> bool:
    """Ask the kernel to SIGKILL this process when its parent exits; False where it cannot.

    Safe as a ``subprocess`` ``preexec_fn``: it only calls a function bound at import time.
    """
    return _PRCTL is not None and _PRCTL(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0


def die_with_parent(parent_pid: int | None = None) -> None:
    """Make this process die (SIGKILL) when its parent does.

    Parameters
    ----------
    parent_pid:
        The parent expected now. If it is already gone (this process was re-parented before
        the call), the process exits at once.
    """
    if kernel_kills_orphans():
        if parent_pid is not None and os.getppid() != parent_pid:
            os._exit(1)  # the parent died before the request was in place
        return
    expected = os.getppid() if parent_pid is None else parent_pid
    threading.Thread(target=_watch, args=(expected,), daemon=True, name="pcmb-lifeline").start()


def _watch(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(_POLL_SECONDS)
    os._exit(1)


# This process's watchdog: (the pid that started it, its token); see :func:`tag`.
_WATCHDOG: tuple[int, str] | None = None
_WATCHDOG_LOCK = threading.Lock()


def tag() -> dict[str, str]:
    """The environment entry that makes a process (and all it starts) end with this process.

    The first call (in each process) starts the watchdog that does it (module docstring).
    """
    global _WATCHDOG
    with _WATCHDOG_LOCK:
        if _WATCHDOG is None or _WATCHDOG[0] != os.getpid():  # none yet, or a fork's parent's
            token = f"{os.getpid()}-{secrets.token_hex(8)}"
            read, write = os.pipe()  # not inherited: only this process holds the write end
            try:
                os.posix_spawn(
                    sys.executable,
                    # -P: not this file's folder on sys.path (its modules would shadow others)
                    [sys.executable, "-P", __file__, token],
                    os.environ,
                    file_actions=[
                        (os.POSIX_SPAWN_DUP2, read, 0),
                        *((os.POSIX_SPAWN_OPEN, fd, os.devnull, os.O_WRONLY, 0) for fd in (1, 2)),
                    ],
                    setsid=True,  # out of reach of the signals sent to pcmb's process group
                )
            except BaseException:
                os.close(write)
                raise
            finally:
                os.close(read)
            _WATCHDOG = (os.getpid(), token)  # the write end stays open until this process ends
        return {TAG: _WATCHDOG[1]}


def _guard(token: str) -> None:
    """The watchdog: wait until the process that started it ends, then end the tagged ones."""
    parent = os.getppid()
    # Nothing is written to the pipe: it turns readable at EOF, when the parent has ended. A
    # fork of the parent may hold the pipe open longer: its own end shows in getppid.
    while os.getppid() == parent and not select.select([0], [], [], _POLL_SECONDS)[0]:
        pass
    _kill_tagged(token)


def _kill_tagged(token: str) -> None:
    """SIGKILL every process whose environment holds ``TAG=token``, until none is left."""
    import psutil

    def tagged(process: psutil.Process) -> bool:
        with contextlib.suppress(psutil.Error):  # gone, a zombie, another user's
            return process.environ().get(TAG) == token
        return False

    for _ in range(_SCANS):
        found = [p for p in psutil.process_iter() if p.pid != os.getpid() and tagged(p)]
        if not found:
            return
        for process in found:
            with contextlib.suppress(psutil.Error):
                process.kill()
        psutil.wait_procs(found, timeout=_POLL_SECONDS)


if __name__ == "__main__":
    _guard(sys.argv[1])
