"""Model adapters: entry points, marked functions, external commands, factories.

References: the decay law y = y0 exp(-k t), dy = -k y, evaluated in the test. Where the
adapter only moves numbers (exact float text in templates and CSV, binary NPY/NPZ, JSON
floats) the comparison is exact: any difference would be a transport bug, not round-off.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import cloudpickle
import joblib
import numpy as np
import pytest

from pcmb.adapters.command import CommandModel, CommandModelFactory, split_command
from pcmb.adapters.protocol import Model, ModelDefinitionError, ModelFactory
from pcmb.adapters.python import (
    BatchFunctionModel,
    FunctionModel,
    ObjectModelFactory,
    PythonModelFactory,
    as_model,
    batched,
    is_function_model,
    load_entry,
    model_factory,
    pointwise,
)
from pcmb.errors import ConfigError, ModelError, UsageError

DATA = Path(__file__).parent / "data"
TIMES = np.linspace(0.0, 2.0, 5)
# numpy's exp may take a SIMD or a scalar path depending on array layout; both are within a
# few ulp of the exact value, so independent evaluations agree to ~1e-15 relative.
EXP_RTOL = 1e-14


def decay(k: np.ndarray, y0: np.ndarray | float = 1.0) -> dict[str, np.ndarray]:
    """The reference: (B,) parameters -> (B, T) outputs on TIMES."""
    k = np.atleast_1d(k)[:, None]
    y = np.asarray(y0, dtype=float).reshape(-1, 1) * np.exp(-k * TIMES)
    return {"y": y, "dy": -k * y}


def only_problem(exc: pytest.ExceptionInfo[ConfigError]) -> tuple[str, str]:
    (problem,) = exc.value.problems
    return problem.path, problem.message


# --------------------------------------------------------------------------- load_entry


def test_load_entry_from_file_relative_to_base_dir():
    cls = load_entry("toy_models.py:Decay", DATA)
    assert cls.__name__ == "Decay"
    assert cls.outputs == ("y", "dy")


def test_load_entry_dotted_attribute_and_module():
    method = load_entry("toy_models.py:Decay.simulate", DATA)
    assert method.__name__ == "simulate"
    join = load_entry("os.path:join", DATA)
    assert join is os.path.join


def test_load_entry_package_next_to_config(tmp_path):
    package = tmp_path / "pcmb_test_pkg_entry"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "sim.py").write_text("def f(params, times):\n    return {}\nf.outputs = ('y',)\n")
    before = list(sys.path)
    func = load_entry("pcmb_test_pkg_entry.sim:f", tmp_path)
    assert func.outputs == ("y",)
    assert sys.path == before  # the config folder is on sys.path only while importing


def test_load_entry_sibling_import(tmp_path):
    (tmp_path / "pcmb_test_helper.py").write_text("SCALE = 7.0\n")
    (tmp_path / "model.py").write_text("from pcmb_test_helper import SCALE\n")
    assert load_entry("model.py:SCALE", tmp_path) == 7.0


@pytest.mark.parametrize(
    ("entry", "fragment"),
    [
        ("toy_models.py", "expected 'path/to/file.py:Name'"),
        ("toy_models.py:", "expected 'path/to/file.py:Name'"),
        ("toy_models.py:Decay-2", "expected 'path/to/file.py:Name'"),
        ("missing_file.py:Model", "missing_file.py does not exist"),
        ("toy_models.py:Nope", "toy_models.py has no attribute 'Nope'"),
        ("toy_models.py:Decay.nope", "toy_models.py.Decay has no attribute 'nope'"),
        ("broken_import.py:X", "RuntimeError: this module cannot be imported"),
        ("pcmb_no_such_module_x:f", "cannot import module 'pcmb_no_such_module_x'"),
    ],
)
def test_load_entry_errors_name_the_problem(entry, fragment):
    with pytest.raises(ConfigError) as exc:
        load_entry(entry, DATA)
    path, message = only_problem(exc)
    assert path == "model.entry"
    assert fragment in message


# --------------------------------------------------------------------------- as_model


def test_as_model_constructs_class_with_params():
    model = as_model(load_entry("toy_models.py:Decay", DATA), {"k": 3.0})
    assert isinstance(model, Model)
    assert model.parameters == {"k": 3.0, "y0": 1.0}


def test_as_model_uses_instance_as_is_and_refuses_params():
    instance = load_entry("toy_models.py:DECAY", DATA)
    assert as_model(instance, {}) is instance
    with pytest.raises(ConfigError) as exc:
        as_model(instance, {"k": 1.0})
    assert only_problem(exc)[0] == "model.params"


def test_as_model_wraps_marked_functions():
    func = load_entry("toy_models.py:decay_point", DATA)
    model = as_model(func, {"k": 2.0, "y0": 1.0})
    assert isinstance(model, FunctionModel)
    assert model.outputs == ("y", "dy")
    assert as_model(func, {"k": 2.0, "y0": 1.0}, outputs=["y"]).outputs == ("y",)
    batch = as_model(load_entry("toy_models.py:decay_batch", DATA), {"k": 2.0, "y0": 1.0})
    assert isinstance(batch, BatchFunctionModel) and batch.outputs == ("y", "dy")


def test_as_model_builds_a_factory_and_checks_outputs_of_classes():
    factory = PythonModelFactory("toy_models.py:Decay", DATA, {"k": 3.0})
    model = as_model(factory, {})
    assert model.parameters == {"k": 3.0, "y0": 1.0}
    with pytest.raises(ConfigError) as exc:
        as_model(factory, {"k": 1.0})
    assert only_problem(exc)[0] == "model.params"
    with pytest.raises(ConfigError) as exc:
        as_model(load_entry("toy_models.py:Decay", DATA), {}, outputs=["y", "zz"])
    message = "'zz' is not an output of Decay (outputs: y, dy)"
    assert only_problem(exc) == ("model.outputs[1]", message)


@pytest.mark.parametrize(
    ("name", "params", "path", "fragment"),
    [
        ("Decay", {"k": -1.0}, "model.params", "ValueError: k must be > 0, got -1.0"),
        ("Decay", {"q": 1.0}, "model.params", "unexpected keyword argument 'q'"),
        ("NotAModel", {}, "model.entry", "NotAModel is not a model"),
        ("NUMBER", {}, "model.entry", "found int"),
        ("undeclared_point", {}, "model.outputs", "does not declare its outputs"),
        ("plain_point", {}, "model.entry", "@pcmb.pointwise(outputs="),
        ("decay_point", {}, "model.outputs[0]", "'zz' is not an output of decay_point"),
    ],
)
def test_as_model_errors_are_located(name, params, path, fragment):
    outputs = ["zz"] if name == "decay_point" else None
    with pytest.raises(ConfigError) as exc:
        as_model(load_entry(f"toy_models.py:{name}", DATA), params, outputs)
    found_path, message = only_problem(exc)
    assert found_path == path
    assert fragment in message


# --------------------------------------------------------------------------- markers


def test_markers_set_a_documented_attribute_and_return_the_function():
    def f(params, times):
        return {}

    assert pointwise(f, outputs=("y",)) is f
    assert f.pcmb_model == "pointwise" and f.outputs == ("y",)
    g = batched(outputs=["a", "b"])(lambda params, times: {})
    assert g.pcmb_model == "batched" and g.outputs == ("a", "b")
    assert is_function_model(f) and is_function_model(g)
    assert not is_function_model(load_entry("toy_models.py:plain_point", DATA))
    assert not is_function_model(load_entry("toy_models.py:Decay", DATA))
    marked = load_entry("toy_models.py:decay_point", DATA)
    assert pickle.loads(pickle.dumps(marked)) is marked  # still pickled by reference


@pytest.mark.parametrize(
    ("call", "fragment"),
    [
        (lambda: pointwise(outputs="y"), "outputs: expected a sequence of names"),
        (lambda: pointwise(int), "expected a function"),
        (lambda: batched(len, outputs=("y",)), "wrap it in a def"),
    ],
)
def test_markers_refuse_what_they_cannot_mark(call, fragment):
    with pytest.raises(UsageError, match=fragment):
        call()


def test_batch_function_gets_every_parameter_as_a_batch():
    model = as_model(load_entry("toy_models.py:decay_batch", DATA), {"k": 2.0, "y0": 1.5})
    k = np.array([1.0, 2.0, 3.0])
    out = model.simulate({"k": k}, TIMES)
    for name in ("y", "dy"):
        np.testing.assert_allclose(out[name], decay(k, 1.5)[name], rtol=EXP_RTOL, atol=0)
    nominal = model.simulate({}, TIMES)
    np.testing.assert_allclose(nominal["y"], decay(np.array([2.0]), 1.5)["y"], rtol=EXP_RTOL)
    with pytest.raises(ValueError, match="unknown parameter"):
        model.simulate({"zz": np.ones(2)}, TIMES)


@pytest.mark.parametrize(
    ("result", "error", "fragment"),
    [
        ({"y": np.zeros(5)}, ModelDefinitionError, "returned shape (5,) for output 'y' for 2"),
        ({}, ModelDefinitionError, "returned no output(s) 'y'"),
        (RuntimeError("boom"), ModelError, "raised RuntimeError: boom"),
    ],
)
def test_batch_function_results_are_checked(result, error, fragment):
    def f(params, times):
        if isinstance(result, Exception):
            raise result
        return result

    model = BatchFunctionModel(batched(f), {"k": 1.0}, ["y"])
    with pytest.raises(error) as exc:
        model.simulate({"k": np.ones(2)}, TIMES)
    assert fragment in str(exc.value)


# --------------------------------------------------------------------------- model_factory


def test_model_factory_takes_what_the_api_accepts():
    factory = PythonModelFactory("toy_models.py:Decay", DATA, {"k": 2.0})
    assert model_factory(factory, {"ignored": 1.0}) is factory
    assert isinstance(factory, ModelFactory)
    decay_class = load_entry("toy_models.py:Decay", DATA)
    built = model_factory(decay_class, {"k": 3.0}, ["y"])
    assert isinstance(built, ModelFactory) and built().parameters["k"] == 3.0
    instance = load_entry("toy_models.py:DECAY", DATA)
    assert model_factory(instance)() is instance
    marked = load_entry("toy_models.py:decay_point", DATA)
    assert isinstance(model_factory(marked, {"k": 1.0, "y0": 1.0})(), FunctionModel)


@pytest.mark.parametrize(
    ("name", "params", "key", "fragment"),
    [
        ("plain_point", {}, "model", '@pcmb.pointwise(outputs=("y", ...))'),
        ("NUMBER", {}, "model", "found int"),
        ("DECAY", {"k": 1.0}, "params", "already built model and takes no params"),
    ],
)
def test_model_factory_refuses_ambiguous_objects_at_once(name, params, key, fragment):
    with pytest.raises(UsageError) as exc:
        model_factory(load_entry(f"toy_models.py:{name}", DATA), params)
    (problem,) = exc.value.problems
    assert problem.path == key and fragment in problem.message
    assert str(exc.value).startswith(f"Study: {key}: ")


def test_a_callable_object_is_told_to_subclass_model_factory():
    class Builder:
        def __call__(self):
            return load_entry("toy_models.py:DECAY", DATA)

    with pytest.raises(UsageError, match=r"the Builder object is callable .* subclass pcmb\.Model"):
        model_factory(Builder())


def test_api_factory_names_the_arguments_of_the_call():
    decay_class = load_entry("toy_models.py:Decay", DATA)
    with pytest.raises(UsageError) as exc:
        model_factory(decay_class, {"k": -1.0})()
    assert only_problem(exc)[0] == "params"
    with pytest.raises(UsageError) as exc:
        model_factory(decay_class, {}, ["y", "zz"])()
    assert only_problem(exc)[0] == "outputs[1]"


# --------------------------------------------------------------------------- FunctionModel


def point_model(**kwargs) -> FunctionModel:
    func = load_entry("toy_models.py:decay_point", DATA)
    return FunctionModel(func, {"k": 2.0, "y0": 1.5, "fail": 0.0}, **kwargs)


def test_function_model_loops_and_keeps_nominal_values():
    k = np.array([1.0, 2.0, 3.0])
    out = point_model().simulate({"k": k}, TIMES)
    expected = decay(k, 1.5)
    for name in ("y", "dy"):
        assert out[name].shape == (3, TIMES.size)
        np.testing.assert_allclose(out[name], expected[name], rtol=EXP_RTOL, atol=0)


def test_function_model_field_input_gets_its_row():
    @pointwise
    def total(params, times):
        return {"s": np.full_like(times, np.sum(params["field"]) + params["c"])}

    model = FunctionModel(total, {"field": 0.0, "c": 1.0}, ["s"])
    field = np.arange(6.0).reshape(3, 2)
    out = model.simulate({"field": field}, TIMES)
    np.testing.assert_array_equal(out["s"][:, 0], [2.0, 6.0, 10.0])


def test_function_model_failed_node_is_nan_in_batch_and_raises_alone():
    model = point_model()
    out = model.simulate({"k": np.array([1.0, 2.0, 3.0]), "fail": np.array([0.0, 1.0, 0.0])}, TIMES)
    assert np.isnan(out["y"][1]).all()
    np.testing.assert_allclose(
        out["y"][[0, 2]], decay(np.array([1.0, 3.0]), 1.5)["y"], rtol=EXP_RTOL
    )
    with pytest.raises(ModelError, match="decay_point raised RuntimeError: asked to fail"):
        model.simulate({"fail": np.array([1.0])}, TIMES)


@pytest.mark.parametrize(
    ("result", "error", "fragment"),
    [
        ([1.0], ModelDefinitionError, "returned a list; it must return a dict {name: (T,) array}"),
        ({"y": np.zeros(5)}, ModelDefinitionError, "returned no output(s) 'dy' (it returned: y)"),
        ({"y": np.zeros(4), "dy": np.zeros(5)}, ModelError, "has shape (4,), expected (5,)"),
        ({"y": "abc", "dy": np.zeros(5)}, ModelError, "output 'y' of the per-point function"),
        (
            {"y": 1.5, "dy": np.zeros(5)},
            ModelDefinitionError,
            "returned a float for output 'y'; it must return a (T,) array, one value per time",
        ),
        ({"y": np.zeros((5, 1)), "dy": np.zeros(5)}, ModelDefinitionError, "shape (5, 1)"),
    ],
)
def test_function_model_checks_results(result, error, fragment):
    model = FunctionModel(pointwise(lambda params, times: result), {}, ["y", "dy"])
    with pytest.raises(error) as exc:
        model.simulate({}, TIMES)
    assert fragment in str(exc.value)
    assert exc.type is error


def test_a_result_no_node_can_get_right_stops_the_whole_batch():
    model = as_model(load_entry("toy_models.py:scalar_point", DATA), {"k": 1.0})
    with pytest.raises(ModelDefinitionError) as exc:
        model.simulate({"k": np.array([1.0, 2.0, 3.0])}, TIMES)  # not three NaN rows
    assert str(exc.value) == (
        "the per-point function scalar_point returned a float for output 'y'; it must return "
        "a (T,) array, one value per time"
    )
    assert exc.value.exit_code == 3


def test_function_model_rejects_unknown_names_and_ragged_batches():
    model = point_model()
    with pytest.raises(ValueError, match="unknown parameter"):
        model.simulate({"zz": np.ones(2)}, TIMES)
    with pytest.raises(ValueError, match="one B"):
        model.simulate({"k": np.ones(2), "y0": np.ones(3)}, TIMES)


# --------------------------------------------------------------------------- factories


def test_python_factory_pickles_and_builds_same_model():
    factory = PythonModelFactory("toy_models.py:Decay", DATA, {"k": 2.0, "y0": 1.0})
    clone = pickle.loads(pickle.dumps(factory))
    assert clone == factory
    k = np.array([1.5, 2.5])
    out = clone().simulate({"k": k}, TIMES)
    np.testing.assert_allclose(out["y"], decay(k)["y"], rtol=EXP_RTOL)


def test_object_factory_in_process_and_in_loky_workers():
    @pointwise(outputs=("y",))
    def ramp(params, times):
        return {"y": params["a"] * times + params["b"]}

    factory = model_factory(ramp, {"a": 1.0, "b": 0.5})
    assert isinstance(factory, ObjectModelFactory)
    # joblib ships callables to loky workers with cloudpickle: a local function survives.
    clone = cloudpickle.loads(cloudpickle.dumps(factory))
    a = np.array([1.0, 2.0, 3.0, 4.0])

    def run(f, index):
        return f().simulate({"a": a[index : index + 1]}, TIMES)["y"][0]

    local = np.array([run(clone, i) for i in range(4)])
    with joblib.Parallel(n_jobs=2, backend="loky") as parallel:
        remote = np.array(parallel(joblib.delayed(run)(factory, i) for i in range(4)))
    expected = a[:, None] * TIMES + 0.5  # exact: one multiply-add of exactly representable values
    np.testing.assert_array_equal(local, expected)
    np.testing.assert_array_equal(remote, expected)


# --------------------------------------------------------------------------- CommandModel


def command(tmp_path: Path, output: str = "out.csv", deck: bool = False, **kwargs) -> CommandModel:
    args = [sys.executable, "sim_decay.py", output, *(["--deck", "deck.txt"] if deck else [])]
    options = {
        "params": {"k": 2.0, "y0": 1.0, "mode": 0.0},
        "outputs": ["y", "dy"],
        "output_file": output,
        "files": ["sim_decay.py"],
        "templates": ["deck.txt"] if deck else [],
        "base_dir": DATA,
        "timeout": 30.0,
        "run_dir": tmp_path / "runs",
    }
    options.update(kwargs)
    return CommandModel(args, **options)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("output", "fmt"),
    [
        ("out.csv", None),
        ("out.txt", "table"),
        ("out.json", None),
        ("out.npy", None),
        ("out.npz", None),
    ],
)
def test_command_reads_every_output_format_exactly(tmp_path, output, fmt):
    k = np.array([1.5, 0.1 + 0.2])
    out = command(tmp_path, output, output_format=fmt).simulate({"k": k}, TIMES)
    expected = decay(k)  # same formula, same inputs in the simulator: bit-identical
    for name in ("y", "dy"):
        np.testing.assert_array_equal(out[name], expected[name])


def test_command_templates_render_exact_floats(tmp_path):
    k = 0.1 + 0.2  # 0.30000000000000004: any rounding in the text would change the result
    model = command(tmp_path, deck=True, keep="all")
    out = model.simulate({"k": np.array([k])}, TIMES)
    np.testing.assert_array_equal(out["y"], decay(np.array([k]))["y"])
    (workdir,) = (tmp_path / "runs").iterdir()
    deck = (workdir / "deck.txt").read_text()
    assert "k = 0.30000000000000004\n" in deck
    assert "times.points = 5\n" in deck
    assert (workdir / "sim_decay.py").is_symlink()


@pytest.mark.slow
def test_command_work_directories_kept_only_for_failures(tmp_path):
    model = command(tmp_path)
    out = model.simulate({"mode": np.array([0.0, 1.0, 0.0])}, TIMES)
    assert np.isnan(out["y"][1]).all() and np.isfinite(out["y"][[0, 2]]).all()
    np.testing.assert_array_equal(out["y"][0], decay(np.array([2.0]))["y"][0])
    (kept,) = (tmp_path / "runs").iterdir()
    assert "something went wrong" in (kept / "stderr.txt").read_text()
    with pytest.raises(ModelError, match=f"work directory kept: {kept.parent}"):
        model.simulate({"mode": np.array([1.0])}, TIMES)
    command(tmp_path, keep="none", run_dir=tmp_path / "none").simulate(
        {"mode": np.array([0.0, 1.0])}, TIMES
    )
    assert list((tmp_path / "none").iterdir()) == []


@pytest.mark.parametrize(
    ("mode", "output", "pattern"),
    [
        (1, "out.csv", r"exited with code 3; last lines of stderr.txt: 'something went wrong"),
        (3, "out.csv", r"cannot parse out.csv as csv: .*line 2: 'not-a-number' is not a number"),
        (4, "out.csv", r"the command succeeded but wrote no output file out.csv"),
        (5, "out.npy", r"output 'y' in out.npy has shape \(4,\), expected \(5,\)"),
        (5, "out.csv", r"'time' column of out.csv does not match the requested grid"),
        (6, "out.csv", r"killed by signal 11 \(SIGSEGV\)"),
        (7, "out.json", r"output 'y' in out.json is not finite at 1 time\(s\), first at t=1"),
        (8, "out.npz", r"'time' column of out.npz does not match the requested grid"),
    ],
)
def test_command_failures_are_classified(tmp_path, mode, output, pattern):
    with pytest.raises(ModelError, match=pattern):
        command(tmp_path, output).simulate({"mode": np.array([float(mode)])}, TIMES)


@pytest.mark.slow
def test_command_timeout_kills_the_whole_process_group(tmp_path):
    model = command(tmp_path, timeout=1.5)
    start = time.monotonic()
    with pytest.raises(ModelError, match=r"timed out after 1.5 s \(process group killed\)"):
        model.simulate({"mode": np.array([2.0])}, TIMES)
    assert time.monotonic() - start < 10.0  # the 60 s sleep was cut short
    (workdir,) = (tmp_path / "runs").iterdir()
    grandchild = int((workdir / "grandchild.pid").read_text())
    # The grandchild was SIGKILLed with its group; its new parent reaps it shortly after.
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and Path(f"/proc/{grandchild}").exists():
        state = Path(f"/proc/{grandchild}/stat").read_text().split()[2]
        if state == "Z":
            break
        time.sleep(0.05)
    else:
        assert not Path(f"/proc/{grandchild}").exists()


@pytest.mark.parametrize(
    ("change", "path", "fragment"),
    [
        ({"templates": ["no_such.tmpl"]}, "model.templates[0]", "no_such.tmpl does not exist"),
        ({"files": ["sim_decay.py", "nope.py"]}, "model.files[1]", "nope.py does not exist"),
        ({"params": {"k": 2.0}}, "model.templates[0]", "deck.txt line 2: placeholder '{{y0}}'"),
        ({"output_file": "out.txt"}, "model.output.format", "its extension 'txt' is none of"),
        ({"output_format": "xml"}, "model.output.format", "found 'xml'"),
        ({"output_file": "sub/out.csv"}, "model.output.file", "plain file name"),
        (
            {"output_file": "deck.txt", "output_format": "csv"},
            "model.templates[0]",
            "deck.txt is already used by model.output.file",
        ),
        ({"files": ["sim_decay.py", "sim_decay.py"]}, "model.files[1]", "already used by"),
        ({"output_file": "params.json"}, "model.output.file", "reserved work-directory name"),
        ({"outputs": []}, "model.outputs", "must list the outputs"),
        ({"outputs": ["time"]}, "model.outputs", "time column"),
        ({"timeout": 0.0}, "model.timeout", "positive"),
        ({"params": {"k": "x", "y0": 1.0, "mode": 0.0}}, "model.params", "takes numbers"),
    ],
)
def test_command_construction_errors_are_located(tmp_path, change, path, fragment):
    with pytest.raises(ConfigError) as exc:
        command(tmp_path, deck=True, **change)
    found_path, message = only_problem(exc)
    assert found_path == path
    assert fragment in message


def test_command_program_lookup():
    def build(argv):
        return CommandModel(argv, params={}, outputs=["y"], output_file="o.csv", base_dir=DATA)

    with pytest.raises(ConfigError) as exc:
        build(["pcmb-no-such-program"])
    assert only_problem(exc) == (
        "model.command[0]",
        "program 'pcmb-no-such-program' not found on PATH",
    )
    with pytest.raises(ConfigError) as exc:
        build("./toy_models.py")
    assert only_problem(exc)[0] == "model.command[0]"
    assert "is not executable" in only_problem(exc)[1]
    with pytest.raises(ConfigError) as exc:
        build("true x {{ nope }}")
    assert only_problem(exc)[0] == "model.command[2]"
    assert "'{{nope}}' names no parameter" in only_problem(exc)[1]
    with pytest.raises(ConfigError) as exc:
        build("true 'unbalanced")
    assert only_problem(exc)[0] == "model.command"


def test_split_command_keeps_placeholders_whole():
    expected = ["sim", "--k", "{{k}}", "a b", "{{y0}}"]
    assert split_command("sim --k {{ k }} 'a b' {{y0}}") == expected


def test_command_factory_pickles_and_builds(tmp_path):
    factory = CommandModelFactory(
        command=(sys.executable, "sim_decay.py", "out.csv"),
        params={"k": 2.0, "y0": 1.0},
        outputs=("y",),
        output_file="out.csv",
        files=("sim_decay.py",),
        base_dir=DATA,
        run_dir=tmp_path,
    )
    model = pickle.loads(pickle.dumps(factory))()
    out = model.simulate({"k": np.array([1.0])}, TIMES)
    np.testing.assert_array_equal(out["y"], decay(np.array([1.0]))["y"])
    assert model.parameters == {"k": 2.0, "y0": 1.0}
    assert pickle.loads(pickle.dumps(model)).argv == model.argv  # the model itself ships too


def test_the_python_and_command_adapters_load_no_pydantic_yaml_or_mujoco():
    code = (
        "import sys\n"
        "import pcmb.adapters.command\n"
        "from pcmb.adapters.python import model_factory, pointwise\n"
        "f = pointwise(lambda params, times: {'y': times}, outputs=('y',))\n"
        "model_factory(f, {'a': 1.0})()\n"
        "print(sorted(m for m in ('pydantic', 'yaml', 'mujoco') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_a_missing_output_column_lists_the_columns_found(tmp_path):
    model = command(tmp_path, outputs=["y", "dy", "z"])
    with pytest.raises(ModelError, match=r"output\(s\) 'z' missing from out.csv \(found: [^)]*y"):
        model.simulate({"k": np.array([1.5])}, TIMES)
