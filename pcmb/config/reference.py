"""The Markdown reference of every config key (``docs/config.md``), generated from the schema.

``python -m pcmb.config.reference > docs/config.md`` regenerates the page and
``tests/test_config_docs.py`` checks that it is current. Every table is read from the pydantic
models of :class:`~pcmb.config.schema.StudyConfig` (field annotations, constraints, defaults
and ``Field(description=...)``; the first paragraph of each section's docstring), so the
lists of kinds come from the registries the schema reads. Only the page's header and its
example are written here. Nothing imports this module at start-up.
"""

from __future__ import annotations

import json
import sys
import types
import typing
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal, get_args, get_origin

import annotated_types
from pydantic import AfterValidator, BaseModel, BeforeValidator, Discriminator
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from pcmb.config.types import Name, selecting_key, unique
from pcmb.wording import markdown

__all__ = ["EXAMPLE", "config_reference", "main", "undescribed_keys"]

#: How the key path shows a mapping's key and a list's index.
KEY = "<name>"
INDEX = "[i]"

#: The page's example: the default study (``configs/quarter_car.yaml``). Its relative model
#: path resolves against ``configs/``; ``tests/test_config_docs.py`` validates it there.
EXAMPLE = """\
name: quarter-car-combined
model:
  kind: python
  entry: ../models/quarter_car.py:QuarterCar   # relative to this file's folder
  params:                                      # nominal values; the inputs vary some of them
    terrain: sine
    damper: linear
    spring: cubic
    Ms: 250.0
    Mu: 35.0
    k: 6.0e+6
    c: 1000.0
    kT: 1.5e+5
    A: 0.05
    f: 1.0
  outputs: [x1, x2]
time: {start: 0.0, stop: 3.0, points: 301}
inputs:                                        # the order is the germ order
  A: {dist: uniform, low: 0.025, high: 0.075}
  kT: {dist: uniform, low: 1.2e+5, high: 1.8e+5}
  c: {dist: uniform, low: 800.0, high: 1200.0}
method: {kind: collocation, order: 5, basis: tensor}
execution: {jobs: 2, backend: loky, on_failure: abort}
output: results/quarter_car.h5                 # relative to the current directory
analysis:
  psd: [x1]
  pdf_times: [3.0]
  pdf_freqs: [1.33, 3.0]
  units: {x1: m, x2: m}
  time_unit: s
"""

