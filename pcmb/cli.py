"""The ``pcmb`` command line.

Exit codes come from the error kinds (:mod:`pcmb.errors`): 0 success; 2 invalid config,
usage, missing dependency or result file; 3 the model failed at one or more nodes (policy
abort); 4 with ``--strict``, an expansion the diagnostics call unreliable (the file is
written); 1 anything unexpected; 128 + the signal's number when stopped by SIGINT (Ctrl-C),
SIGTERM or SIGHUP, after killing the workers (finished nodes stay in the journal). Logs and
progress go to stderr; stdout carries only requested data. Heavy modules are imported inside
the commands, so ``pcmb --help`` starts fast.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import os
import shlex
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import TYPE_CHECKING

from pcmb.adapters.registry import ADAPTERS
from pcmb.errors import (
    EXIT_OK,
    EXIT_UNEXPECTED,
    EXIT_UNRELIABLE,
    PcmbError,
    PcmbWarning,
    UsageError,
)
from pcmb.run.backends import BACKENDS, close_kept
from pcmb.run.progress import phase
from pcmb.wording import plural

if TYPE_CHECKING:
    from pcmb.axes import OutputAxis


_QUIET = "no progress bar, no log of the dask backend"


def _address_flag(command: argparse.ArgumentParser) -> None:
    """``--address``: a dask cluster of the user's (implies the dask backend)."""
    command.add_argument(
        "--address",
        metavar="SCHEDULER",
        help="run on the dask cluster whose scheduler is at this address, e.g. "
        "tcp://HOST:8786 (implies --backend dask; overrides execution.address; uses every "
        "thread of the cluster unless --jobs is given)",
    )


def _check_address(args: argparse.Namespace) -> None:
    """``--address`` goes with no backend but dask."""
    backend = getattr(args, "backend", None)
    if args.address is not None and backend not in (None, "dask"):
        raise UsageError(f"--address needs --backend dask (it implies it), got --backend {backend}")


def _journal_flags(command: argparse.ArgumentParser, what: str) -> None:
    """``--resume`` and ``--fresh``: continue the journals of an interrupted ``what``, or
    discard them and start over (one or the other)."""
    either = command.add_mutually_exclusive_group()
    either.add_argument("--resume", action="store_true", help=f"continue an interrupted {what}")
    either.add_argument(
        "--fresh",
        action="store_true",
        help=f"discard what an interrupted {what} left (its journal, even unreadable) and "
        "start over",
    )


def _parser() -> argparse.ArgumentParser:
    kinds = "\n".join(f"  {kind:<9} {entry.summary}" for kind, entry in ADAPTERS.items())
    parser = argparse.ArgumentParser(
        prog="pcmb",
        description="Simulations with error bars: polynomial chaos by stochastic collocation.",
        epilog=f"model kinds (model.kind):\n{kinds}\nevery config key: docs/config.md",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="run a study and write its HDF5 result")
    run.add_argument("config", help="YAML study configuration")
    run.add_argument("-o", "--output", help="result file (overrides the config's output)")
    _campaign_flags(run, "run", "a file at the output that is not a pcmb result")
    run.add_argument(
        "--strict",
        action="store_true",
        help=f"exit {EXIT_UNRELIABLE} when the diagnostics call an expansion unreliable",
    )
    run.add_argument(
        "--pdb",
        action="store_true",
        help="run the model in this process (--backend inprocess) and open pdb at the first "
        "exception of the model's code",
    )

    validate = commands.add_parser("validate", help="check a config without running anything")
    validate.add_argument("config")
    _address_flag(validate)

    inspect = commands.add_parser("inspect", help="summarise a result file (or a sweep.h5)")
    inspect.add_argument("result", help="an HDF5 file written by pcmb run or pcmb sweep")

    report = commands.add_parser("report", help="write figures and an index page of a result")
    report.add_argument("result", help="an HDF5 file written by pcmb run")
    report.add_argument(
        "--compare",
        nargs="+",
        default=[],
        metavar="OTHER.h5",
        help="results of the same model on the same grid to overlay (e.g. Monte Carlo)",
    )
    report.add_argument("-o", "--output", help="folder for the report (default: RESULT_report/)")

    compare = commands.add_parser(
        "compare", help="differences of mean and std over time between results"
    )
    compare.add_argument("reference", help="the result the others are compared with")
    compare.add_argument("others", nargs="+", metavar="OTHER", help="results to compare")
    compare.add_argument("-o", "--output", help="folder for overlay figures (default: none)")

    sweep = commands.add_parser(
        "sweep", help="run one case by several methods at rising cost against a reference"
    )
    sweep.add_argument("config", help="YAML study configuration (its sweep: section, if any)")
    sweep.add_argument(
        "-o",
        "--output",
        help="folder for sweep.csv, sweep.h5, sweep.png and the results "
        "(default: the config's output without .h5, followed by _sweep)",
    )
    sweep.add_argument(
        "--reference", metavar="REF.h5", help="result to measure against (not sweep.reference)"
    )
    _campaign_flags(sweep, "sweep", "files at the settings' result paths that are not pcmb results")

    commands.add_parser("schema", help="print the config JSON Schema (for editors)")
    return parser


