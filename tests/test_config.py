"""Config loading: YAML traps, the schema, located problems, semantic checks, fuzzing.

Every broken config must give a ConfigError whose message names the file, the line and
the exact key path of the offending key (and, from the command line, exit code 2 with no
traceback and no file written).
"""

from __future__ import annotations

import hashlib
import json
import pickle
import subprocess
import sys
from pathlib import Path

import hypothesis.strategies as st
import jsonschema
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings

from pcmb.adapters.command import CommandModelFactory
from pcmb.adapters.command.spec import CommandModelSpec
from pcmb.adapters.python import PythonModelFactory
from pcmb.chaos import inputs
from pcmb.cli import main as cli_main
from pcmb.config import StudyConfig, config_json_schema, load_config, validate_config
from pcmb.designs import METHOD_KINDS, method_section
from pcmb.errors import ConfigError

DATA = Path(__file__).parent / "data"
SOURCE = DATA / "study.yaml"  # named in messages; the text is passed in, the folder is real

BASE = """\
name: decay study
model:
  kind: python
  entry: toy_models.py:Decay
  params: {k: 2.0, y0: 1.0}
  outputs: [y]
time: {start: 0.0, stop: 2.0, points: 21}
inputs:
  k: {dist: uniform, low: 1.5, high: 2.5}
  y0: {dist: normal, mean: 1.0, std: 1e-1}
method:
  kind: collocation
  order: 3
  basis: tensor
execution:
  jobs: 2
  backend: loky
  on_failure: abort
  retries: 1
output: results/decay.h5
"""


def plain_data(text: str = BASE):
    """The config as data, through PyYAML's own loader (which would read 1e-1 as text)."""
    return yaml.safe_load(text.replace("1e-1", "0.1"))


def load(text: str = BASE):
    return load_config(SOURCE, text=text)


def line_of(text: str, marker: str) -> int:
    """1-based line of the only line holding ``marker`` (independent of the loader)."""
    (line,) = [i for i, content in enumerate(text.splitlines(), 1) if marker in content]
    return line


# --------------------------------------------------------------------------- a valid config


def test_valid_config_loads_with_everything_derived():
    config = load()
    assert config.name == "decay study"
    assert config.input_names == ("k", "y0")
    assert config.distributions == [inputs.Uniform(1.5, 2.5), inputs.Normal(1.0, 0.1)]
    assert config.orders == (3, 3)
    assert config.output_names == ("y",)
    np.testing.assert_array_equal(config.times, np.linspace(0.0, 2.0, 21))
    assert config.source_text == BASE
    assert config.sha256 == hashlib.sha256(BASE.encode()).hexdigest()
    assert config.path == SOURCE
    assert config.base_dir == DATA.resolve()


def test_defaults():
    text = BASE.split("execution:")[0].replace("  basis: tensor\n", "")
    config = load(text)
    assert config.method.basis is None  # the method's own default: tensor for collocation
    assert config.output is None
    execution = config.execution
    assert (execution.jobs, execution.backend, execution.address) == (None, "loky", None)
    assert (execution.on_failure, execution.retries, execution.chunk_size) == ("abort", 1, None)


def test_model_factory_is_picklable_and_builds_the_model():
    factory = load().model_factory()
    assert isinstance(factory, PythonModelFactory)
    model = pickle.loads(pickle.dumps(factory))()
    assert model.parameters == {"k": 2.0, "y0": 1.0}


def test_config_is_frozen():
    config = load()
    with pytest.raises(ValueError, match="frozen"):
        config.name = "other"


def test_anisotropic_orders_follow_germ_order():
    config = load(BASE.replace("order: 3", "order: {y0: 1, k: 4}"))
    assert config.orders == (4, 1)


def test_validate_config_from_python_data():
    data = plain_data()
    config = validate_config(data, base_dir=DATA)
    assert config.orders == (3, 3)
    assert config.source_text is None
    data["method"]["order"] = -1
    with pytest.raises(ConfigError, match=r"^<config>: method.order: expected a value >= 0"):
        validate_config(data, base_dir=DATA)


# --------------------------------------------------------------------------- YAML traps


