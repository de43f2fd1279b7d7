"""One native thread in the main process while workers take the cores.

Workers get their share of the cores for their native thread pools (BLAS, OpenMP; see
:mod:`pcmb.run.backends`). The main process's own linear algebra while they run (a random
process's eigen-solve while a config loads, recovery, analysis) would otherwise start one
spinning OpenBLAS thread per core on cores that are busy, which makes a symmetric eigen-solve
several times slower on a loaded machine (``scripts/bench_threads.py``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["THREAD_LIMITS", "one_thread_here"]

#: Environment variables that cap native thread pools, read when a library loads.
THREAD_LIMITS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def one_thread_here() -> Iterator[None]:
    """This process's native thread pools at one thread: those already loaded through
    threadpoolctl, those loaded later through their environment variables; both restored
    on exit. Workers started meanwhile get their own limits from their pool."""
    from threadpoolctl import threadpool_limits

    saved = {name: os.environ.get(name) for name in THREAD_LIMITS}
    os.environ.update(dict.fromkeys(THREAD_LIMITS, "1"))
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
