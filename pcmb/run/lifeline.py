"""Processes that die with their parent: pcmb's workers and the programs they start.

A worker killed with its parent (``kill -9`` of pcmb, a crash) must not go on running a model,
and an external simulator must not outlive the worker that started it. On Linux the kernel
does this: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` makes it send SIGKILL to the process when its
parent exits, whatever the process is doing (strictly: when the parent's thread that started
it ends, so workers meant to outlive a thread must be started by the main thread). Elsewhere
a daemon thread polls the parent's pid (it cannot interrupt native code that holds the GIL, so
there it is a best effort).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent", "kernel_kills_orphans"]

_PR_SET_PDEATHSIG = 1
_POLL_SECONDS = 0.5


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