@pytest.mark.parametrize(
    ("written", "value"),
    [("1e5", 1e5), ("1.5e+5", 1.5e5), ("-2E-3", -2e-3), ("150000", 150000.0), (".5", 0.5)],
)
def test_numbers_in_any_notation(written, value):
    config = load(BASE.replace("low: 1.5", f"low: {written}").replace("high: 2.5", "high: 1e6"))
    assert config.inputs["k"].low == value
    assert isinstance(config.inputs["k"].low, float)


def test_yaml_12_plain_scalars():
    # YAML 1.1 would read `on` as True, 0o17 as a string, 2024-01-02 as a date, 1:30 as 90.
    text = BASE.replace("name: decay study", "name: 2024-01-02").replace("order: 3", "order: 0o17")
    text = text.replace("points: 21", "points: 0x15")
    config = load(text)
    assert config.name == "2024-01-02"
    assert config.method.order == 15
    assert config.time.points == 21
    with pytest.raises(ConfigError, match="name: expected a string, found 90"):
        load(BASE.replace("name: decay study", "name: 90"))
    with pytest.raises(ConfigError, match="'on' is not a parameter of Decay"):
        load(BASE.replace("  y0: {dist", "  on: {dist"))


def test_alias_bomb_is_refused():
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
    for level in "bcdefg":
        previous = chr(ord(level) - 1)
        bomb += f"{level}: &{level} [*{previous}, *{previous}, *{previous}, *{previous}, *{previous}, *{previous}, *{previous}, *{previous}, *{previous}, *{previous}]\n"  # noqa: E501
    with pytest.raises(ConfigError, match="more than 100000 nodes"):
        load(bomb)


# --------------------------------------------------------------------------- broken configs