def _campaign_flags(command: argparse.ArgumentParser, name: str, foreign: str) -> None:
    """The flags of a command that runs nodes (``run``, ``sweep``): workers, journal, output."""
    command.add_argument(
        "--jobs", type=int, help="worker processes (default: config, else all cores)"
    )
    command.add_argument("--backend", choices=list(BACKENDS), help="parallel backend")
    _address_flag(command)
    _journal_flags(command, name)
    command.add_argument("--force", action="store_true", help=f"overwrite {foreign}")
    command.add_argument("--quiet", action="store_true", help=_QUIET)


def _log(message: str) -> None:
    print(message, file=sys.stderr)


def _summary(config, address: str | None = None) -> str:
    """What ``pcmb validate`` prints; ``address``: ``--address``."""
    from pcmb.study import Study

    cluster = _cluster_line(config, address)  # first: an unreachable cluster is refused fast
    study = Study.from_config(config)
    nodes = study.node_set()
    outputs = study.check_model()
    lines = [
        f"config   {config.path}",
        f"name     {config.name}",
        f"model    {config.model.kind} ({ADAPTERS[config.model.kind].summary})",
        f"outputs  {', '.join(outputs)}",
        *(
            f"derived  {name}: {entry.kind} of {entry.source}"
            + "".join(f", {key} {value:g}" for key, value in entry.options.items())
            for name, entry in study.derived.items()
        ),
        f"time     {config.time.describe()}",
        "inputs   (germ order)",
    ]
    for name, dist in study.inputs.items():
        described = ", ".join(f"{k}={v}" for k, v in dist.describe().items() if k != "dist")
        lines.append(f"  {name:<10} {dist.describe()['dist']}({described})")
    for name, found in study.processes.items():
        lines.append(
            f"process  {name}: {found.covariance.description['kind']} covariance, "
            f"{found.terms} germs {name}[0]..{name}[{found.terms - 1}] keep "
            f"{found.captured_energy:.4f} of the variance (truncation error "
            f"{found.truncation_error:.3g}; eigenvalues to ~{found.eigenvalue_error:.1g}), "
            f"field of {found.grid.size} points"
        )
    design = study.design.record()
    seed = f", seed {design.seed}" if design.seed is not None else ""
    made = "no nodes: solved from the model's equations" if design.grid == "none" else "nodes"
    grid = "" if design.grid == "none" else f"{design.grid} "
    lines.append(f"method   {design.kind}: {design.label}, {grid}{made}{seed}")
    budget, first, most = study.planned_runs(nodes.size)
    rounds = f" in the first round, at most {budget} in all" if budget > nodes.size else ""
    upto = f"{first} to {most}" if most > first else f"{most}"
    checks = f" + {upto} held-out runs that check the expansion" if most else ""
    lines.append(
        f"runs     {nodes.size} model runs{rounds}{checks} "
        f"({config.execution.on_failure} on failure)"
    )
    lines += [cluster] if cluster else []
    where = "relative to the current directory; model files resolve against the config's folder"
    lines.append(f"output   {config.output or '(none: give -o)'} ({where})")
    lines.append(_space_line(study, nodes.size, outputs, config.output))
    lines.append(_memory_line(study, nodes.size, outputs, config.output))
    return "\n".join(lines)


