"""The checks that need more than one section, or the model built as a worker would build it.

Each yields ``(key path, message)``; the caller locates them in the file.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING

from pcmb.analysis.derived import derived_problems
from pcmb.chaos.nodes import overflowing_inputs
from pcmb.config.types import MAX_RUNS, MAX_VALUES
from pcmb.designs import DESIGNS, make_design, section_key
from pcmb.errors import ConfigError

if TYPE_CHECKING:
    from pcmb.config.schema import MethodSpec, StudyConfig

__all__ = ["config_design", "cross_check", "model_check"]


def cross_check(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Order mapping against the inputs; the number of runs and of stored values; every
    input's value at every node a finite number; the ``derived:`` entries (one figure kind
    each, with its options)."""
    try:
        config.derived_outputs  # noqa: B018 - parsed for its problems
    except ConfigError as error:
        for problem in error.problems:
            yield problem.path, problem.message
    method = config.method
    order = getattr(method, "order", None)
    if isinstance(order, dict):
        unknown = [key for key in order if key not in config.inputs]
        for key in unknown:
            yield f"method.order.{key}", f"names no input (inputs: {', '.join(config.inputs)})"
        missing = [name for name in config.inputs if name not in order]
        if missing:
            yield "method.order", f"no order given for input(s) {', '.join(missing)}"
        if unknown or missing:
            return
    try:
        design = config_design(config)
    except ConfigError as error:  # the design names every problem of its keys
        for problem in error.problems:
            yield problem.path, problem.message
        return
    except ValueError as error:  # the design names the key: "method.<key>: what is wrong"
        key, _, message = str(error).partition(": ")
        yield key, message
        return
    # A design that runs in rounds is bounded by its budget, the others by their first round.
    rounds = method.size_key == method.budget_key
    key = f"method.{method.size_key}"
    runs = getattr(design, "budget", design.runs) if rounds else design.runs
    if runs > MAX_RUNS:
        yield key, f"the design asks for {_many(runs)} runs, more than the limit of {MAX_RUNS:.0e}"
    elif runs * config.time.points > MAX_VALUES:
        yield (
            key,
            (
                f"the design asks for {runs} runs x {config.time.points} time points = "
                f"{runs * config.time.points:.3g} values per output, more than {MAX_VALUES:.0e}"
            ),
        )
    elif not all(d.finite_at_nodes for d in config.distributions):
        # A design of a size to run, with inputs whose values only its nodes tell: the nodes
        # are made now, as the run will make them.
        for name, message in overflowing_inputs(design.nodes(), config.input_names):
            yield f"inputs.{name}", message


def _many(count: int) -> str:
    """A count for a message: ``1.26e+263``, or ``~10^417`` beyond the floats."""
    return f"{count:.3g}" if count < 1e300 else f"~10^{len(str(int(count))) - 1}"


def config_design(config: StudyConfig) -> object:
    """The design a config's ``method:`` makes on its inputs.

    Raises
    ------
    ValueError
        Settings the design cannot use (the message starts with the key).
    """
    inputs = dict(zip(config.input_names, config.distributions, strict=True))
    return make_design(inputs, config.method.settings(config.orders, config.diagnostics.tolerance))


def _intrusive(config: StudyConfig) -> object:
    """The config's intrusive design (``IntrusiveDesign``: it checks the model in a worker);
    ``None`` for a node design, or when the cross checks reject the settings (an order
    mapping that misses an input cannot even be read)."""
    if not hasattr(DESIGNS[section_key(config.method)], "check"):
        return None
    try:
        return config_design(config)
    except (ValueError, KeyError):
        return None


def _swept_intrusive(
    config: StudyConfig, swept: Iterable[tuple[str, MethodSpec]]
) -> Iterator[tuple[str, object]]:
    """(key path, check) of the first intrusive method of each key path in ``swept``."""
    seen = set()
    for where, method in swept:
        check = getattr(_intrusive(config.model_copy(update={"method": method})), "check", None)
        if check is not None and where not in seen:
            seen.add(where)
            yield where, check


def model_check(
    config: StudyConfig, swept: Iterable[tuple[str, MethodSpec]] = ()
) -> Iterator[tuple[str, str]]:
    """Build the model in a worker, as a run would (the adapter reports its own keys), then
    check the inputs, the analysis and the time grid against what it says of itself, and the
    intrusive methods among ``swept`` ((key path, method) of a sweep's settings, see
    :func:`pcmb.sweep.plan.swept_methods`) against the model's polynomial form."""
    from pcmb.run.backends import checking_pool
    from pcmb.run.executor import describe_model, run_in_worker

    # A model is only ever built in a worker process, here too: its crash is not pcmb's.
    try:
        with checking_pool(config.execution.backend, config.execution.jobs) as pool:
            factory = config.model_factory()
            facts = describe_model(factory, pool, config.times, tuple(config.inputs))
            # An intrusive method checks the model's polynomial form where the model lives.
            check = getattr(_intrusive(config), "check", None)
            if check is not None:
                yield from run_in_worker(factory, pool, check, config.output_names)
            for where, swept_check in _swept_intrusive(config, swept):
                for path, message in run_in_worker(factory, pool, swept_check, config.output_names):
                    yield where + path.removeprefix("method"), message
    except ConfigError as exc:
        for problem in exc.problems:
            yield problem.path, problem.message
        return
    section = config.model
    label = facts.name
    declared = facts.parameters
    if declared is None or facts.nominal_from_params:
        why = (
            f"{label} does not declare its parameters"
            if declared is None
            else f"a {section.kind} model takes every nominal value from model.params"
        )
        for name in config.inputs:
            if name not in section.nominal_names:
                yield (
                    f"inputs.{name}",
                    f"{name!r} has no nominal value in model.params ({why}): add it there",
                )
    else:
        for name in config.inputs:
            if name not in declared:
                yield (
                    f"inputs.{name}",
                    f"{name!r} is not a parameter of {label} (parameters: {', '.join(declared)})",
                )
    yield from facts.input_problems
    kept = tuple(config.output_names or facts.outputs)
    on_time = tuple(name for name in kept if name not in facts.axes)
    every = (*kept, *config.derived)  # a figure of merit is an output too
    if config.analysis is not None:
        yield from config.analysis.settings().problems(config.times, every, on_time)
    named = {
        "diagnostics.outputs": config.diagnostics.outputs,
        "sweep.outputs": config.sweep.outputs if config.sweep is not None else None,
    }
    for key, names in named.items():
        for index, name in enumerate(names or ()):
            if name not in every:
                outputs = ", ".join(every)
                yield f"{key}[{index}]", f"{name!r} is not an output (outputs: {outputs})"
    yield from facts.time_problems
    if config.derived:
        try:
            derived = config.derived_outputs
        except ConfigError:  # reported by cross_check
            return
        yield from derived_problems(derived, kept, on_time, config.times)