# (id, text to replace in BASE, replacement, key path, marker on the expected line, fragment)
BROKEN = [
    ("unknown-key", "  basis:", "  bassis:", "method.bassis", "bassis", "did you mean 'basis'?"),
    ("unknown-top-key", "output:", "outptu:", "outptu", "outptu", "did you mean 'output'?"),
    ("low>=high", "low: 1.5, high: 2.5", "low: 2.5, high: 1.5", "inputs.k", "  k:", "low must"),
    ("negative-std", "std: 1e-1", "std: -1e-1", "inputs.y0", "y0: {", "std must be > 0"),
    ("order<0", "order: 3", "order: -1", "method.order", "order:", "expected a value >= 0"),
    ("missing-file", "toy_models.py", "nope.py", "model.entry", "entry:", "does not exist"),
    (
        "missing-attr",
        ":Decay",
        ":Decya",
        "model.entry",
        "entry:",
        "has no attribute 'Decya'; did you mean 'Decay'?",
    ),
    (
        "broken-import",
        "toy_models.py:Decay",
        "broken_import.py:X",
        "model.entry",
        "entry:",
        "RuntimeError: this module cannot be imported",
    ),
    (
        "constructor-rejects",
        "k: 2.0,",
        "k: -2.0,",
        "model.params",
        "params:",
        "Decay(**params) failed: ValueError: k must be > 0",
    ),
    (
        "unknown-output",
        "[y]",
        "[y, zz]",
        "model.outputs[1]",
        "outputs:",
        "'zz' is not an output of Decay (outputs: y, dy)",
    ),
    (
        "input-not-parameter",
        "  y0: {dist",
        "  q: {dist",
        "inputs.q",
        "q: {",
        "'q' is not a parameter of Decay (parameters: k, y0)",
    ),
    (
        "no-as-number",
        "stop: 2.0",
        "stop: no",
        "time.stop",
        "stop:",
        "expected a number, found the text 'no'",
    ),
    ("quoted-number", "low: 1.5", 'low: "1.5"', "inputs.k.low", "low:", "the text '1.5'"),
    (
        "bool-as-int",
        "order: 3",
        "order: true",
        "method.order",
        "order:",
        "expected an integer, found true",
    ),
    (
        "duplicate-key",
        "  order: 3",
        "  order: 3\n  order: 4",
        "method.order",
        "order: 4",
        "duplicate key 'order' (first at line 13, again at line 14)",
    ),
    (
        "bad-dist",
        "dist: uniform",
        "dist: unifrom",
        "inputs.k.dist",
        "unifrom",
        "expected one of uniform, loguniform, beta, normal, gamma, scipy, found the text "
        "'unifrom'; "
        "did you mean 'uniform'?",
    ),
    (
        "unknown-scipy",
        "dist: uniform, low: 1.5, high: 2.5",
        "dist: scipy, name: poisson",
        "inputs.k",
        "  k:",
        "no continuous distribution named 'poisson'",
    ),
    (
        "bad-scipy-params",
        "dist: uniform, low: 1.5, high: 2.5",
        "dist: scipy, name: lognorm, params: {s: -0.5}",
        "inputs.k",
        "  k:",
        "rejects params",
    ),
    (
        "scipy-missing-shape",
        "dist: uniform, low: 1.5, high: 2.5",
        "dist: scipy, name: lognorm, params: {scale: 2.0}",
        "inputs.k",
        "  k:",
        "missing: s",
    ),
    ("jobs-0", "jobs: 2", "jobs: 0", "execution.jobs", "jobs:", "expected a value >= 1"),
    (
        "backend-typo",
        "backend: loky",
        "backend: lokky",
        "execution.backend",
        "lokky",
        "expected 'loky', 'dask' or 'inprocess'",
    ),
    (
        "address-without-dask",
        "backend: loky",
        "backend: loky\n  address: tcp://h:8786",
        "execution.address",
        "address:",
        "only used with backend: dask",
    ),
    ("retries<0", "retries: 1", "retries: -1", "execution.retries", "retries:", ">= 0"),
    (
        "samples-missing",
        "kind: collocation\n  order: 3\n  basis: tensor",
        "kind: montecarlo",
        "method.samples",
        "method:",
        "required key is missing (needed by kind montecarlo)",
    ),
    (
        "fit-with-collocation",
        "kind: collocation",
        "kind: collocation\n  fit: regression",
        "method.fit",
        "fit:",
        "not a setting of kind collocation (it belongs to montecarlo, lhs, sobol",
    ),
    (
        "fit-needs-order",
        "kind: collocation\n  order: 3\n  basis: tensor",
        "kind: lhs\n  fit: regression\n  samples: 10",
        "method.order",
        "method:",
        "needed by fit regression",
    ),
    (
        "order-names-non-input",
        "order: 3",
        "order: {k: 2, y0: 1, zz: 3}",
        "method.order.zz",
        "order:",
        "names no input (inputs: k, y0)",
    ),
    (
        "order-misses-input",
        "order: 3",
        "order: {k: 2}",
        "method.order",
        "order:",
        "no order given for input(s) y0",
    ),
    (
        "grid-too-large",
        "order: 3",
        "order: 9999",
        "method.order",
        "order:",
        "the design asks for 1e+08 runs",
    ),
    ("stop<=start", "stop: 2.0", "stop: 0.0", "time.stop", "time:", "expected stop > start"),
    ("points<2", "points: 21", "points: 1", "time.points", "time:", "expected a value >= 2"),
    ("not-h5", "decay.h5", "decay.nc", "output", "output:", "ending in .h5"),
    (
        "kind-typo",
        "kind: python",
        "kind: pyhton",
        "model.kind",
        "pyhton",
        "expected one of python, mujoco, command",
    ),
    (
        "entry-missing",
        "  entry: toy_models.py:Decay\n",
        "",
        "model.entry",
        "model:",
        "required key is missing",
    ),
    (
        "inputs-empty",
        "  k: {dist: uniform, low: 1.5, high: 2.5}\n  y0: {dist: normal, mean: 1.0, std: 1e-1}\n",
        "  {}\n",
        "inputs",
        "inputs:",
        "expected at least 1 entry, found 0",
    ),
    (
        "input-not-identifier",
        "  k: {dist",
        "  1k: {dist",
        "inputs.1k",
        "1k:",
        "expected a name made of letters",
    ),
    (
        "function-without-outputs",
        "toy_models.py:Decay\n  params: {k: 2.0, y0: 1.0}\n  outputs: [y]",
        "toy_models.py:undeclared_point\n  params: {k: 2.0, y0: 1.0}",
        "model.outputs",
        "model:",
        "does not declare its outputs",
    ),
    (
        "function-input-without-nominal",
        "toy_models.py:Decay\n  params: {k: 2.0, y0: 1.0}",
        "toy_models.py:decay_point\n  params: {k: 2.0}",
        "inputs.y0",
        "y0: {",
        "'y0' has no nominal value in model.params",
    ),
    (
        "unsupported-tag",
        "order: 3",
        "order: !!binary AAAA",
        "method.order",
        "order:",
        "unsupported YAML tag",
    ),
    ("syntax-error", "  basis: tensor", "  basis: [tensor", "", "execution:", "YAML syntax error"),
    (
        "bind-entry-typo",
        "kind: python\n  entry: toy_models.py:Decay\n  params: {k: 2.0, y0: 1.0}\n  outputs: [y]",
        "kind: mujoco\n  xml: scene.xml\n  bind:\n    k: [{field: body_mass,"
        " nam: bob}]\n  outputs: {y: {qpos: hinge}}",
        "model.bind.k[0].nam",
        "nam: bob",
        "did you mean 'name'?",
    ),
    (
        "mujoco-output-kind",
        "kind: python\n  entry: toy_models.py:Decay\n  params: {k: 2.0, y0: 1.0}\n  outputs: [y]",
        "kind: mujoco\n  xml: scene.xml\n  outputs:\n    y: {qacc: hinge}",
        "model.outputs.y",
        "qacc",
        "expected one of {qpos: joint}",
    ),
]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("old", "new", "path", "marker", "fragment"),
    [case[1:] for case in BROKEN],
    ids=[case[0] for case in BROKEN],
)
def test_broken_config_names_file_line_and_key(old, new, path, marker, fragment):
    assert BASE.count(old) == 1
    text = BASE.replace(old, new)
    with pytest.raises(ConfigError) as exc:
        load(text)
    line = line_of(text, marker)
    prefix = f"{SOURCE}:{line}: {path}: " if path else f"{SOURCE}:{line}: "
    lines = str(exc.value).splitlines()
    assert any(entry.startswith(prefix) and fragment in entry for entry in lines), lines


