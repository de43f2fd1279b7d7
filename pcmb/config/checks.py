"""The checks that need more than one section, or the model built as a worker would build it.

Each yields ``(key path, message)``; the caller locates them in the file.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

from pcmb.config.types import MAX_RUNS, MAX_VALUES
from pcmb.designs import MethodSettings, make_design
from pcmb.errors import ConfigError

if TYPE_CHECKING:
    from pcmb.config.schema import StudyConfig

__all__ = ["cross_check", "model_check"]


def cross_check(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Order mapping against the inputs; the number of runs and of stored values."""
    method, names = config.method, config.input_names
    if isinstance(method.order, dict):
        unknown = [key for key in method.order if key not in config.inputs]
        for key in unknown:
            yield f"method.order.{key}", f"names no input (inputs: {', '.join(names)})"
        missing = [name for name in names if name not in method.order]
        if missing:
            yield "method.order", f"no order given for input(s) {', '.join(missing)}"
        if unknown or missing:
            return
    settings = MethodSettings(
        kind=method.kind,
        orders=config.orders,
        basis=method.basis,
        samples=method.samples,
        seed=method.seed,
        fit=method.fit,
    )
    try:
        runs = make_design(dict(zip(names, config.distributions, strict=True)), settings).runs
    except ValueError as error:  # the design names the key: "method.<key>: what is wrong"
        key, _, message = str(error).partition(": ")
        yield key, message
        return
    key = "method.samples" if method.samples is not None else "method.order"
    if runs > MAX_RUNS:
        yield key, f"the design asks for {runs:.3g} runs, more than the limit of {MAX_RUNS:.0e}"
    elif runs * config.time.points > MAX_VALUES:
        yield (
            key,
            (
                f"the design asks for {runs} runs x {config.time.points} time points = "
                f"{runs * config.time.points:.3g} values per output, more than {MAX_VALUES:.0e}"
            ),
        )


def model_check(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Build the model as a worker would (the adapter reports its own keys), then check the
    inputs, the analysis and the time grid against it."""
    try:
        model = config.model_factory()()
    except ConfigError as exc:
        for problem in exc.problems:
            yield problem.path, problem.message
        return
    section = config.model
    label = type(model).__name__
    declared = getattr(model, "parameters", None)
    if declared is None or getattr(model, "nominal_from_params", False):
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
    if config.analysis is not None:
        kept = config.output_names or tuple(model.outputs)
        yield from config.analysis.settings().problems(config.times, kept)
    check_times = getattr(model, "check_times", None)
    if callable(check_times):
        try:
            check_times(config.times)
        except ConfigError as exc:
            for problem in exc.problems:
                yield problem.path or "time", problem.message
