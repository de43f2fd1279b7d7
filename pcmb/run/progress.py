"""A progress line on stderr: nodes done / total, rate, ETA."""

from __future__ import annotations

import math
import time
from typing import TextIO

__all__ = ["Progress"]

#: Smallest interval between two redraws, seconds.
_PROGRESS_INTERVAL = 0.1


class Progress:
    """One status line on a stream, rewritten in place: nodes (or another ``unit``) done /
    total, rate, ETA."""

    def __init__(self, total: int, done: int, stream: TextIO | None, unit: str = "nodes") -> None:
        self._total, self._done, self._stream, self._unit = total, done, stream, unit
        self._ran = 0
        self._start = self._last = time.perf_counter()
        self._width = 0

    def advance(self, count: int) -> None:
        self._done += count
        self._ran += count
        now = time.perf_counter()
        if now - self._last >= _PROGRESS_INTERVAL or self._done == self._total:
            self._last = now
            self._show(now)

    def _show(self, now: float) -> None:
        if self._stream is None:
            return
        rate = self._ran / max(now - self._start, 1e-9)
        eta = (self._total - self._done) / rate if rate > 0 else math.inf
        if math.isfinite(eta):
            seconds = round(eta)
            eta_text = f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"
        else:
            eta_text = "?"
        line = (
            f"pcmb: {self._done}/{self._total} {self._unit} "
            f"({100 * self._done / self._total:.0f}%), {rate:.3g} {self._unit}/s, ETA {eta_text}"
        )
        self._stream.write("\r" + line.ljust(self._width))
        self._stream.flush()
        self._width = len(line)

    def close(self) -> None:
        if self._stream is not None and self._width:
            self._stream.write("\n")
            self._stream.flush()