@pytest.mark.parametrize(
    ("old", "new", "path"),
    [
        # uniform: the range fits a float but its midpoint does not
        ("k: {dist: uniform, low: 1.5, high: 2.5}", "k: {dist: uniform, low: 1.0e+308, "
         "high: 1.5e+308}", "inputs.k"),
        # normal: the nodes of order 3 fit, those of a swept order 8 (out to 4.5 std) do not
        ("std: 1e-1}", "std: 5.0e+307}\nsweep: {methods: [{kind: collocation, order: [2, 8]}]}",
         "sweep.methods[0].inputs.y0"),
    ],
    ids=["uniform-midpoint", "swept-normal"],
)  # fmt: skip
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # numpy's, on the way
def test_inputs_whose_values_overflow_at_some_node_are_refused(old, new, path):
    with pytest.raises(ConfigError) as exc:
        load(BASE.replace(old, new))
    assert f": {path}: " in str(exc.value) and "not a finite number" in str(exc.value)


def test_every_problem_is_reported_at_once():
    text = BASE.replace("jobs: 2", "jobs: 0").replace("low: 1.5", "low: x")
    text = text.replace("decay.h5", "decay.nc")
    with pytest.raises(ConfigError) as exc:
        load(text)
    assert [p.path for p in exc.value.problems] == ["inputs.k.low", "execution.jobs", "output"]
    assert [p.line for p in exc.value.problems] == [9, 16, 20]