def _memory_line(study, n_nodes: int, outputs, output: str | None) -> str:
    """The ``memory`` line of the summary; checks that the run fits or streams (raises
    UsageError)."""
    from pcmb.run.memory import check_memory
    from pcmb.run.output import format_bytes

    estimate = study.memory_estimate(n_nodes, outputs)
    streams = study.why_not_streamed(output)
    available, plan = check_memory(
        estimate, study.memory, inputs=len(study.inputs), streams=streams
    )
    streamed = (
        ""
        if plan is None
        else f"; over {study.memory.describe(available)}: the runs stream to the file, "
        f"quantiles from a reservoir of {plan.reservoir_rows} runs"
    )
    return (
        f"memory   about {format_bytes(estimate.total)} at most in pcmb's process; "
        f"{format_bytes(available)} available{streamed}"
    )


def _cluster_line(config, address: str | None) -> str | None:
    """The ``cluster`` line of the summary, for a dask scheduler's address (``--address``,
    else ``execution.address``): its workers now; raises ClusterError if none answers."""
    from pcmb.run.backends import describe_cluster

    if address is not None:
        return f"cluster  {describe_cluster(address, '--address')}"
    if config.execution.backend == "dask" and config.execution.address is not None:
        return f"cluster  {describe_cluster(config.execution.address, 'execution.address')}"
    return None


def _space_line(study, n_nodes: int, outputs, output: str | None) -> str:
    """The ``size`` line of the summary; checks the output (raises ResultFileError)."""
    from pcmb.run.output import check_output, format_bytes

    estimate = study.size_estimate(n_nodes, outputs)
    size = (
        f"size     about {format_bytes(estimate.total)} at most: result file "
        f"{format_bytes(estimate.result)} + journal {format_bytes(estimate.journal)} while it runs"
    )
    if output is None:
        return size
    free = check_output(output, estimate)
    if Path(output).exists():  # a run refuses what is not a pcmb result without --force
        from pcmb.store import check_replaceable

        check_replaceable(output)
    return size if free is None else f"{size}; {format_bytes(free)} free there"


def _quiet_backend(quiet: bool, backend: str) -> AbstractContextManager[None]:
    """With ``--quiet``, the backend's own logging silenced for the command."""
    from pcmb.run.backends import silenced

    return silenced(backend) if quiet else nullcontext()


def _run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from pcmb.run.backends import warm_up

    if args.jobs is not None and args.jobs < 1:
        raise UsageError(f"--jobs must be >= 1, got {args.jobs}")
    if args.pdb and args.backend not in (None, "inprocess"):
        raise UsageError(
            f"--pdb debugs the model in this process: it takes --backend inprocess (or none), "
            f"not {args.backend}"
        )
    if args.pdb:
        args.backend = "inprocess"
    _check_address(args)
    if args.backend in (None, "loky") and args.address is None:
        warm_up(args.jobs)  # workers start while this process reads the config

    from pcmb.run.status import failure_report
    from pcmb.run.worker import post_mortem
    from pcmb.study import Study

    config = _load_config(args.config, check_sweep=False)  # a run ignores sweep:
    output = args.output or config.output
    if output is None:
        raise UsageError(f"{args.config}: no output file: give -o OUT.h5 or set 'output:'")
    changes = {} if args.jobs is None else {"jobs": args.jobs}
    if args.backend is not None:
        # A scheduler address only means something to dask.
        changes |= {"backend": args.backend} | ({} if args.backend == "dask" else {"address": None})
    if args.address is not None:  # every thread of the cluster, not the config's local jobs
        changes |= {"backend": "dask", "address": args.address, "jobs": args.jobs}
    address_key = "execution.address" if args.address is None else "--address"
    study = Study.from_config(config, changes, address_key)
    provenance = {
        "config": config.source_text or "",
        "config_sha256": config.sha256,
        "command_line": shlex.join(["pcmb", *argv]),
    }
    debugging = post_mortem() if args.pdb else nullcontext()
    _collect_from_here()
    with warnings.catch_warnings(), _quiet_backend(args.quiet, study.execution.backend), debugging:
        warnings.simplefilter("ignore", PcmbWarning)  # listed below, once each
        result = study.run(
            output,
            resume=args.resume,
            fresh=args.fresh,
            force=args.force,
            progress=not (args.quiet or args.pdb),
            provenance=provenance,
        )
    for warning in result.alerts:  # the notes are listed by inspect and the report
        _log(f"pcmb: warning: {warning}")
    if any(failure.traceback is not None for failure in result.failures):
        _log("pcmb: the nodes left out, once per cause with the model's traceback:")
        _log("\n".join(failure_report(result.failures, "  ")))
    _log(f"pcmb: wrote {output} ({plural(result.n_nodes, 'node')}, {result.seconds:.2f} s of runs)")
    unreliable = [name for name, found in result.diagnostics.items() if not found.reliable]
    if args.strict and unreliable:
        _log(f"pcmb: --strict: the expansion of {', '.join(unreliable)} is unreliable")
        return EXIT_UNRELIABLE
    return EXIT_OK


