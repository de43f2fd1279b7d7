"""Progress on stderr: nodes done / total, rate, ETA; and the phases of work between them.

On a terminal the line is rewritten in place; elsewhere (a log file, a CI job, a pipe) a new
line is written each 5 % of the total (:data:`LOG_LINES`): progress in a log, not a flood.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

__all__ = ["LOG_LINES", "Progress", "phase"]

#: Smallest interval between two redraws on a terminal, seconds.
_PROGRESS_INTERVAL = 0.1
#: Lines written over the whole work where the stream is not a terminal (one per 5 %).
LOG_LINES = 20


def _is_terminal(stream: TextIO) -> bool:
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


class Progress:
    """Nodes (or another ``unit``) done / total, rate, ETA: one line rewritten in place on a
    terminal, a line per 5 % of the total elsewhere (:data:`LOG_LINES`). Work found done already
    (``done``, e.g. runs reused from a journal) is said at once."""

    def __init__(self, total: int, done: int, stream: TextIO | None, unit: str = "nodes") -> None:
        self._total, self._done, self._stream, self._unit = total, done, stream, unit
        self._ran = 0
        self._start = self._last = time.perf_counter()
        self._width = 0
        self._in_place = stream is not None and _is_terminal(stream)
        self._logged = self._step(done)
        if stream is not None and done:
            stream.write(f"pcmb: {done} of {total} {unit} reused from the journal\n")
            stream.flush()

    def _step(self, done: int) -> int:
        """Which step of :data:`LOG_LINES` ``done`` has reached."""
        return done * LOG_LINES // self._total if self._total else LOG_LINES

    def advance(self, count: int) -> None:
        self._done += count
        self._ran += count
        now = time.perf_counter()
        if self._in_place:
            if now - self._last >= _PROGRESS_INTERVAL or self._done == self._total:
                self._last = now
                self._show(now)
        elif self._step(self._done) > self._logged:
            self._logged = self._step(self._done)
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
        if self._in_place:
            self._stream.write("\r" + line.ljust(self._width))
            self._width = len(line)
        else:
            self._stream.write(line + "\n")
        self._stream.flush()

    def close(self) -> None:
        if self._stream is not None and self._width:
            self._stream.write("\n")
            self._stream.flush()


@contextmanager
def phase(what: str, stream: TextIO | None) -> Iterator[None]:
    """Say ``pcmb: <what> ...`` on ``stream`` when a phase of work starts and how long it
    took when it ends (nothing without a stream)."""
    if stream is None:
        yield
        return
    stream.write(f"pcmb: {what} ...")
    stream.flush()
    start = time.perf_counter()
    try:
        yield
    finally:
        stream.write(f" {time.perf_counter() - start:.1f} s\n")
        stream.flush()