@pytest.mark.parametrize(
    ("method", "paths"),
    [
        ("kind: regression\n  tolerance: 0.01", ["method.samples", "method.order"]),
        ("kind: lhs\n  fit: regression", ["method.samples", "method.order"]),
        (
            "kind: regression\n  max_samples: 90",
            ["method.samples", "method.order", "method.max_samples"],
        ),
    ],
    ids=["regression", "lhs-fit", "regression-budget"],
)
def test_every_missing_key_of_a_method_is_reported_at_once(method, paths):
    """A design's own checks name every problem of its keys together, each located."""
    text = BASE.replace("kind: collocation\n  order: 3\n  basis: tensor", method)
    with pytest.raises(ConfigError) as exc:
        load(text)
    assert sorted(p.path for p in exc.value.problems) == sorted(paths)
    assert all(p.line is not None for p in exc.value.problems)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "the file is empty"),
        ("# only a comment\n", "the file is empty"),
        ("- 1\n- 2\n", "expected a mapping, found a list"),
        ("just text\n", "expected a mapping, found the text 'just text'"),
        ("name: a\n---\nname: b\n", "expected a single document"),
        (
            "name: a\n\x00\n",
            r"^\S+:2: YAML error: special characters are not allowed \(found U\+0000\)",
        ),
        ("[" * 1500 + "]" * 1500, "nested too deeply"),
    ],
    ids=[
        "empty",
        "comment-only",
        "top-level-list",
        "top-level-text",
        "two-documents",
        "control-character",
        "deep-nesting",
    ],
)
def test_whole_file_problems(text, message):
    with pytest.raises(ConfigError, match=message):
        load(text)


def test_missing_file():
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read the config: no such file"):
        load_config(DATA / "nope.yaml")


def test_the_model_kinds_are_the_registered_adapters():
    from pcmb.adapters.registry import ADAPTERS

    with pytest.raises(ConfigError) as exc:
        load(BASE.replace("kind: python", "kind: fortran"))
    assert f"expected one of {', '.join(ADAPTERS)}, found the text 'fortran'" in str(exc.value)
    with pytest.raises(ConfigError) as exc:
        load(BASE.replace("  kind: python\n", ""))
    assert f"model.kind: required key is missing (one of {', '.join(ADAPTERS)})" in str(exc.value)
    model = config_json_schema()["properties"]["model"]
    assert set(model["discriminator"]["mapping"]) == set(ADAPTERS)


def test_a_function_entry_must_be_marked():
    text = BASE.replace(":Decay", ":plain_point")
    with pytest.raises(ConfigError) as exc:
        load(text)
    (problem,) = exc.value.problems
    assert problem.path == "model.entry" and problem.line == line_of(text, "entry:")
    assert '@pcmb.pointwise(outputs=("y", ...))' in problem.message
    assert "@pcmb.batched" in problem.message


def test_marked_functions_load_from_a_config():
    text = BASE.replace(":Decay", ":decay_batch")
    model = load(text).model_factory()()
    out = model.simulate({"k": np.array([1.0, 2.0])}, np.linspace(0.0, 1.0, 3))
    assert out["y"].shape == (2, 3)


