"""Exceptions raised by pcmb.

Only the command line turns these into exit codes and messages (see :mod:`pcmb.cli`):
:class:`ConfigError` -> 2, :class:`ModelRunError` -> 3, anything else -> 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


class PcmbError(Exception):
    """Base class of every error pcmb raises on purpose."""


@dataclass(frozen=True)
class ConfigProblem:
    """One problem found in a configuration.

    Attributes
    ----------
    path:
        Key path inside the config, e.g. ``"inputs.A.low"`` (empty for the whole file).
    message:
        What was expected and what was found.
    line:
        1-based line in the file where the offending key or value is, when known.
    """

    path: str
    message: str
    line: int | None = None

    def format(self, source: str | None = None) -> str:
        where = source or "<config>"
        if self.line is not None:
            where = f"{where}:{self.line}"
        key = f" {self.path}:" if self.path else ""
        return f"{where}:{key} {self.message}"


class ConfigError(PcmbError, ValueError):
    """An invalid configuration or invalid arguments, found before any model runs.

    Parameters
    ----------
    problems:
        Every problem found (a config is checked as a whole, not stopped at the first).
    source:
        The config file name, used in the message.
    """

    def __init__(self, problems: Sequence[ConfigProblem] | str, source: str | None = None):
        if isinstance(problems, str):
            problems = [ConfigProblem(path="", message=problems)]
        self.problems: tuple[ConfigProblem, ...] = tuple(problems)
        self.source = source
        super().__init__("\n".join(p.format(source) for p in self.problems))


class ModelError(PcmbError):
    """A model run failed (raised by models and adapters for a single run or batch)."""


class ModelRunError(PcmbError):
    """One or more collocation nodes failed and the failure policy does not allow going on.

    Attributes
    ----------
    failures:
        The failed nodes (objects with ``index``, ``params`` and ``message``).
    """

    def __init__(self, failures: Sequence[object], message: str | None = None):
        self.failures = tuple(failures)
        lines = [message or f"the model failed at {len(self.failures)} node(s):"]
        lines += [f"  {f}" for f in self.failures]
        super().__init__("\n".join(lines))


class IllPosedError(PcmbError, ValueError):
    """A least-squares chaos fit that cannot be trusted (too few nodes or ill conditioned)."""