_HEADER = """\
# Config reference

> Generated from the config schema by `python -m pcmb.config.reference > docs/config.md`;
> do not edit by hand (`tests/test_config_docs.py` checks that this page is current).

A config is one YAML file that describes one study: the simulator and its nominal
parameters (`model`), the output time grid (`time`), the uncertain inputs (`inputs`), how
the nodes are made and the chaos coefficients recovered (`method`), where the runs execute
(`execution`), what to store besides mean, standard deviation and Sobol' indices
(`analysis`), and the result file (`output`). `pcmb run CONFIG` runs it; in Python,
`pcmb.config.load_config(path)` returns the validated `StudyConfig`.

- **Paths.** Relative paths to the model's files (a Python entry file, an MJCF scene, a
  command's program, templates and files) resolve against the folder of the config file, so
  a config and its model move together; `output` (and a command's `run_dir`) resolve
  against the current directory.
- **Values.** Plain scalars follow YAML 1.2: `1e5`, `1.5e+5` and `0x10` are numbers, only
  `true`/`false` are booleans (`yes`, `no`, `on`, `off` are text), `null` or `~` is null.
  A number written as text (`"1.5"`) or as a boolean is an error. A *name* (an input,
  output or parameter name) is made of letters, digits and `_`, not starting with a digit.
- **Strictness.** Unknown keys and duplicate keys are errors. Every problem is reported at
  once, as `file:line: key.path: message`.
- **Checking.** `pcmb validate CONFIG` checks everything a run would check and runs
  nothing: the YAML, the schema, the method against the inputs, then the model built as a
  worker would build it (its parameters, outputs and time grid against the inputs and the
  analysis). `pcmb schema` prints the JSON Schema of config files, for editors with YAML
  schema support.

**Figures of merit** (`derived`) are questions asked of time outputs without model code:

```yaml
derived: {x1_peak: {max_abs: x1}, x1_rms: {rms: x1}, x2_at_2s: {at: x2, time: 2.0},
          x1_settle: {settling_time: x1, band: 0.02}}
```

Each entry names one new output (not an output of the model) and holds one figure key
naming a time output, with that figure's options. After the runs pcmb computes the figure
of every run (and of every held-out run and the nominal run) from its stored time series on
the grid, y_j = y(t_j), j = 0..T-1:

- `max_abs`: max_j |y_j|;
- `rms`: sqrt(∫ y² dt / (t_{T-1} - t_0)), the integral by the trapezoid rule on the grid;
- `at` with `time: s`: y(s), linear between the two grid points around s (s within the grid);
- `settling_time` with `band: b` (default 0.02): the settling time into the band
  |y - y_f| <= b·|y_f| around the final value y_f = y_{T-1}, i.e. the time the run leaves
  the band for the last time: with j the last grid point outside the band, the time
  between t_j and t_{j+1} where the excess |y - y_f| - b·|y_f| crosses 0, linear between
  the two; t_0 when the run never leaves the band. A run that ends before settling has
  its settling time near the end of the grid: choose the grid long enough.

A figure is then an output like any other, one number per run: mean, std, Sobol' indices,
PDF and diagnostics, stored under `/outputs/<name>/` without the time dimension (`values`
(N,), `mean`, `std`, `sobol_first` (n,), ...) and listed by `pcmb inspect`. The chaos of a
maximum (or of a settling time, which jumps where an oscillation's last excursion leaves
the band) may converge slowly: the diagnostics then say so. `pcmb validate` reports a
figure that names no time output (`derived.x1_peak.max_abs: 'x9' is not an output;
outputs are x1, x2`) or a time off the grid.

In the tables below, a key path shows a mapping's keys as `<name>` and a list's entries as
`[i]`. A key that is not required may be left out; its default applies ("not set": the key
is absent, and the description says what that means).
"""

_NAME_CHECK = get_args(Name)[1].func
_NOUNS = {
    "string": "strings",
    "number": "numbers",
    "integer": "integers",
    "name": "names",
    "section": "sections",
}


# --------------------------------------------------------------------------- types


@dataclass
class _Nested:
    """Sections reached through a field: ``suffix`` extends the key path (``.<name>``,
    ``[i]``); ``forms`` are the section classes, each with what tells it apart (the value of
    ``selector``, else its first key; ``None`` for the only form)."""

    suffix: str
    forms: list[tuple[type[BaseModel], str | None]]
    selector: Any = None
    #: The selector of each form when they differ (a union picked by key around unions
    #: picked by a value, as ``inputs``: ``dist`` or ``process``); ``None``: ``selector``.
    selectors: list[Any] | None = None


def _unwrap(tp: Any, meta: typing.Iterable[Any] = ()) -> tuple[Any, list[Any], Any]:
    """The bare type, its flattened metadata and its discriminator."""
    found = list(meta)
    while get_origin(tp) is Annotated:
        found = [*tp.__metadata__, *found]
        tp = tp.__origin__
    flat: list[Any] = []
    discriminator = None
    for item in found:
        if isinstance(item, FieldInfo):
            flat.extend(item.metadata)
            if item.discriminator is not None:
                discriminator = item.discriminator
        else:
            flat.append(item)
            if isinstance(item, Discriminator):
                discriminator = item.discriminator
    return tp, flat, discriminator