@pytest.mark.slow
def test_loading_a_python_config_does_not_import_mujoco():
    code = (
        "import sys; from pcmb.config.schema import load_config; "
        f"load_config({str(DATA / 'valid_python.yaml')!r}); print('mujoco' in sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.stdout.strip() == "False", result.stderr


# --------------------------------------------------------------------------- command kind

COMMAND = f"""\
name: command study
model:
  kind: command
  command: {sys.executable} sim_decay.py out.csv --deck deck.txt
  files: [sim_decay.py]
  templates: [deck.txt]
  params: {{k: 2.0, y0: 1.0, mode: 0.0}}
  outputs: [y, dy]
  output: {{file: out.csv}}
  timeout: 30
time: {{start: 0.0, stop: 2.0, points: 5}}
inputs:
  k: {{dist: uniform, low: 1.5, high: 2.5}}
method: {{kind: collocation, order: 1}}
"""


def test_command_config_builds_a_working_model(tmp_path):
    config = load(COMMAND.replace("timeout: 30", f"timeout: 30\n  run_dir: {tmp_path}"))
    assert isinstance(config.model, CommandModelSpec)
    factory = config.model_factory()
    assert isinstance(factory, CommandModelFactory)
    model = pickle.loads(pickle.dumps(factory))()
    k = np.array([1.5, 2.5])
    out = model.simulate({"k": k}, config.times)
    # Exact: the simulator gets the values as repr text and writes repr text back.
    np.testing.assert_array_equal(out["y"], np.exp(-k[:, None] * config.times))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("old", "new", "path", "marker", "fragment"),
    [
        (
            "templates: [deck.txt]",
            "templates: [nope.txt]",
            "model.templates[0]",
            "templates:",
            "nope.txt does not exist",
        ),
        ("mode: 0.0", "mod: 0.0", "model.templates[0]", "templates:", "line 3: placeholder"),
        ("{file: out.csv}", "{file: out.dat}", "model.output.format", "output:", "'dat' is none"),
        ("timeout: 30", "timeout: 0", "model.timeout", "timeout:", "expected a value > 0"),
        (
            f"command: {sys.executable} sim",
            "command: pcmb-no-such-program sim",
            "model.command[0]",
            "command:",
            "not found on PATH",
        ),
        (  # a command written as one string: its words are counted after splitting
            "out.csv --deck",
            "'{{ kk }}' --deck",
            "model.command[2]",
            "command:",
            "placeholder '{{kk}}' names no parameter (known: k, y0, mode, times.start",
        ),
        (
            "  k: {dist",
            "  c: {dist",
            "inputs.c",
            "c: {",
            "'c' has no nominal value in model.params (a command model takes every nominal",
        ),
        # keys under model.command are reported there, not at model (the union's tag)
        (f"command: {sys.executable} sim", "command: [] #", "model.command", "command:", "least 1"),
        (f"command: {sys.executable} sim", "command: 5 #", "model.command", "command:", "a list"),
        (f"command: {sys.executable} sim", "command: [a, 5] #", "model.command[1]", "[a, 5]", ""),
        (
            f"command: {sys.executable} sim",
            'command: "a \'b" #',
            "model.command",
            "command:",
            "cannot split the command: No closing quotation",
        ),
        (
            "files: [sim_decay.py]",
            "files: [sim_decay.py, deck.txt, 3]",
            "model.files[2]",
            "files:",
            "expected a string, found 3",
        ),
        (
            "files: [sim_decay.py]",
            "files: [sim_decay.py, nope.py]",
            "model.files[1]",
            "files:",
            "nope.py does not exist",
        ),
        (
            "files: [sim_decay.py]",
            "files: [sim_decay.py, sim_decay.py]",
            "model.files[1]",
            "files:",
            "sim_decay.py is already used by model.files[0]",
        ),
        ("{file: out.csv}", "{file: params.json}", "model.output.file", "output:", "reserved"),
    ],
)
def test_broken_command_config(old, new, path, marker, fragment):
    text = COMMAND.replace(old, new)
    with pytest.raises(ConfigError) as exc:
        load(text)
    line = line_of(text, marker)
    lines = str(exc.value).splitlines()
    assert any(e.startswith(f"{SOURCE}:{line}: {path}: ") and fragment in e for e in lines), lines


# --------------------------------------------------------------------------- mujoco kind

MUJOCO = """\
name: hinge
model:
  kind: mujoco
  xml: hinge.xml
  params: {L: 1.0}
  bind:
    m: [{field: body_mass, name: bob}]
  init: {qpos: {hinge: 0.5}}
  outputs:
    theta: {qpos: hinge}
    x: {xpos: bob, axis: 0}
time: {start: 0.0, stop: 1.0, points: 11}
inputs:
  L: {dist: uniform, low: 0.9, high: 1.1}
  m: {dist: uniform, low: 0.9, high: 1.1}
method: {kind: collocation, order: 1}
"""


@pytest.mark.slow
def test_mujoco_config_builds_the_scene():
    config = load(MUJOCO)
    assert config.output_names == ("theta", "x")
    model = pickle.loads(pickle.dumps(config.model_factory()))()
    assert set(config.input_names) <= set(model.parameters)
    out = model.simulate({"L": np.array([1.0]), "m": np.array([1.0])}, config.times)
    assert out["theta"].shape == (1, 11)
    assert out["theta"][0, 0] == 0.5  # the fixed initial state from init


