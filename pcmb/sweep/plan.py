"""What a sweep runs: the ``sweep:`` section expanded into one method setting per value.

Each entry of ``sweep.methods`` is a ``method:`` block with at most one key given as a list;
every value of that list is one setting, an ordinary study (a block without a list is one
setting: a method without a cost to vary, such as statistical linearization). Without a
``sweep:`` section the config's own method is swept over a rising cost
(:func:`default_sweep`). Seeded methods (sampling, regression) are run ``sweep.replicates``
times with seeds ``seed``, ``seed + 1``, …
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from pcmb.config.checks import config_design, cross_check
from pcmb.designs import MethodSection, MethodSpec, NodeDesign, method_section, section_key
from pcmb.designs.sampling import monte_carlo

if TYPE_CHECKING:
    from pcmb.config.schema import StudyConfig

__all__ = [
    "SWEPT_DEFAULTS",
    "Setting",
    "SweepPlan",
    "default_sweep",
    "plan_sweep",
    "sweep_problems",
    "swept_methods",
]

#: Keys a sweep entry always sets unless it gives them: held-out runs and the nominal run are
#: checks and extras, not part of a method's cost.
SWEPT_DEFAULTS: Mapping[str, Any] = {"validation": 0}
#: Keys that never appear in a method's label (the swept key and the seed are shown apart).
_UNLABELLED = ("kind", "grid", "seed", "validation")
#: Largest number of settings the default sweep makes of one cost key.
_DEFAULT_STEPS = 8


@dataclass(frozen=True)
class Setting:
    """One study of a sweep.

    Attributes
    ----------
    entry:
        Index of its entry in ``sweep.methods`` (-1 for the reference).
    method:
        The method's label in tables and charts, e.g. ``collocation:smolyak`` or
        ``collocation basis=total``.
    setting:
        The swept value as ``key=value``, e.g. ``order=3``.
    replicate:
        0, 1, … for the seeds of a seeded method (always 0 otherwise).
    spec:
        The full ``method:`` block of the study.
    """

    entry: int
    method: str
    setting: str
    replicate: int
    spec: MethodSection

    @property
    def stem(self) -> str:
        """File name of the setting's result, without ``.h5``."""
        if self.entry < 0:
            return "reference"
        text = f"{self.entry:02d}-{self.method}-{self.setting}"
        text += f"-r{self.replicate}" if self.replicate else ""
        return re.sub(r"[^A-Za-z0-9=.,_-]+", "_", text)


@dataclass(frozen=True)
class SweepPlan:
    """The settings of a sweep, in order, the reference (``None``: a file given by the user),
    and the outputs errors are computed for (``sweep.outputs``, else ``diagnostics.outputs``;
    ``None``: every output of the reference)."""

    settings: tuple[Setting, ...]
    reference: Setting | None
    outputs: tuple[str, ...] | None


def _swept_key(entry: Mapping[str, Any]) -> list[str]:
    return [key for key, value in entry.items() if isinstance(value, list)]


def _labels(entries: list[tuple[Mapping[str, Any], MethodSection, str]]) -> list[str]:
    """One label per entry: its design key, followed, where entries share a key, by the
    fixed keys that tell them apart (``collocation basis=total``)."""
    keys = [section_key(spec) for _, spec, _ in entries]
    labels = []
    for (entry, _, swept), key in zip(entries, keys, strict=True):
        twins = [e for (e, _, w), k in zip(entries, keys, strict=True) if k == key]
        differing = [
            f"{name}={_text(value)}"
            for name, value in entry.items()
            if name not in (*_UNLABELLED, swept) and any(twin.get(name) != value for twin in twins)
        ]
        labels.append(" ".join([key, *differing]))
    return labels


def _fixed(entry: Mapping[str, Any]) -> str:
    """The setting text of a block without a list: its keys, ``kind=linearization``."""
    return " ".join(f"{key}={_text(value)}" for key, value in entry.items() if key != "validation")


