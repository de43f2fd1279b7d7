"""The command adapter (``model.kind: command``): an external program run once per node.

Per node: a fresh work directory; template files rendered into it; the listed files linked;
``params.json`` written; the command run there in its own process group (killed whole on
timeout); its output file parsed. Its config section is :mod:`pcmb.adapters.command.spec`.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import os
import re
import shlex
import shutil
import signal
import stat
import subprocess
import tempfile
import time
import typing
import zipfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pcmb.adapters.protocol import (
    ModelFactory,
    PointwiseModel,
    check_point_result,
    describe_exception,
    float_array,
)
from pcmb.axes import OutputAxis
from pcmb.errors import ConfigError, ConfigProblem, ModelError
from pcmb.run.lifeline import kernel_kills_orphans
from pcmb.wording import signal_name

__all__ = [
    "FORMATS",
    "KEEP_POLICIES",
    "CommandModel",
    "CommandModelFactory",
    "command_files",
    "split_command",
]

OutputFormat = Literal["csv", "table", "json", "npy", "npz"]
KeepPolicy = Literal["failed", "all", "none"]

#: Output file formats, and which work directories survive (``keep``); the config's lists.
FORMATS: tuple[str, ...] = typing.get_args(OutputFormat)
# Formats inferred from an output file's extension (a whitespace table has no usual one).
_EXTENSIONS = ("csv", "json", "npy", "npz")
KEEP_POLICIES: tuple[str, ...] = typing.get_args(KeepPolicy)

_PLACEHOLDER = re.compile(r"\{\{\s*([^{}]*?)\s*\}\}")
# Template names that describe the output grid; dotted, so no parameter name can clash.
_GRID_NAMES = ("times.start", "times.stop", "times.points")
_PARAMS_FILE = "params.json"
_STDOUT_FILE = "stdout.txt"
_STDERR_FILE = "stderr.txt"
# The end of a failed run's stderr (else stdout) shown in its message: the lines that say why.
_TAIL_LINES = 5
_TAIL_LINE_CHARS = 200
# The longest #! line the kernel reads (Linux since 5.1).
_SHEBANG_BYTES = 256


def _problem(path: str, message: str) -> ConfigError:
    return ConfigError([ConfigProblem(path=path, message=message)])


def _open_to_others(folder: Path) -> str | None:
    """Why another user could tamper with the work directories made in ``folder`` (swap one
    for a link, plant its outputs), or None: it must be a real folder of this user's (or
    root's), writable by no one else unless sticky like /tmp. A folder not made yet is safe:
    pcmb makes it."""
    try:
        info = os.lstat(folder)
    except FileNotFoundError:
        return None
    if not stat.S_ISDIR(info.st_mode):
        return f"{folder} is not a folder (a link or a file)"
    if info.st_uid not in (os.getuid(), 0):
        return f"{folder} is owned by uid {info.st_uid}, not by this user (uid {os.getuid()})"
    mode = stat.S_IMODE(info.st_mode)
    if mode & (stat.S_IWGRP | stat.S_IWOTH) and not mode & stat.S_ISVTX:
        return (
            f"{folder} is writable by other users (mode {mode:04o}) without the sticky bit: "
            f"use a folder of your own (chmod 700) or a sticky one like /tmp"
        )
    return None


def split_command(text: str) -> list[str]:
    """Split a command line like a shell would (without running one).

    ``{{ name }}`` placeholders stay whole arguments, whatever spaces they hold.

    Raises
    ------
    ValueError
        Unbalanced quotes.
    """
    return shlex.split(_PLACEHOLDER.sub(lambda m: "{{" + m.group(1) + "}}", text))


@dataclass(frozen=True)
class _Template:
    name: str
    text: str


def _format_value(value: Any) -> str:
    """Exact text of a parameter: repr of a float round-trips bit for bit."""
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        return repr(float(array))
    return " ".join(repr(float(x)) for x in array.ravel())


def _jsonable(value: Any) -> Any:
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array.tolist()


def _output_tail(workdir: Path) -> str:
    """The last non-blank lines of the run's stderr (else stdout), quoted on one line: a
    failure is reported on one line per node."""
    for name in (_STDERR_FILE, _STDOUT_FILE):
        try:
            text = (workdir / name).read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        if lines:
            shown = ", ".join(repr(line[-_TAIL_LINE_CHARS:]) for line in lines[-_TAIL_LINES:])
            return f"last lines of {name}: {shown}"
    return f"{_STDERR_FILE} and {_STDOUT_FILE} are empty"


def _missing_interpreter(script: Path) -> str | None:
    """What is missing to run ``script`` when its ``#!`` line names an interpreter that does
    not exist (the kernel would say "No such file or directory" of the script); else None.

    The line is read as the kernel reads it: the interpreter's path, then at most one argument
    (the rest of the line), which ``env`` takes as the program to find on PATH (its words
    after ``-S``).
    """
    try:
        with open(script, "rb") as file:
            first = file.read(_SHEBANG_BYTES).split(b"\n", 1)[0]
    except OSError:  # not readable: the kernel will say so itself
        return None
    if not first.startswith(b"#!"):
        return None
    # Split at spaces and tabs only, as the kernel does (a "\r" of a DOS line ending stays).
    text = os.fsdecode(first[2:]).strip(" \t").replace("\t", " ")
    interpreter, _, argument = text.partition(" ")
    line = first.decode(errors="replace")
    if not interpreter:
        return f"its {line!r} line names no interpreter"
    if not (os.path.isfile(interpreter) and os.access(interpreter, os.X_OK)):
        return f"its interpreter {interpreter!r} (line {line!r}) is missing or not executable"
    argument = argument.strip(" ")
    if os.path.basename(interpreter) != "env" or not argument:
        return None
    if argument.startswith("-S"):  # env splits the rest into words
        names = [w for w in argument[2:].split() if not w.startswith("-") and "=" not in w]
    elif argument.startswith("-") or "=" in argument:  # other options: not second-guessed
        names = []
    else:
        names = [argument]
    if names and shutil.which(names[0]) is None:
        return f"its interpreter {names[0]!r} (line {line!r}) is not found on PATH"
    return None


def _wait_unreaped(pid: int, timeout: float | None) -> bool:
    """Wait for ``pid`` to exit without reaping it; True if it exited in time.

    Leaving the zombie in place keeps its process-group id reserved, so the group can be
    killed afterwards without any risk of signalling an unrelated process.
    """
    deadline = None if timeout is None else time.monotonic() + timeout
    delay = 0.0005
    while True:
        try:
            if os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
                return True
        except ChildProcessError:  # already reaped (SIGCHLD ignored): it has exited
            return True
        if deadline is not None and time.monotonic() >= deadline:
            return False
        # Poll quickly at first (short commands), then every 10 ms (negligible CPU).
        delay = min(2 * delay, 0.01)
        time.sleep(delay)


class CommandModel(PointwiseModel):
    """An external executable as a model, run once per node.

    Per node: a fresh work directory; template files rendered into it (``{{ name }}`` ->
    the exact float text, ``repr``; ``{{ times.start }}``, ``{{ times.stop }}`` and
    ``{{ times.points }}`` describe the grid); the listed ``files`` symlinked into it;
    ``params.json`` written (``{"params": {name: value}, "times": [...]}``); the command
    run there in its own process group, with ``timeout`` killing the whole group; the
    output file parsed.

    Parameters
    ----------
    command:
        The argv (a list, or a string split like a shell would, without running a shell).
        Arguments may contain placeholders too. A program given with a ``/`` resolves
        against ``base_dir``; a bare name is looked up on PATH.
    params:
        Nominal value of every parameter (all numbers), including every uncertain input.
    outputs:
        Output names to read from the output file.
    output_file:
        File the command writes in its work directory.
    output_format:
        ``csv`` (header row of names, one row per time), ``table`` (the same, separated by
        whitespace, as ngspice's ``wrdata`` writes), ``json`` (``{name: [...]}``), ``npy``
        ((T,) for one output or (T, k) with columns in ``outputs`` order) or ``npz`` (arrays
        by name); ``None`` infers it from the file extension (all but ``table``).
    templates:
        Template files (relative to ``base_dir``), rendered into the work directory under
        their own file name.
    files:
        Files linked into every work directory (the simulator script, a mesh...).
    base_dir:
        Folder relative paths resolve against (the config file's folder).
    timeout:
        Seconds before a run is killed (``None``: no limit).
    run_dir:
        Folder that receives the per-node work directories (default: the system temp dir).
    keep:
        Which work directories survive: ``failed`` (default; their path is in the error
        message), ``all`` or ``none``.
    time_column:
        Name of an optional time column/key in the output; when present it must match the
        requested grid.
    axis, axis_column:
        The outputs' own axis (:class:`~pcmb.axes.OutputAxis`, e.g. the frequencies of an
        AC sweep) instead of time, and the column/key of the output file that holds its
        points at every node (required, and checked against ``axis.values``).

    Raises
    ------
    ConfigError
        Located at the ``model.*`` key at fault: program not found, missing template or
        file, a placeholder naming no parameter, an unknown output format, clashing names.

    Notes
    -----
    Processes the command leaves behind are killed with its process group when it ends.
    """

    nominal_from_params = True

    def __init__(
        self,
        command: str | Sequence[str],
        *,
        params: Mapping[str, float],
        outputs: Sequence[str],
        output_file: str,
        output_format: OutputFormat | None = None,
        templates: Sequence[str] = (),
        files: Sequence[str] = (),
        base_dir: Path | None = None,
        timeout: float | None = None,
        run_dir: Path | None = None,
        keep: KeepPolicy = "failed",
        time_column: str = "time",
        axis: OutputAxis | None = None,
        axis_column: str = "frequency",
    ):
        base_dir = Path.cwd() if base_dir is None else Path(base_dir).resolve()
        try:
            argv = split_command(command) if isinstance(command, str) else list(command)
        except ValueError as exc:
            raise _problem("model.command", f"cannot split the command: {exc}") from exc
        if not argv:
            raise _problem("model.command", "the command is empty")
        self.argv = (self._resolve_program(argv[0], base_dir), *argv[1:])
        try:
            self.parameters = {k: float(v) for k, v in params.items()}
        except (TypeError, ValueError) as exc:
            raise _problem("model.params", f"a command model takes numbers: {exc}") from exc
        if timeout is not None and not timeout > 0:
            raise _problem(
                "model.timeout", f"expected a positive number of seconds, found {timeout}"
            )
        if keep not in KEEP_POLICIES:
            raise _problem("model.keep", f"expected 'failed', 'all' or 'none', found {keep!r}")
        self.outputs = tuple(outputs)
        if not self.outputs:
            raise _problem("model.outputs", "a command model must list the outputs it reads")
        if time_column in self.outputs:
            raise _problem("model.outputs", f"{time_column!r} is the time column, not an output")
        self.output_file = output_file
        self.output_format = self._resolve_format(output_file, output_format)
        self.timeout = timeout
        self.run_dir = None if run_dir is None else Path(run_dir)
        if self.run_dir is not None and (why := _open_to_others(self.run_dir)):
            raise _problem("model.run_dir", why)
        self.keep = keep
        self.time_column = time_column
        self.axis, self.axis_column = axis, axis_column
        if axis is not None:
            # The model protocol's output_axes: every output of the file is on the axis.
            self.output_axes = dict.fromkeys(self.outputs, axis)
        self.templates = tuple(
            self._read_template(base_dir, name, f"model.templates[{i}]")
            for i, name in enumerate(templates)
        )
        self.files = tuple(
            self._resolve_file(base_dir, name, f"model.files[{i}]") for i, name in enumerate(files)
        )
        self._check_placeholders()
        self._check_names()

    # -- construction checks

    @staticmethod
    def _resolve_program(program: str, base_dir: Path) -> str:
        if os.sep in program:
            path = (base_dir / program).resolve()
            if not path.is_file() or not os.access(path, os.X_OK):
                raise _problem(
                    "model.command[0]", f"program {path} does not exist or is not executable"
                )
        else:
            found = shutil.which(program)
            if found is None:
                raise _problem("model.command[0]", f"program {program!r} not found on PATH")
            path = Path(found)
        missing = _missing_interpreter(path)
        if missing:
            raise _problem("model.command[0]", f"program {path} cannot start: {missing}")
        return str(path)

    @staticmethod
    def _resolve_format(output_file: str, output_format: str | None) -> str:
        if Path(output_file).name != output_file or output_file in ("", ".", ".."):
            raise _problem(
                "model.output.file", f"expected a plain file name, found {output_file!r}"
            )
        if output_format is not None:
            if output_format not in FORMATS:
                raise _problem(
                    "model.output.format",
                    f"expected one of {', '.join(FORMATS)}, found {output_format!r}",
                )
            return output_format
        suffix = Path(output_file).suffix.lstrip(".").lower()
        if suffix not in _EXTENSIONS:
            raise _problem(
                "model.output.format",
                f"give the format of {output_file} ({', '.join(FORMATS)}): its extension "
                f"{suffix!r} is none of {', '.join(_EXTENSIONS)}",
            )
        return suffix

    @staticmethod
    def _resolve_file(base_dir: Path, name: str, key: str) -> Path:
        path = (base_dir / name).resolve()
        if not path.is_file():
            raise _problem(key, f"file {path} does not exist")
        return path

    def _read_template(self, base_dir: Path, name: str, key: str) -> _Template:
        path = self._resolve_file(base_dir, name, key)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise _problem(key, f"cannot read template {path}: {describe_exception(exc)}") from exc
        return _Template(path.name, text)

    def _check_placeholders(self) -> None:
        known = set(self.parameters) | set(_GRID_NAMES)
        hint = f"known: {', '.join([*self.parameters, *_GRID_NAMES])}"
        for i, template in enumerate(self.templates):
            for match in _PLACEHOLDER.finditer(template.text):
                if match.group(1) not in known:
                    line = template.text.count("\n", 0, match.start()) + 1
                    raise _problem(
                        f"model.templates[{i}]",
                        f"{template.name} line {line}: placeholder {match.group(0)!r} names "
                        f"no parameter ({hint})",
                    )
        for i, arg in enumerate(self.argv[1:], start=1):
            for match in _PLACEHOLDER.finditer(arg):
                if match.group(1) not in known:
                    raise _problem(
                        f"model.command[{i}]",
                        f"placeholder {match.group(0)!r} names no parameter ({hint})",
                    )

    def _check_names(self) -> None:
        """Everything placed in a work directory needs its own name (reported where reused)."""
        reserved = (_PARAMS_FILE, _STDOUT_FILE, _STDERR_FILE)
        placed = [
            ("model.output.file", self.output_file),
            *((f"model.templates[{i}]", t.name) for i, t in enumerate(self.templates)),
            *((f"model.files[{i}]", f.name) for i, f in enumerate(self.files)),
        ]
        first: dict[str, str] = {}
        for key, name in placed:
            if name in reserved:
                raise _problem(
                    key, f"{name} is a reserved work-directory name ({', '.join(reserved)})"
                )
            if name in first:
                raise _problem(
                    key, f"work-directory file name {name} is already used by {first[name]}"
                )
            first[name] = key

    # -- one node

    def _render(self, text: str, context: Mapping[str, str]) -> str:
        return _PLACEHOLDER.sub(lambda m: context[m.group(1)], text)

    def _prepare(
        self, workdir: Path, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> list[str]:
        context = {name: _format_value(v) for name, v in values.items()}
        context.update(
            {
                "times.start": repr(float(times[0])),
                "times.stop": repr(float(times[-1])),
                "times.points": str(times.size),
            }
        )
        for template in self.templates:
            (workdir / template.name).write_text(self._render(template.text, context), "utf-8")
        for path in self.files:
            (workdir / path.name).symlink_to(path)
        document = {
            "params": {name: _jsonable(v) for name, v in values.items()},
            "times": times.tolist(),
        }
        (workdir / _PARAMS_FILE).write_text(json.dumps(document, indent=1), "utf-8")
        return [self.argv[0], *(self._render(arg, context) for arg in self.argv[1:])]

    def _execute(self, workdir: Path, argv: list[str]) -> None:
        with (
            open(workdir / _STDOUT_FILE, "wb") as stdout,
            open(workdir / _STDERR_FILE, "wb") as stderr,
        ):
            try:
                process = subprocess.Popen(
                    argv,
                    cwd=workdir,
                    stdin=subprocess.DEVNULL,
                    stdout=stdout,
                    stderr=stderr,
                    start_new_session=True,
                    # The simulator dies with the worker that runs it (kill -9 of pcmb).
                    preexec_fn=kernel_kills_orphans,
                )
            except OSError as exc:
                # ENOENT of a script that exists: its #! line names what is missing.
                missing = isinstance(exc, FileNotFoundError) and _missing_interpreter(Path(argv[0]))
                reason = missing or describe_exception(exc)
                raise ModelError(f"cannot start {argv[0]}: {reason}") from exc
            try:
                finished = _wait_unreaped(process.pid, self.timeout)
            finally:
                # The leader is not reaped yet, so its group id cannot have been reused.
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                code = process.wait()
        if not finished:
            raise ModelError(f"timed out after {self.timeout:g} s (process group killed)")
        if code < 0:
            raise ModelError(f"killed by signal {-code} ({signal_name(-code)})")
        if code > 0:
            raise ModelError(f"exited with code {code}")

    def _read_outputs(
        self, workdir: Path, times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        path = workdir / self.output_file
        if not path.is_file():
            raise ModelError(f"the command succeeded but wrote no output file {self.output_file}")
        try:
            columns = _READERS[self.output_format](path, self.outputs)
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, csv.Error) as exc:
            what = f"{self.output_file} as {self.output_format}"
            raise ModelError(f"cannot parse {what}: {describe_exception(exc)}") from exc
        key, label, points = self.time_column, "t", "time(s)"
        if self.axis is not None:
            key, times = self.axis_column, self.axis.values
            label, points = key, "point(s)"
            if key not in columns:
                raise ModelError(f"{self.output_file} has no {key!r} column (the axis)")
        if key in columns:
            self._check_time_column(columns[key], times, key)
        result = check_point_result(columns, self.outputs, times.size, self.output_file)
        for name, values in result.items():
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ModelError(
                    f"output {name!r} in {self.output_file} is not finite at "
                    f"{bad.size} {points}, first at {label}={times[bad[0]]:g}"
                )
        return result

    def _check_time_column(self, column: Any, times: NDArray[np.float64], key: str) -> None:
        file_times = float_array(column, f"{key!r} in {self.output_file}")
        # A simulator may print times with few digits; a row must still be unmistakably its
        # grid time, i.e. within a small fraction of the grid step.
        step = np.min(np.diff(times)) if times.size > 1 else max(1.0, abs(float(times[0])))
        if file_times.shape != times.shape or not np.allclose(
            file_times, times, rtol=0, atol=1e-3 * step
        ):
            raise ModelError(
                f"the {key!r} column of {self.output_file} does not match the "
                f"requested grid ({times.size} points from {times[0]:g} to {times[-1]:g})"
            )

    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run the command for one node; see :meth:`PointwiseModel.run_point`.

        The ModelError message says what failed (exit code, signal, timeout, missing or
        unparseable output, wrong length, non-finite values) with the tail of the
        command's output, and where the kept work directory is.
        """
        times = np.asarray(times, dtype=float)
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            if why := _open_to_others(self.run_dir):  # made by someone else since the check
                raise ModelError(f"model.run_dir: {why}")
        workdir = Path(tempfile.mkdtemp(prefix="pcmb-node-", dir=self.run_dir))
        succeeded = False
        try:
            argv = self._prepare(workdir, {**self.parameters, **values}, times)
            self._execute(workdir, argv)
            result = self._read_outputs(workdir, times)
            succeeded = True
            return result
        except ModelError as exc:
            message = f"{exc}; {_output_tail(workdir)}"
            if self.keep != "none":
                message += f" [work directory kept: {workdir}]"
            raise ModelError(message) from exc
        finally:
            if self.keep == "none" or (self.keep == "failed" and succeeded):
                shutil.rmtree(workdir, ignore_errors=True)


def _read_csv(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    text = path.read_text(encoding="utf-8", errors="replace")
    return _columns([row for row in csv.reader(io.StringIO(text)) if row])


def _read_table(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    text = path.read_text(encoding="utf-8", errors="replace")
    return _columns([line.split() for line in text.splitlines() if line.strip()])


def _columns(rows: list[list[str]]) -> dict[str, NDArray[np.float64]]:
    """Columns by name of a table whose first row names them.

    A name may repeat only for columns of equal values (ngspice's ``wrdata`` repeats its
    scale column before every vector): otherwise which column is meant cannot be told.
    """
    if not rows:
        raise ValueError("the file is empty")
    header = [cell.strip() for cell in rows[0]]
    table = np.empty((len(rows) - 1, len(header)))
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(f"line {number} has {len(row)} fields, the header has {len(header)}")
        for j, cell in enumerate(row):
            try:
                table[number - 2, j] = float(cell)
            except ValueError:
                raise ValueError(f"line {number}: {cell.strip()!r} is not a number") from None
    columns: dict[str, NDArray[np.float64]] = {}
    for j, name in enumerate(header):
        if name in columns and not np.array_equal(columns[name], table[:, j], equal_nan=True):
            where = [k + 1 for k, other in enumerate(header) if other == name]
            count = "twice" if len(where) == 2 else f"{len(where)} times"
            raise ValueError(
                f"column {name!r} appears {count} (columns {', '.join(map(str, where[:-1]))} "
                f"and {where[-1]}) with different values: which one is meant is unknown"
            )
        columns[name] = table[:, j]
    return columns


def _read_json(path: Path, outputs: Sequence[str]) -> dict[str, Any]:
    document = json.loads(
        path.read_text(encoding="utf-8", errors="replace"), object_pairs_hook=_unique_keys
    )
    if not isinstance(document, dict):
        raise ValueError(f"expected an object {{name: [values]}}, found {type(document).__name__}")
    return document


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose keys repeat only with equal values (else the meant one is unknown;
    ``json`` alone would keep the last)."""
    document: dict[str, Any] = {}
    for key, value in pairs:
        if key in document and document[key] != value:
            raise ValueError(f"key {key!r} appears more than once, with different values")
        document[key] = value
    return document


def _read_npy(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    array = np.load(path, allow_pickle=False)
    if array.ndim == 1 and len(outputs) == 1:
        return {outputs[0]: array}
    if array.ndim != 2 or array.shape[1] != len(outputs):
        raise ValueError(f"expected shape (T, {len(outputs)}), found {array.shape}")
    return {name: array[:, j] for j, name in enumerate(outputs)}


def _read_npz(path: Path, outputs: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    with np.load(path, allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


_READERS: dict[str, Callable[[Path, Sequence[str]], Mapping[str, Any]]] = {
    "csv": _read_csv,
    "table": _read_table,
    "json": _read_json,
    "npy": _read_npy,
    "npz": _read_npz,
}


def command_files(
    command: Iterable[str],
    templates: Iterable[str],
    files: Iterable[str],
    base_dir: str | os.PathLike[str],
) -> list[Path]:
    """The files a command model reads, resolved like the adapter resolves them: the program
    when given as a path (a bare name found on ``PATH`` is not), every argument that is an
    absolute path of an existing file, every template and linked file."""
    base = Path(base_dir)
    argv = list(command)
    found = [base / name for name in (*templates, *files)]
    if argv and os.sep in argv[0]:
        found.append(base / argv[0])
    found += [Path(arg) for arg in argv[1:] if os.path.isabs(arg) and Path(arg).is_file()]
    return [path.resolve() for path in found]


@dataclass(frozen=True)
class CommandModelFactory(ModelFactory):
    """Builds a :class:`CommandModel`; the fields are its constructor's arguments."""

    command: tuple[str, ...]
    params: Mapping[str, float]
    outputs: tuple[str, ...]
    output_file: str
    output_format: OutputFormat | None = None
    templates: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    base_dir: Path | None = None
    timeout: float | None = None
    run_dir: Path | None = None
    keep: KeepPolicy = "failed"
    time_column: str = "time"
    axis: OutputAxis | None = None
    axis_column: str = "frequency"

    def model_files(self) -> list[Path]:
        """The program, its file arguments, the templates and files (:func:`command_files`)."""
        base = Path.cwd() if self.base_dir is None else self.base_dir
        return command_files(self.command, self.templates, self.files, base)

    def __call__(self) -> CommandModel:
        """Build the model (raises ConfigError as :class:`CommandModel` does)."""
        arguments = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return CommandModel(arguments.pop("command"), **arguments)