@pytest.mark.slow
@pytest.mark.parametrize(
    ("old", "new", "path", "marker", "fragment"),
    [
        ("name: bob}", "name: bobb}", "model.bind.m[0].name", "bobb", "no body named 'bobb'"),
        ("points: 11", "points: 14", "time", "time:", "whole number of the scene's timesteps"),
        ("  m: {dist", "  q: {dist", "inputs.q", "q: {", "'q' is not a parameter of"),
        ("hinge.xml", "nope.xml", "model.xml", "xml:", "nope.xml"),
        (
            "{qpos: hinge}",
            "{qpos: hinge, axis: 0}",
            "model.outputs.theta.axis",
            "theta:",
            "unknown key (allowed: qpos)",
        ),
    ],
)
def test_broken_mujoco_config(old, new, path, marker, fragment):
    text = MUJOCO.replace(old, new)
    with pytest.raises(ConfigError) as exc:
        load(text)
    line = line_of(text, marker)
    lines = str(exc.value).splitlines()
    assert any(e.startswith(f"{SOURCE}:{line}: {path}: ") and fragment in e for e in lines), lines


# --------------------------------------------------------------------------- command line


@pytest.mark.slow
@pytest.mark.parametrize(
    ("old", "new", "path", "marker", "fragment"),
    [case[1:] for case in BROKEN],
    ids=[case[0] for case in BROKEN],
)
def test_cli_reports_broken_config_with_exit_2_and_writes_nothing(
    tmp_path, capsys, old, new, path, marker, fragment
):
    text = BASE.replace(old, new)
    config = tmp_path / "study.yaml"
    config.write_text(text)
    # The model entry resolves against the config's folder: point it back at the fixtures.
    config.write_text(text.replace("entry: ", f"entry: {DATA}/"))
    out = tmp_path / "out.h5"
    for argv in (["validate", str(config)], ["run", str(config), "-o", str(out)]):
        try:
            code = cli_main(argv)
        except SystemExit as exc:
            code = exc.code
        captured = capsys.readouterr()
        assert code == 2, captured.err
        assert "Traceback" not in captured.err
        assert f": {path}: " in captured.err if path else "YAML syntax error" in captured.err
        assert fragment in captured.err
        assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.yaml"]


# --------------------------------------------------------------------------- JSON Schema


def test_json_schema_accepts_the_valid_config_and_rejects_broken_ones():
    schema = config_json_schema()
    json.dumps(schema)  # plain JSON
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    validator.validate(plain_data())
    validator.validate(plain_data(COMMAND))
    for old, new in [
        ("backend: loky", "backend: lokky"),
        ("  basis:", "  bassis:"),
        ("jobs: 2", "jobs: 0"),
        ("kind: python", "kind: pyhton"),
    ]:
        assert not validator.is_valid(plain_data(BASE.replace(old, new)))


# --------------------------------------------------------------------------- fuzzing

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["uniform", "scipy", "lognorm", "collocation", "dask", "no", "1e5", "y"]),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


def check_outcome(text: str) -> None:
    """Either a config or a ConfigError whose problems are all located; nothing else."""
    try:
        config = load(text)
    except ConfigError as exc:
        assert exc.problems
        for problem in exc.problems:
            assert problem.path or problem.line is not None, problem
        return
    assert isinstance(config, StudyConfig)


def paths_of(data, prefix=()):
    yield prefix
    if isinstance(data, dict):
        for key, value in data.items():
            yield from paths_of(value, (*prefix, key))
    elif isinstance(data, list):
        for index, value in enumerate(data):
            yield from paths_of(value, (*prefix, index))


BASE_DATA = plain_data()
BASE_PATHS = [p for p in paths_of(BASE_DATA) if p]
FUZZ = settings(
    max_examples=150, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)


@pytest.mark.slow
@FUZZ
@given(
    path=st.sampled_from(BASE_PATHS),
    action=st.sampled_from(["replace", "delete", "add"]),
    value=values,
    key=st.text(max_size=8),
)
def test_fuzz_mutated_config(path, action, value, key):
    data = json.loads(json.dumps(BASE_DATA))
    parent = data
    for part in path[:-1]:
        parent = parent[part]
    if action == "delete":
        del parent[path[-1]]
    elif action == "replace":
        parent[path[-1]] = value
    elif isinstance(parent, dict):
        parent[key] = value
    check_outcome(yaml.safe_dump(data, allow_unicode=True))


@pytest.mark.slow
@FUZZ
@given(document=values)
def test_fuzz_random_documents(document):
    check_outcome(yaml.safe_dump(document, allow_unicode=True))