def _sweep(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from pcmb.run.backends import warm_up

    if args.jobs is not None and args.jobs < 1:
        raise UsageError(f"--jobs must be >= 1, got {args.jobs}")
    _check_address(args)
    if args.backend in (None, "loky") and args.address is None:
        warm_up(args.jobs)

    from pcmb.sweep.runner import run_sweep

    config = _load_config(args.config)
    _collect_from_here()
    folder = args.output
    if folder is None:
        if config.output is None:
            raise UsageError(f"{args.config}: no output folder: give -o DIR or set 'output:'")
        folder = config.output.removesuffix(".h5") + "_sweep"
    backend = "dask" if args.address is not None else args.backend or config.execution.backend
    with warnings.catch_warnings(), _quiet_backend(args.quiet, backend):
        warnings.simplefilter("ignore", PcmbWarning)  # stored in each setting's file
        outcome = run_sweep(
            config,
            folder,
            reference=args.reference,
            resume=args.resume,
            fresh=args.fresh,
            force=args.force,
            progress=not args.quiet,
            jobs=args.jobs,
            backend=args.backend,
            address=args.address,
            command_line=shlex.join(["pcmb", *argv]),
        )
    settings = len({(row.method, row.setting) for row in outcome.table.rows})
    studies = len({(row.method, row.setting, row.replicate) for row in outcome.table.rows})
    count = plural(settings, "setting")
    if studies != settings:
        count += f", {plural(studies, 'study', 'studies')} with replicates"
    _log(f"pcmb: wrote {', '.join(str(p) for p in outcome.files[:3])} ({count})")
    return EXIT_OK


def _load(path: str):
    from pcmb.store import load

    return load(path)


def _report(args: argparse.Namespace) -> int:
    from pcmb.analysis.report import write_report
    from pcmb.sweep.table import is_sweep_file

    _collect_from_here()

    if is_sweep_file(args.result):
        from pcmb.sweep.report import write_sweep_report
        from pcmb.sweep.table import read_sweep

        folder = args.output or str(Path(args.result).with_suffix("")) + "_report"
        with phase("drawing the sweep's figures", sys.stderr):
            written = write_sweep_report(read_sweep(args.result), folder, source=args.result)
        _log(f"pcmb: wrote {plural(len(written) - 1, 'figure')} and {written[-1]}")
        return EXIT_OK
    result = _load(args.result)
    others = [_load(path) for path in args.compare]
    folder = args.output or str(Path(args.result).with_suffix("")) + "_report"
    with phase("drawing the report's figures", sys.stderr):
        written = write_report(result, folder, source=args.result, comparisons=others)
    _log(f"pcmb: wrote {plural(len(written) - 1, 'figure')} and {written[-1]}")
    return EXIT_OK


def _compare(args: argparse.Namespace) -> int:
    from pcmb.analysis.comparison import compare, method_label

    _collect_from_here()

    reference = _load(args.reference)
    others = [_load(path) for path in args.others]
    names = [f"{path}: {method_label(r)}" for path, r in zip(args.others, others, strict=True)]
    own = f"{args.reference}: {method_label(reference)}"
    tables = [
        compare(reference, other, labels=(own, name)).table()
        for other, name in zip(others, names, strict=True)
    ]
    print("\n\n".join(tables))
    if args.output:
        from pcmb.analysis.report import write_comparison_figures

        with phase("drawing the comparison's figures", sys.stderr):
            written = write_comparison_figures(reference, others, args.output, labels=args.others)
        _log(f"pcmb: wrote {plural(len(written), 'figure')} to {args.output}")
    return EXIT_OK


def _placement(axis: OutputAxis | None, on_time: bool) -> str:
    """Where an output of ``pcmb inspect`` lives, unless on time: ``  on frequency [Hz], 40
    points`` or ``  scalar``."""
    if on_time:
        return ""
    if axis is None:
        return "  scalar"
    unit = f" [{axis.unit}]" if axis.unit else ""
    return f"  on {axis.name}{unit}, {axis.values.size} points"


def _runs_made(result) -> str:
    """Every model run a result holds: the design's, the held-out check's, the nominal one."""
    held_out = result.held_out
    checked = (
        "no held-out runs"
        if held_out is None
        else f"{len(held_out.ok)} held-out ({int(held_out.ok.sum())} ok)"
    )
    nominal = "1 nominal" if result.nominal else "no nominal run"
    total = result.n_nodes + (0 if held_out is None else len(held_out.ok)) + bool(result.nominal)
    made = f"{total} in all: {result.n_nodes} of the design, {checked}, {nominal}"
    return "; ".join(filter(None, (made, result.fitted_runs)))


def _inspect(path: str) -> str:
    import numpy as np

    from pcmb.run.status import failure_report

    result = _load(path)
    named_inputs = zip(result.input_names, result.distributions, strict=True)
    status = np.bincount(result.status.astype(int), minlength=3)
    lines = [
        f"file     {path}",
        f"name     {result.name}",
        f"method   {result.design.label}, {result.n_nodes} nodes: {status[1]} ok, "
        f"{status[2]} failed, {status[0]} pending; {result.seconds:.2f} s of runs",
        f"runs     {_runs_made(result)}",
        f"time     {result.times[0]} .. {result.times[-1]}, {result.times.size} points",
        "inputs   " + ", ".join(f"{n} ~ {d.law}" for n, d in named_inputs),
    ]
    design = dataclasses.asdict(result.design)
    shown = {k: v for k, v in design.items() if v is not None and k != "label"}  # label: above
    lines.append("design   " + ", ".join(f"{k} {v}" for k, v in shown.items()))
    for name, found in result.processes.items():
        lines.append(
            f"process  {name}: {found.covariance.description['kind']} covariance, "
            f"{found.terms} germs keep {found.captured_energy:.4f} of the variance, field of "
            f"{found.grid.size} points"
        )
    if result.multi_index is not None:
        lines.append(f"chaos    {result.multi_index.shape[0]} terms")
    lines.append(f"{'output':<12}{'mean min':>12}{'mean max':>12}{'std min':>12}{'std max':>12}")
    for name in result.outputs:
        mean, std = result.mean(name), result.std(name)
        lines.append(
            f"{name:<12}{mean.min():>12.4g}{mean.max():>12.4g}{std.min():>12.4g}{std.max():>12.4g}"
            + _placement(result.axis(name), result.on_time(name))
        )
    for name, found in result.diagnostics.items():
        held = (
            f"mean/std error up to {np.nanmax(found.holdout.statistics, initial=0.0):.3g}, "
            f"surrogate error up to {np.nanmax(found.holdout.error, initial=0.0):.3g} "
            f"({found.holdout.count} {'placed' if result.held_out.placed else 'drawn'} "
            "held-out runs)"
            if found.holdout is not None
            else "no held-out runs, estimated error up to "
            f"{np.nanmax(found.estimate, initial=0.0):.3g}"
        )
        axis = result.axis(name)
        undecided = found.reliable and found.undecided.any()
        if axis is None:  # a scalar: pass or fail, or too few runs to tell
            verdict = "undecided" if undecided else "reliable" if found.reliable else "UNRELIABLE"
        else:
            point = "time" if result.on_time(name) else f"{axis.name} point"
            verdict = (
                f"reliable at every {point}"
                if found.reliable
                else f"UNRELIABLE from {axis.name} = {found.failing_from:.4g}"
            )
            if undecided:
                first = axis.values[np.argmax(found.undecided)]
                verdict = f"undecided from {axis.name} = {first:.4g} (more held-out runs tell)"
        lines.append(
            f"checked  {name}: {verdict} (tolerance {found.tolerance:g} of the largest std; "
            f"{held}, decay up to {np.nanmax(found.decay, initial=0.0):.3g}"
            f"{result.checked_fit(name)})"
        )
    if result.report is not None:  # what the design concluded, in its own words
        lines += [f"{label:<9}{text}" for label, text in result.report.summary(result)]
    if result.nominal_params:
        nominal = ", ".join(f"{k}={v:.6g}" for k, v in result.nominal_params.items())
        lines.append(f"nominal  {nominal} ({'stored' if result.nominal else 'failed'})")
    if result.analysis is not None:
        spectra = [n for n, a in result.analysis.outputs.items() if a.spectrum is not None]
        first = next(iter(result.analysis.outputs.values()), None)
        times = "" if first is None else ", ".join(f"{t:g}" for t in first.pdf.at)
        lines.append(
            f"analysis quantile bands, PDFs at t = {times}; spectra: {', '.join(spectra) or 'none'}"
        )
    lines += [f"{result.severity(w):<9}{w}" for w in result.warnings]
    lines += failure_report(result.failures, "failed   ")
    return "\n".join(lines)


def _load_config(path: str, **options: bool):
    """The config at ``path`` (:func:`pcmb.config.schema.load_config`), read with one native
    thread (:mod:`pcmb.run.threads`): workers start meanwhile, and a random process's
    eigen-solve would otherwise spin a BLAS thread on every core they need."""
    from pcmb.config.schema import load_config
    from pcmb.run.threads import one_thread_here

    with one_thread_here():
        return load_config(path, **options)


def _command(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the parsed command; its exit code."""
    if args.command == "run":
        return _run(args, argv)
    if args.command == "validate":
        from pcmb.run.backends import checking_process

        # One worker process builds and checks the model (started first: it starts while
        # this process reads the config); no pool, since nothing runs.
        with checking_process():
            print(_summary(_load_config(args.config), args.address))
    elif args.command == "inspect":
        from pcmb.sweep.table import is_sweep_file, read_sweep, summary

        is_sweep = is_sweep_file(args.result)
        print(summary(read_sweep(args.result)) if is_sweep else _inspect(args.result))
    elif args.command == "report":
        return _report(args)
    elif args.command == "compare":
        return _compare(args)
    elif args.command == "sweep":
        return _sweep(args, argv)
    elif args.command == "schema":
        from pcmb.config.schema import config_json_schema

        print(json.dumps(config_json_schema(), indent=2))
    return EXIT_OK


class _Stopped(BaseException):
    """A stop signal (SIGTERM, SIGHUP), raised like Ctrl-C's ``KeyboardInterrupt`` so that
    everything running unwinds: workers killed, journal kept."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_stopped(signum: int, frame: object) -> None:
    raise _Stopped(signum)


@contextmanager
def _stopped_by_signals() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`_Stopped` while the command runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _raise_stopped) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _collect_from_here() -> None:
    """Garbage collection back on, if the command turned it off for its start (:func:`main`),
    with what exists now frozen out of it: the modules, classes and schema of the imports,
    which every full collection would walk again."""
    if not gc.isenabled():
        gc.freeze()
        gc.enable()


_RESUME_HINT = "finished nodes are kept in the journal (run the same command with --resume)"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pcmb`` command; returns the exit code.

    Called as the command (``argv`` not given) the process ends next: the workers it kept
    (started before a config error, or idle after the run) are killed on the way out. The
    command also collects no garbage while it imports and reads its config (about 150
    collections, 50 ms, that free nothing; :func:`_collect_from_here` turns collection back on
    where its work starts), and freezes what is left on the way out, so that the
    interpreter's final collection does not walk it (another 50 ms).
    """
    as_command = argv is None
    if as_command:
        gc.disable()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    try:
        with _stopped_by_signals():
            return _command(args, argv)
    except PcmbError as error:
        _log(
            f"pcmb: {error.label}:\n{error}"
            if "\n" in str(error)
            else f"pcmb: {error.label}: {error}"
        )
        return error.exit_code
    except BrokenPipeError:
        # stdout closed early (e.g. `pcmb schema | head`): not worth a traceback. Point
        # stdout at devnull so the interpreter's final flush does not fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except KeyboardInterrupt:
        _log(f"pcmb: interrupted (SIGINT); {_RESUME_HINT}")
        return 128 + signal.SIGINT
    except _Stopped as stop:
        _log(f"pcmb: stopped by {signal.Signals(stop.signum).name}; {_RESUME_HINT}")
        return 128 + stop.signum
    except SystemExit as exit_:
        # Raised by code pcmb ran on the user's behalf and could not attribute to a node (e.g.
        # a model class calling sys.exit() while it is built): never a silent success.
        _log(
            f"pcmb: unexpected error: code run by pcmb called sys.exit({exit_.code!r}) "
            "outside any node; nothing was written"
        )
        return EXIT_UNEXPECTED
    except Exception:
        _log("pcmb: unexpected error (please report it):\n" + traceback.format_exc())
        return EXIT_UNEXPECTED
    finally:
        if as_command:
            close_kept(kill=True)
            gc.freeze()


if __name__ == "__main__":
    sys.exit(main())
