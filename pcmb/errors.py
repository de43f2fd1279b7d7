"""The kinds of error pcmb raises on purpose, and its warning category.

Each kind carries the exit code the command line gives it (:attr:`PcmbError.exit_code`);
only :mod:`pcmb.cli` turns errors into exit codes and messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from pcmb.run.status import NodeFailure


#: Exit codes of the command line, by kind of outcome.
EXIT_OK, EXIT_UNEXPECTED, EXIT_INVALID, EXIT_MODEL = 0, 1, 2, 3
#: ``pcmb run --strict``: the result is written, but an expansion is called unreliable.
EXIT_UNRELIABLE = 4


class PcmbError(Exception):
    """Base class of every error pcmb raises on purpose."""

    exit_code: ClassVar[int] = EXIT_UNEXPECTED
    #: How the command line introduces the message.
    label: ClassVar[str] = "error"


@dataclass(frozen=True)
class ConfigProblem:
    """One problem found in a configuration or in a call's arguments.

    Attributes
    ----------
    path:
        Key path, e.g. ``"inputs.A.low"`` (empty for the whole file or call).
    message:
        What was expected and what was found.
    line:
        1-based line in the file where the offending key or value is, when known.
    """

    path: str
    message: str
    line: int | None = None

    def format(self, source: str | None = None) -> str:
        where = source or ""
        if self.line is not None:
            where = f"{where}:{self.line}"
        key = f"{self.path}: " if self.path else ""
        return f"{where}: {key}{self.message}" if where else f"{key}{self.message}"


class _Located(PcmbError, ValueError):
    """An error made of located problems (every problem is reported, not just the first)."""

    exit_code = EXIT_INVALID

    def __init__(self, problems: Sequence[ConfigProblem] | str, source: str | None = None):
        if isinstance(problems, str):
            problems = [ConfigProblem(path="", message=problems)]
        self.problems: tuple[ConfigProblem, ...] = tuple(problems)
        self.source = source
        super().__init__("\n".join(p.format(source) for p in self.problems))


class ConfigError(_Located):
    """An invalid configuration, found before any model runs (exit 2).

    Parameters
    ----------
    problems:
        Every problem found, each with its key path (and line, from a file).
    source:
        The config file name, used in the message.
    """

    label = "invalid configuration"


class UsageError(_Located):
    """Invalid command-line or API arguments (exit 2); ``source`` names the call."""

    label = "usage"


class ClusterError(_Located):
    """A dask cluster that cannot be used: nothing answers at its address, or not a dask
    scheduler (exit 2); the problem's path names the setting that gave the address
    (``execution.address``, ``--address`` or ``Study``'s ``address``)."""

    label = "cluster"


class MissingDependencyError(PcmbError, ImportError):
    """An optional package is needed and not installed (exit 2).

    Parameters
    ----------
    package:
        The import name that failed, e.g. ``"matplotlib"``.
    extra:
        The pcmb extra that installs it, e.g. ``"plot"``.
    needed_for:
        What needed it, e.g. ``"figures"``.
    """

    exit_code = EXIT_INVALID
    label = "missing dependency"

    def __init__(self, package: str, extra: str, needed_for: str):
        self.package, self.extra = package, extra
        super().__init__(
            f'{needed_for} need {package}, which is not installed: pip install "pcmb[{extra}]"',
            name=package,
        )


class ResultFileError(PcmbError, OSError):
    """A result file that is missing, unreadable or not a pcmb result (exit 2)."""

    exit_code = EXIT_INVALID
    label = "file"


class ModelError(PcmbError):
    """A model run failed (raised by models and adapters for a single run or batch)."""


class ModelDefinitionError(ModelError):
    """A model that breaks the model protocol in a way no node can escape (exit 3).

    For example a per-point function that returns a number where a (T,) array is due: every
    node would fail the same way, so the run stops at the first with one message.
    """

    exit_code = EXIT_MODEL
    label = "model error"


class ModelRunError(PcmbError):
    """Nodes failed and the failure policy does not allow going on (exit 3).

    Attributes
    ----------
    failures:
        The failed nodes (:class:`pcmb.result.NodeFailure`), reported in the message once
        per cause, with the model's traceback (:func:`pcmb.run.status.failure_report`).
    """

    exit_code = EXIT_MODEL
    label = "model failure"

    def __init__(self, failures: Sequence[NodeFailure], message: str | None = None):
        self.failures = tuple(failures)
        lines = [message or f"the model failed at {len(self.failures)} node(s):"]
        from pcmb.run.status import failure_report  # the base of every error stays a leaf

        lines += failure_report(self.failures, "  ")
        super().__init__("\n".join(lines))


class IllPosedError(PcmbError, ValueError):
    """A least-squares chaos fit that cannot be trusted (too few nodes or ill conditioned)."""

    exit_code = EXIT_INVALID
    label = "ill-posed fit"


class PcmbWarning(UserWarning):
    """The category of every warning pcmb issues (see :class:`pcmb.result.WarningRecord`)."""


def complex_output(what: str, imaginary: float) -> ModelError:
    """The error for a model output (``what``: ``"output 'y'"``, with where it comes from)
    that is complex with a non-zero imaginary part (largest: ``imaginary``), which a float
    would drop."""
    return ModelError(
        f"{what} is complex (imaginary part up to {imaginary:.3g}); pcmb takes real outputs "
        "only: return its real and imaginary parts, or its modulus and phase, as outputs of "
        "their own"
    )


def missing_dependency(package: str, extra: str, needed_for: str) -> MissingDependencyError:
    """The error for an optional ``package`` (from the ``extra``) that failed to import."""
    return MissingDependencyError(package, extra, needed_for)