@pytest.mark.slow
@FUZZ
@given(
    position=st.integers(0, len(BASE)),
    cut=st.integers(0, 8),
    insert=st.one_of(st.text(alphabet=":-{}[],&*!|>'\"#%@` \n\tabc0123.e", max_size=6), st.text()),
)
def test_fuzz_text_edits(position, cut, insert):
    check_outcome(BASE[:position] + insert + BASE[position + cut :])


@pytest.mark.parametrize(
    ("time", "key", "message"),
    [
        (
            "{values: [0.0, 2.0, 0.5]}",
            "time.values",
            "expected strictly increasing times, found 0.5 after 2.0 (entry 2)",
        ),
        ("{start: 0.0, stop: 2.0, points: 5, spacing: log}", "time.spacing", "needs start > 0"),
        ("{values: [0.0, 1.0], stop: 2.0}", "time", "expected a grid (stop, points"),
        ("{values: [1.0]}", "time.values", "expected at least 2 entries, found 1"),
    ],
)
def test_a_bad_time_form_is_refused_at_its_key(time, key, message):
    with pytest.raises(ConfigError) as error:
        load(BASE.replace("{start: 0.0, stop: 2.0, points: 21}", time))
    assert f"{key}: " in str(error.value) and message in str(error.value)


def test_the_time_forms_give_their_grids():
    listed = load(BASE.replace("{start: 0.0, stop: 2.0, points: 21}", "{values: [0.0, 0.3, 2.0]}"))
    np.testing.assert_array_equal(listed.times, [0.0, 0.3, 2.0])
    logged = load(
        BASE.replace(
            "start: 0.0, stop: 2.0, points: 21", "start: 0.01, stop: 100.0, points: 5, spacing: log"
        )
    )
    np.testing.assert_allclose(logged.times, [0.01, 0.1, 1.0, 10.0, 100.0], rtol=1e-14)


def test_a_key_of_another_method_is_refused_at_its_key_naming_the_methods_that_take_it():
    with pytest.raises(ConfigError) as exc:
        load(BASE.replace("  basis: tensor\n", "  basis: tensor\n  samples: 64\n"))
    # The kinds that take samples, from the registry (a new sampling design joins the list).
    takers = [
        k for k in METHOD_KINDS if "samples" in type(method_section({"kind": k})).model_fields
    ]
    assert {"montecarlo", "lhs", "sobol", "regression"} <= set(takers)
    assert [(p.path, p.line, p.message) for p in exc.value.problems] == [
        (
            "method.samples",
            15,
            f"not a setting of kind collocation (it belongs to {', '.join(takers)})",
        )
    ]
    with pytest.raises(ConfigError) as exc:
        load(
            BASE.replace("kind: collocation\n  order: 3\n  basis: tensor", "kind: lhs\n  level: 2")
        )
    assert [(p.path, p.message) for p in exc.value.problems] == [
        ("method.level", "not a setting of kind lhs (it belongs to collocation)")
    ]


@pytest.mark.parametrize(
    "method",
    [
        "collocation\n  order: 3",
        "adaptive\n  tolerance: 0.01",
        "regression\n  order: 2\n  samples: 20",
    ],
)
def test_every_design_takes_the_seed_of_its_held_out_runs(method):
    """``seed`` seeds the held-out check of every design (the SPEC's example sets it beside
    ``kind: collocation``), so no design refuses it."""
    config = load(
        BASE.replace("kind: collocation\n  order: 3\n  basis: tensor", f"kind: {method}\n  seed: 7")
    )
    assert config.method.seed == 7


def test_the_schema_shows_method_as_a_union_keyed_by_kind_each_with_its_own_keys():
    schema = config_json_schema()
    method = schema["properties"]["method"]
    assert method["discriminator"]["propertyName"] == "kind"
    branches = {
        kind: schema["$defs"][ref.rpartition("/")[2]]["properties"]
        for kind, ref in method["discriminator"]["mapping"].items()
    }
    assert set(branches) == set(METHOD_KINDS)
    assert "samples" in branches["lhs"] and "samples" not in branches["collocation"]
    assert "level" in branches["collocation"] and "level" not in branches["regression"]
    assert set(branches["linearization"]) == {"kind", "validation", "seed"}