def _text(value: Any) -> str:
    """A setting value as compact text: ``3``, ``1e-04``, ``a:2,b:3``, ``0.0;1.0``."""
    if isinstance(value, Mapping):
        return ",".join(f"{k}:{_text(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ";".join(_text(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _expand(entry: Mapping[str, Any]) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """(swept key, index, method data) per value of the entry's list; for an entry without a
    list (a method without a cost to vary, e.g. linearization) one setting with key ``""``;
    nothing for an entry with several lists (:func:`sweep_problems` says why)."""
    keys = _swept_key(entry)
    if not keys:
        yield "", 0, {**SWEPT_DEFAULTS, **entry}
        return
    if len(keys) != 1:
        return
    key = keys[0]
    for index, value in enumerate(entry[key]):
        yield key, index, {**SWEPT_DEFAULTS, **entry, key: value}


def _first(entry: Mapping[str, Any], index: int) -> tuple[str, int, dict[str, Any]]:
    """The first setting of an entry.

    Raises
    ------
    ValueError
        An entry with several lists (:func:`sweep_problems` explains it at its key).
    """
    for found in _expand(entry):
        return found
    raise ValueError(f"sweep.methods[{index}] varies more than one key")


def _design(config: StudyConfig, spec: MethodSection) -> NodeDesign:
    """The design of a method block on the config's inputs."""
    return config_design(config.model_copy(update={"method": spec}))


def _settings_of(
    config: StudyConfig, entry: Mapping[str, Any], index: int, label: str, replicates: int
) -> Iterator[Setting]:
    for key, _, data in _expand(entry):
        spec = method_section(data)
        copies = replicates if _design(config, spec).record().seed is not None else 1
        text = f"{key}={_text(data[key])}" if key else _fixed(entry)
        for replicate in range(copies):
            seeded = spec.model_copy(update={"seed": spec.seed + replicate}) if replicate else spec
            yield Setting(index, label, text, replicate, seeded)


def _rising(value: Any, key: str) -> list[Any]:
    """Values of a cost key rising to ``value`` (the config's own)."""
    if key == "order":
        if isinstance(value, Mapping):  # every input's order raised together, capped at its own
            top = max(value.values())
            return [{k: min(p, step) for k, p in value.items()} for step in range(1, top + 1)]
        return list(range(1, value + 1))[-_DEFAULT_STEPS:]
    if key == "level":
        return list(range(value + 1))[-_DEFAULT_STEPS:]
    if key == "tolerance":
        return [value * 100.0, value * 10.0, value]
    return sorted({max(2, value // 8), max(2, value // 4), max(2, value // 2), value})


def _finer(value: Any, key: str) -> Any:
    """A much more accurate value of a cost key, for the default reference."""
    if key == "order":
        return {k: p + 2 for k, p in value.items()} if isinstance(value, Mapping) else value + 2
    if key == "level":
        return value + 2
    if key == "tolerance":
        return value / 100.0
    return value * 16


def default_sweep(section: MethodSection, runs: int) -> dict[str, Any]:
    """The ``sweep:`` section used when a config has none.

    Its own method at a rising cost (order 1 to its order, levels up to its level, samples
    /8, /4, /2, 1, tolerances ×100, ×10, 1); Monte Carlo with 16, 64, 256, … samples up to
    twice the ``runs`` of the config's method (at least 64), unless the method samples
    itself; and the same method at a finer cost as the reference (order + 2, level + 2,
    samples × 16, tolerance / 100).
    """
    method = section.model_dump(exclude_defaults=True)
    key = section.cost_key
    top = max(64, 2 * runs)
    comparator = monte_carlo([16 * 4**k for k in range(_DEFAULT_STEPS) if 16 * 4**k <= top], 1)
    if key is None:  # a method without a cost to raise (statistical linearization)
        return {"methods": [method, comparator], "reference": method}
    if key == "samples":  # a fixed sample at each cost: adding samples is what is swept
        method = {k: v for k, v in method.items() if k not in ("tolerance", "max_samples")}
    value = method.get(key, 1000)  # order: auto within max_runs: its budget is the cost
    rising = _rising(value, key)
    if key == section.budget_key:  # no budget below the first round, which it refuses
        rising = sorted({max(runs, budget) for budget in rising})
    methods = [{**method, key: rising}]
    if key != "samples":
        methods.append(comparator)
    return {"methods": methods, "reference": {**method, key: _finer(value, key)}}


def plan_sweep(config: StudyConfig) -> SweepPlan:
    """The settings a config's sweep runs (its ``sweep:``, else :func:`default_sweep`).

    The config must have passed :func:`sweep_problems` (``load_config`` checks it).
    """
    section = config.sweep
    if section is None:
        runs = _design(config, config.method).runs
        found = default_sweep(config.method, runs)
        methods, outputs, replicates = found["methods"], config.diagnostics.outputs, 1
        reference_data = {**SWEPT_DEFAULTS, **found["reference"]}
    else:
        methods, replicates = section.methods, section.replicates
        outputs = section.outputs or config.diagnostics.outputs
        reference_data = (
            None if section.reference is None else {**SWEPT_DEFAULTS, **section.reference}
        )
    firsts = [(entry, *_first(entry, index)) for index, entry in enumerate(methods)]
    labels = _labels([(e, method_section(data), key) for e, key, _, data in firsts])
    settings = tuple(
        setting
        for index, (entry, label) in enumerate(zip(methods, labels, strict=True))
        for setting in _settings_of(config, entry, index, label, replicates)
    )
    reference = None
    if reference_data is not None:
        spec = method_section(reference_data)
        fixed = " ".join(
            f"{k}={_text(v)}" for k, v in reference_data.items() if k not in _UNLABELLED
        )
        reference = Setting(-1, section_key(spec), fixed, 0, spec)
    return SweepPlan(settings, reference, None if outputs is None else tuple(outputs))


def swept_methods(config: StudyConfig) -> Iterator[tuple[str, MethodSection]]:
    """(key path, method) of every setting of the sweep and of its reference, when the sweep
    itself is valid (:func:`sweep_problems` reports it otherwise); none without ``sweep:``."""
    if config.sweep is None:
        return
    try:
        plan = plan_sweep(config)
    except ValueError:  # a bad sweep: sweep_problems reports it
        return
    for setting in (*plan.settings, *([plan.reference] if plan.reference else [])):
        where = f"sweep.methods[{setting.entry}]" if setting.entry >= 0 else "sweep.reference"
        yield where, setting.spec


def _design_problems(
    config: StudyConfig, spec: MethodSection, prefix: str, swept: str | None, index: int
) -> Iterator[tuple[str, str]]:
    for path, message in cross_check(config.model_copy(update={"method": spec})):
        key = path.removeprefix("method").lstrip(".")
        head = key.split(".")[0].split("[")[0]
        where = f"{prefix}.{key}" if key else prefix
        if swept is not None and head == swept and key == swept:
            where += f"[{index}]"
        yield where, message


def sweep_problems(config: StudyConfig) -> Iterator[tuple[str, str]]:
    """Every problem of the ``sweep:`` section, as (key path, message), before anything runs:
    an entry that varies no key or more than one, a setting the schema or its design
    refuses (named down to the list item, e.g. ``sweep.methods[1].order[2]``)."""
    from pcmb.config.messages import schema_problems

    section = config.sweep
    if section is None:
        return
    seen: set[tuple[str, str]] = set()
    for index, entry in enumerate(section.methods):
        prefix = f"sweep.methods[{index}]"
        keys = _swept_key(entry)
        if len(keys) > 1:
            yield (
                prefix,
                "a sweep entry varies at most one key, given as a list of values "
                f"(e.g. order: [1, 2, 3]); found {', '.join(keys)}",
            )
            continue
        for key, position, data in _expand(entry):
            try:
                spec = method_section(data)
            except ValidationError as error:
                problems = schema_problems(error, MethodSpec, prefix=("sweep", "methods", index))
                found = [
                    (
                        f"{p.path}[{position}]" if p.path == f"{prefix}.{key}" else p.path,
                        p.message,
                    )
                    for p in problems
                ]
            else:
                found = list(_design_problems(config, spec, prefix, key, position))
            for problem in found:
                if problem not in seen:
                    seen.add(problem)
                    yield problem
    if section.reference is not None:
        data = {**SWEPT_DEFAULTS, **section.reference}
        try:
            spec = method_section(data)
        except ValidationError as error:
            for p in schema_problems(error, MethodSpec, prefix=("sweep", "reference")):
                yield p.path, p.message
        else:
            yield from _design_problems(config, spec, "sweep.reference", None, 0)