def _is_section(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _bounds(meta: list[Any]) -> str:
    parts = []
    for item in meta:
        for kind, symbol in (
            (annotated_types.Gt, ">"),
            (annotated_types.Ge, ">="),
            (annotated_types.Lt, "<"),
            (annotated_types.Le, "<="),
        ):
            if isinstance(item, kind):
                parts.append(f"{symbol} {getattr(item, kind.__name__.lower())}")
    return " and ".join(parts)


def _plural(text: str) -> str:
    first, _, rest = text.partition(" ")
    if first in _NOUNS:
        return " ".join([_NOUNS[first], rest]).strip()
    return f"({text})"


def _label(section: type[BaseModel], selector: Any) -> str:
    """What tells a form of a union apart: its ``selector`` value, else its first key."""
    if isinstance(selector, str):
        return " | ".join(map(str, get_args(section.model_fields[selector].annotation)))
    return selecting_key(section)


def _forms(members: list[Any], selector: Any) -> list[tuple[type[BaseModel], str, Any]] | None:
    """(section, label, selector) of every form of a union whose members are sections or
    unions of sections; ``None`` if some member is neither."""
    found: list[tuple[type[BaseModel], str, Any]] = []
    for member in members:
        tp, _, inner = _unwrap(member)
        if _is_section(tp):
            found.append((tp, _label(tp, selector), selector))
        elif get_origin(tp) in (typing.Union, types.UnionType):
            more = _forms([m for m in get_args(tp) if m is not type(None)], inner)
            if more is None:
                return None
            found += more
        else:
            return None
    return found


def _selector_key(section: type[BaseModel], selector: Any) -> str:
    """The key that picks a form: ``selector``, else the section's first key."""
    return selector if isinstance(selector, str) else selecting_key(section)


def _describe(
    tp: Any, meta: typing.Iterable[Any] = (), selector: Any = None
) -> tuple[str, _Nested | None]:
    """A readable type and the sections nested in it (a :class:`_Nested` or ``None``)."""
    tp, meta, inner = _unwrap(tp, meta)
    selector = selector if selector is not None else inner
    inputs = [
        m.json_schema_input_type
        for m in meta
        if isinstance(m, BeforeValidator) and m.json_schema_input_type is not PydanticUndefined
    ]
    if inputs:  # the value is converted from what is written: document what is written
        return _describe(inputs[0])
    after = {m.func for m in meta if isinstance(m, AfterValidator)}
    min_length = max(
        (m.min_length for m in meta if isinstance(m, annotated_types.MinLen)), default=0
    )
    size = "non-empty " if min_length == 1 else f"{min_length} or more: " if min_length else ""
    bounds = _bounds(meta)
    origin = get_origin(tp)

    if origin in (typing.Union, types.UnionType):
        members = [m for m in get_args(tp) if m is not type(None)]
        sections = [_unwrap(m)[0] for m in members]
        if all(_is_section(s) for s in sections):
            if len(sections) == 1:
                return "section", _Nested("", [(sections[0], None)])
            by = f"`{selector}`" if isinstance(selector, str) else "key"
            forms = [(s, _label(s, selector)) for s in sections]
            return f"section (one form per {by})", _Nested("", forms, selector)
        picked = _forms(members, selector)
        if picked is not None:  # unions of sections inside a union picked by key
            forms = [(s, label) for s, label, _ in picked]
            selectors = [chosen for _, _, chosen in picked]
            keys = ", ".join(dict.fromkeys(f"`{_selector_key(s, c)}`" for s, _, c in picked))
            return f"section (one form per {keys})", _Nested("", forms, selector, selectors)
        texts, nested = [], None
        for member in members:
            text, found = _describe(member)
            texts.append(text)
            nested = nested or found
        return ", or ".join(texts) if any("," in t for t in texts) else " or ".join(texts), nested
    if _is_section(tp):
        return "section", _Nested("", [(tp, None)])
    if origin is Literal:
        values = [f"`{v}`" for v in get_args(tp)]
        return (values[0], None) if len(values) == 1 else (f"one of: {', '.join(values)}", None)
    if origin in (list, tuple, set, frozenset):
        text, nested = _describe(get_args(tp)[0])
        distinct = "distinct " if unique in after else ""
        if nested is not None:
            nested = _Nested(INDEX + nested.suffix, nested.forms, nested.selector, nested.selectors)
        return f"{size}list of {distinct}{_plural(text)}", nested
    if origin is dict:
        key, _ = _describe(get_args(tp)[0])
        value, nested = _describe(get_args(tp)[1])
        if nested is not None:
            nested = _Nested(
                f".{KEY}{nested.suffix}", nested.forms, nested.selector, nested.selectors
            )
        return f"{size}mapping: {key} → {value}", nested
    if tp is typing.Any:
        return "any value", None
    if tp is str:
        noun = "name" if _NAME_CHECK in after else "string"
        return f"{size}{noun}", None
    if tp is bool:
        return "true or false", None
    if tp is int:
        return f"integer {bounds}".strip(), None
    if tp is float:
        return f"number {bounds}".strip(), None
    return getattr(tp, "__name__", str(tp)), None


# --------------------------------------------------------------------------- tables


@dataclass
class _Row:
    path: str
    type: str
    required: bool
    default: str
    description: str


@dataclass
class _Table:
    path: str
    title: str
    level: int
    doc: str
    rows: list[_Row] = field(default_factory=list)
    children: list[_Table] = field(default_factory=list)


def _paragraph(section: type[BaseModel]) -> str:
    return markdown((section.__doc__ or "").strip().split("\n\n")[0])


def _sentence(section: type[BaseModel]) -> str:
    first = _paragraph(section)
    end = first.find(". ")
    return first if end < 0 else first[: end + 1]


def _default(info: FieldInfo) -> str:
    if info.is_required():
        return ""
    value = info.get_default(call_default_factory=True)
    if value is None:
        return "not set"
    if isinstance(value, BaseModel):
        value = value.model_dump(exclude_defaults=True)
    if isinstance(value, str) and value and value.strip() == value and value[0] not in "[{":
        return f"`{value}`"
    return f"`{json.dumps(value, default=str)}`"


def _table(
    section: type[BaseModel], path: str, title: str, level: int, context: str, form: Any
) -> _Table:
    """The table of one section and, after it, the tables of the sections nested in it.

    ``context`` names the form the section belongs to (``kind: mujoco``) in nested titles;
    ``form`` is ``(selector, choices)`` when the section is one form of a union.
    """
    table = _Table(path, title, level, _paragraph(section) if path else "")
    selector, choices = form if form else (None, [])
    for name, info in section.model_fields.items():
        key = f"{path}.{name}" if path else name
        text, nested = _describe(info.annotation, info.metadata, info.discriminator)
        description = markdown(info.description)
        if not description and name == selector:
            description = f"selects the form: {', '.join(f'`{c}`' for c in choices)}"
        elif not description and nested and len(nested.forms) == 1 and not nested.suffix:
            description = _sentence(nested.forms[0][0])  # a section: its docstring's summary
        table.rows.append(_Row(key, text, info.is_required(), _default(info), description))
        if nested is not None:
            # The top level's sections are headed like the top level itself.
            inner = level + 1 if path else level
            table.children.append(_nested(key + nested.suffix, nested, inner, context))
    return table


def _nested(path: str, nested: _Nested, level: int, context: str) -> _Table:
    """The table(s) of the sections a field leads to: one table, or one per form."""
    where = f" ({context})" if context else ""
    if len(nested.forms) == 1:
        ((section, _),) = nested.forms
        return _table(section, path, f"`{path}`{where}", level, context, None)
    choices = [label for _, label in nested.forms]
    listed = ", ".join(f"`{c}`" for c in choices)
    if nested.selectors is not None:
        return _mixed(path, nested, level, context, where)
    if isinstance(nested.selector, str):
        doc = f"One form per `{nested.selector}`: {listed}."
        labels = [f"`{nested.selector}: {c}`" for c in choices]
    else:
        doc = f"One form per key present: {listed}."
        labels = [f"key `{c}`" for c in choices]
    rows = [
        (section, label, (nested.selector, choices))
        for (section, _), label in zip(nested.forms, labels, strict=True)
    ]
    return _form_tables(path, level, where, doc, rows)


def _form_tables(
    path: str, level: int, where: str, doc: str, rows: list[tuple[type, str, Any]]
) -> _Table:
    """A table headed ``path`` with one child table per form: (section, label, selector)."""
    group = _Table(path, f"`{path}`{where}", level, doc)
    for section, label, selector in rows:
        group.children.append(
            _table(section, path, f"`{path}` with {label}{where}", level + 1, label, selector)
        )
    return group


def _mixed(path: str, nested: _Nested, level: int, context: str, where: str) -> _Table:
    """The tables of a union whose forms are picked by different keys (``dist: uniform``,
    ..., ``process: kl``): one table per form, titled by its key and value."""
    picks = [
        (section, _selector_key(section, chosen), chosen)
        for (section, _), chosen in zip(nested.forms, nested.selectors or [], strict=True)
    ]
    values = {key: [_first_value(s, key) for s, k, _ in picks if k == key] for _, key, _ in picks}
    doc = (
        "One form per "
        + "; or ".join(
            f"`{key}`: " + ", ".join(f"`{v}`" for v in listed) for key, listed in values.items()
        )
        + "."
    )
    rows = [
        (
            section,
            f"`{key}: {_first_value(section, key)}`",
            (key, values[key]) if isinstance(chosen, str) else None,
        )
        for section, key, chosen in picks
    ]
    return _form_tables(path, level, where, doc, rows)


def _first_value(section: type[BaseModel], key: str) -> str:
    """The value a form's selecting key must have (its ``Literal``)."""
    (value,) = get_args(section.model_fields[key].annotation)
    return str(value)


def _tables() -> _Table:
    from pcmb.config.schema import StudyConfig

    return _table(StudyConfig, "", "Top level", 2, "", None)


def _walk(table: _Table) -> typing.Iterator[_Table]:
    yield table
    for child in table.children:
        yield from _walk(child)


def _cell(text: str) -> str:
    return text.replace("|", "\\|") or " "


def _render(table: _Table) -> list[str]:
    lines = [f"{'#' * table.level} {table.title}", ""]
    if table.doc:
        lines += [table.doc, ""]
    if table.rows:
        lines += ["| key | type | required | default | description |", "|---|---|---|---|---|"]
        for row in table.rows:
            cells = [f"`{row.path}`", row.type, "yes" if row.required else "no", row.default]
            cells.append(row.description)
            lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
        lines.append("")
    for child in table.children:
        lines += _render(child)
    return lines


def config_reference() -> str:
    """The Markdown reference of every config key (the text of ``docs/config.md``).

    Returns
    -------
    str
        The page: a header, an example, then one table per section (the top level, each
        ``model`` kind and its nested sections, ``time``, each ``inputs`` distribution,
        ``method``, ``execution``, ``analysis``) with every key's path, type, whether it is
        required, its default and its description.
    """
    lines = [_HEADER, "## Example", "", "```yaml", EXAMPLE.rstrip("\n"), "```", ""]
    lines += _render(_tables())
    return "\n".join(lines).rstrip("\n") + "\n"


def undescribed_keys() -> list[str]:
    """Key paths whose field has no ``Field(description=...)`` (and no generated one)."""
    paths = [row.path for t in _walk(_tables()) for row in t.rows if not row.description]
    return list(dict.fromkeys(paths))


def main() -> None:
    """Write the page to standard output as UTF-8."""
    sys.stdout.buffer.write(config_reference().encode("utf-8"))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
