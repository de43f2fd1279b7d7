"""The MuJoCo adapter: bindings, outputs, grid, divergence, errors (pcmb.adapters.mujoco.model).

References are independent of the adapter: a plain ``mj_step`` loop on a scene compiled
fresh from XML that spells the node's values out (as mujoco's own rollout tests do), and,
for divergence, the semi-implicit Euler recurrence written out in numpy. Where the adapter
and the reference run the same arithmetic the comparison is exact: MuJoCo's batch steps
bit-identically to a loop of mj_step, and a field edit is the value the compiler would
write. Where the adapter takes another route to the same model (scaling an inertia instead
of computing it from a geom), round-off differs by an ulp and the tolerance says so.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import mujoco
import numpy as np
import pytest

import pcmb.adapters.mujoco.model
from pcmb.adapters.mujoco.binding import parse_scene_io
from pcmb.adapters.mujoco.model import MujocoModel, MujocoModelFactory
from pcmb.cli import main
from pcmb.errors import ConfigError, ModelError

# A damped compound pendulum: a hub on the hinge and a ball at distance L below it. L is a
# template input; everything else may be bound. Contacts off: nothing here touches.
SCENE = """\
<mujoco model="test_pendulum">
  <option timestep="0.002" gravity="0 0 -9.81">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="arm">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="hub" type="sphere" size="0.03" mass="0.2"/>
      <body name="bob" pos="0 0 -{{ L }}">
        <geom name="ball" type="sphere" size="0.05" mass="1"/>
        <site name="tip" pos="0 0 -0.05"/>
      </body>
    </body>
  </worldbody>
  <sensor>
    <framepos name="tip_pos" objtype="site" objname="tip"/>
    <accelerometer name="tip_acc" site="tip"/>
  </sensor>
</mujoco>
"""
OUTPUTS = {
    "theta": {"qpos": "hinge"},
    "omega": {"qvel": "hinge"},
    "bob_x": {"xpos": "bob", "axis": 0},
    "tip_z": {"site_xpos": "tip", "axis": 2},
    "tip_x": {"sensor": "tip_pos", "index": 0},
    "acc_z": {"sensor": "tip_acc", "index": 2},
}
TIMES = np.linspace(0.0, 1.0, 11)  # multiples of the 2 ms timestep
INIT = {"qpos": {"hinge": 0.6}}
REPO = Path(__file__).resolve().parents[1]


def write(folder: Path, text: str, name: str = "scene.xml") -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def reference(xml: str, times: np.ndarray, qpos: float = 0.6, qvel: float = 0.0) -> dict:
    """Outputs of SCENE by a plain mj_step loop on a freshly compiled XML (values spelled out)."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[0], data.qvel[0] = qpos, qvel
    bob = model.body("bob").id
    tip = model.site("tip").id
    pos, acc = model.sensor("tip_pos").adr[0], model.sensor("tip_acc").adr[0]
    rows = []
    done = 0
    for target in np.rint(times / model.opt.timestep).astype(int):
        if target > done:
            mujoco.mj_step(model, data, nstep=int(target - done))
            done = target
        mujoco.mj_forward(model, data)  # derived quantities at the new state
        rows.append(
            [
                data.qpos[0],
                data.qvel[0],
                data.xpos[bob, 0],
                data.site_xpos[tip, 2],
                data.sensordata[pos],
                data.sensordata[acc + 2],
            ]
        )
    return dict(zip(OUTPUTS, np.array(rows).T, strict=True))


def spelled(length: float, old: str = "", new: str = "") -> str:
    """SCENE with L written in and one attribute replaced."""
    text = SCENE.replace("{{ L }}", repr(float(length)))
    assert old in text  # the test's own consistency, not validation
    return text.replace(old, new)


def pendulum(folder: Path, **kwargs) -> MujocoModel:
    kwargs.setdefault("params", {"L": 0.5})
    kwargs.setdefault("init", INIT)
    kwargs.setdefault("outputs", OUTPUTS)
    return MujocoModel(xml=write(folder, SCENE), **kwargs)


# --------------------------------------------------------------------------- oracle


# Bytes of recorded states per rollout call: 1 B steps unrecorded to each output time and
# records one step; 69 kB records 125 steps (2.5 output intervals of 50 steps) per call;
# default: all at once.
@pytest.mark.parametrize("record_bytes", [1, 69_000, None])
def test_each_node_equals_a_plain_mj_step_loop_on_a_fresh_scene(
    tmp_path, monkeypatch, record_bytes
):
    if record_bytes is not None:
        monkeypatch.setattr(pcmb.adapters.mujoco.model, "_RECORD_BYTES", record_bytes)
    model = pendulum(
        tmp_path,
        bind={
            "damping": [{"field": "dof_damping", "name": "hinge"}],
            "th0": [{"qpos0": "hinge"}],
            "w0": [{"qvel0": "hinge"}],
        },
    )
    params = {
        "L": np.array([0.4, 0.5, 0.7]),
        "damping": np.array([0.0, 0.1, 0.3]),
        "th0": np.array([0.2, 0.6, 1.5]),
        "w0": np.array([0.0, -1.0, 2.0]),
    }
    out = model.simulate(params, TIMES)
    for i in range(3):
        xml = spelled(params["L"][i], 'damping="0.1"', f'damping="{float(params["damping"][i])!r}"')
        expected = reference(xml, TIMES, qpos=params["th0"][i], qvel=params["w0"][i])
        for name in OUTPUTS:
            # same arithmetic in the same order: bit for bit
            np.testing.assert_array_equal(out[name][i], expected[name], err_msg=name)


def test_uncertain_inputs_override_and_the_others_keep_nominal_values(tmp_path):
    model = pendulum(
        tmp_path,
        params={"L": 0.7, "damping": 0.3},
        bind={"damping": [{"field": "dof_damping", "name": "hinge"}]},
    )
    assert dict(model.parameters) == {"L": 0.7, "damping": 0.3}
    out = model.simulate({"L": np.array([0.4])}, TIMES)
    expected = reference(spelled(0.4, 'damping="0.1"', 'damping="0.3"'), TIMES)
    np.testing.assert_array_equal(out["theta"][0], expected["theta"])
    nominal = model.simulate({}, TIMES)
    expected = reference(spelled(0.7, 'damping="0.1"', 'damping="0.3"'), TIMES)
    np.testing.assert_array_equal(nominal["tip_z"][0], expected["tip_z"])


def test_parameters_report_nominal_values_read_from_the_scene(tmp_path):
    model = pendulum(
        tmp_path,
        bind={
            "m": [{"field": "body_mass", "name": "bob"}],
            "gz": [{"field": "opt.gravity", "index": 2}],
            "r": [{"field": "geom_size", "name": "ball", "index": 0}],
            "th0": [{"qpos0": "hinge"}],
            "w0": [{"qvel0": "hinge"}],
        },
    )
    assert dict(model.parameters) == {
        "L": 0.5,
        "m": 1.0,
        "gz": -9.81,
        "r": 0.05,
        "th0": 0.6,  # from init
        "w0": 0.0,
    }
    assert model.outputs == tuple(OUTPUTS)


# --------------------------------------------------------------------------- bindings


# (binding, attribute in SCENE, how the value is written there, node values)
BINDINGS = [
    pytest.param(
        {"field": "body_mass", "name": "bob"},
        'size="0.05" mass="1"',
        'size="0.05" mass="{}"',
        [0.5, 3.0],
        id="body_mass",
    ),
    pytest.param(
        {"field": "geom_size", "name": "ball", "index": 0},
        'size="0.05" mass="1"',
        'size="{}" mass="1"',
        [0.01, 0.2],
        id="geom_size",
    ),
    pytest.param(
        {"field": "opt.gravity", "index": 2},
        'gravity="0 0 -9.81"',
        'gravity="0 0 {}"',
        [-1.62, -24.79],
        id="opt.gravity",
    ),
    pytest.param(
        {"field": "opt.timestep"},
        'timestep="0.002"',
        'timestep="{}"',
        [0.001, 0.0005],
        id="opt.timestep",
    ),
]


@pytest.mark.parametrize(("binding", "old", "new", "values"), BINDINGS)
def test_a_binding_gives_the_trajectory_of_an_xml_with_that_value(
    tmp_path, binding, old, new, values
):
    model = pendulum(tmp_path, bind={"v": [binding]})
    out = model.simulate({"v": np.array(values)}, TIMES)
    for i, value in enumerate(values):
        expected = reference(spelled(0.5, old, new.format(repr(value))), TIMES)
        for name in OUTPUTS:
            # body_mass scales the compiled inertia (m'/m) I instead of computing it from m':
            # one rounding apart, which a 1 s damped swing keeps near 1e-15 relative.
            np.testing.assert_allclose(out[name][i], expected[name], rtol=1e-12, atol=1e-13)
    assert not np.allclose(out["theta"][0], out["theta"][1])  # the binding did something


def test_body_mass_keeps_contact_constants_consistent(tmp_path):
    # Contact softness scales with the inverse weights mj_setConst derives from the masses:
    # a stale value would change the slide. The box on the incline, mass bound vs in the XML.
    scene = (REPO / "models" / "mujoco" / "contact_incline.xml").read_text(encoding="utf-8")
    model = MujocoModel(
        xml=write(tmp_path, scene),
        bind={
            "m": [{"field": "body_mass", "name": "box"}],
            "mu": [{"field": "geom_friction", "name": "box", "index": 0}],
        },
        outputs={"x": {"qpos": "x"}, "z": {"qpos": "z"}},
    )
    times = np.linspace(0.0, 0.5, 6)
    masses = np.array([0.2, 5.0])
    out = model.simulate({"m": masses, "mu": np.full(2, 0.4)}, times)
    for i, mass in enumerate(masses):
        fresh = mujoco.MjModel.from_xml_string(
            scene.replace(
                'mass="1" friction="0.5 0 0"', f'mass="{float(mass)!r}" friction="0.4 0 0"'
            )
        )
        data = mujoco.MjData(fresh)
        x = []
        for _ in range(times.size):
            x.append(data.qpos.copy())
            mujoco.mj_step(fresh, data, nstep=100)
        x = np.array(x)
        # an iterative contact solve from the same constants: round-off level only
        np.testing.assert_allclose(out["x"][i], x[:, 0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(out["z"][i], x[:, 1], rtol=1e-9, atol=1e-12)


def test_sizes_of_a_geom_given_by_fromto_cannot_be_bound(tmp_path):
    scene = SCENE.replace(
        '<geom name="hub" type="sphere" size="0.03" mass="0.2"/>',
        '<geom name="rod" type="capsule" fromto="0 0 0 0 0 -0.2" size="0.01" mass="0.2"/>',
    )
    with pytest.raises(ConfigError) as exc:
        MujocoModel(
            xml=write(tmp_path, scene),
            params={"L": 0.5},
            bind={"r": [{"field": "geom_size", "name": "rod", "index": 1}]},
            outputs=OUTPUTS,
        )
    assert [p.path for p in exc.value.problems] == ["model.bind.r[0].field"]
    assert "fromto" in exc.value.problems[0].message


# --------------------------------------------------------------------------- config errors


def bad(**changes):
    return changes


CONFIG_ERRORS = [
    (bad(bind={"m": [{"field": "body_mass", "name": "nope"}]}), "model.bind.m[0].name", "nope"),
    (bad(bind={"m": [{"field": "body_mas", "name": "bob"}]}), "model.bind.m[0].field", "mass"),
    (
        bad(bind={"m": [{"field": "body_subtreemass", "name": "bob"}]}),
        "model.bind.m[0].field",
        "computes",
    ),
    (bad(bind={"m": [{"field": "body_pos", "name": "bob"}]}), "model.bind.m[0].index", "3 values"),
    (
        bad(bind={"m": [{"field": "body_pos", "name": "bob", "index": 3}]}),
        "model.bind.m[0].index",
        "0-2",
    ),
    (
        bad(bind={"g": [{"field": "opt.gravity", "name": "bob", "index": 2}]}),
        "model.bind.g[0].name",
        "no element",
    ),
    (bad(bind={"g": [{"field": "opt.integrator"}]}), "model.bind.g[0].field", "real-valued"),
    (
        bad(bind={"m": [{"field": "body_mass", "name": "bob", "scale": 2}]}),
        "model.bind.m[0].scale",
        "unknown key",
    ),
    (bad(bind={"th": [{"qpos0": "elbow"}]}), "model.bind.th[0].qpos0", "no joint named 'elbow'"),
    (bad(bind={"th": [{"joint": "hinge"}]}), "model.bind.th[0]", "expected"),
    (bad(bind={"L": [{"qpos0": "hinge"}]}), "model.bind.L", "placeholder"),
    (bad(params={"L": 0.5, "zz": 1.0}), "model.params.zz", "neither"),
    (bad(params={}), "model.params", "{{ L }}"),
    (bad(init={"qpos": {"elbow": 0.1}}), "model.init.qpos.elbow", "no joint"),
    (bad(init={"qacc": {"hinge": 0.1}}), "model.init.qacc", "unknown key"),
    (bad(outputs={"x": {"xpos": "bob", "axis": 3}}), "model.outputs.x.axis", "0, 1 or 2"),
    (bad(outputs={"x": {"site_xpos": "toe", "axis": 0}}), "model.outputs.x.site_xpos", "toe"),
    (bad(outputs={"s": {"sensor": "tip_pos"}}), "model.outputs.s.index", "3 values"),
    (bad(outputs={"s": {"sensor": "gyro"}}), "model.outputs.s.sensor", "tip_pos, tip_acc"),
    (bad(outputs={"s": {"qpos": "hinge", "qvel": "hinge"}}), "model.outputs.s", "one of"),
    (bad(outputs={}), "model.outputs", "at least 1 entry"),
    # the binding language's own checks (pcmb.adapters.mujoco.binding), as in a config
    (bad(bind={"m": {"field": "body_mass"}}), "model.bind.m", "expected a list"),
    (bad(bind={"m": []}), "model.bind.m", "at least 1 entry"),
    (
        bad(bind={"m": [{"field": "body_mass", "name": "bob", "index": -1}]}),
        "model.bind.m[0].index",
        ">= 0",
    ),
    (bad(bind={"m": [{"qpos0": "hinge", "field": "body_mass"}]}), "model.bind.m[0]", "expected"),
    (bad(bind={"1m": [{"qpos0": "hinge"}]}), "model.bind.1m", "letters, digits"),
    (bad(init={"qpos": {"hinge": "a lot"}}), "model.init.qpos.hinge", "expected a number"),
    (bad(init={"qpos": {"hinge": float("nan")}}), "model.init.qpos.hinge", "finite"),
    (bad(outputs={"x": {"xpos": "bob", "axis": True}}), "model.outputs.x.axis", "0, 1 or 2"),
    (bad(outputs={"x": {"xpos": "bob"}}), "model.outputs.x.axis", "required key is missing"),
]


@pytest.mark.parametrize(("changes", "path", "fragment"), CONFIG_ERRORS)
def test_semantic_errors_name_the_key_path(tmp_path, changes, path, fragment):
    with pytest.raises(ConfigError) as exc:
        pendulum(tmp_path, **changes)
    assert [p.path for p in exc.value.problems] == [path]
    assert fragment in exc.value.problems[0].message


def test_parsed_entries_of_the_binding_language_are_taken_as_they_are(tmp_path):
    scene_io = parse_scene_io(
        {"m": [{"field": "body_mass", "name": "bob"}]}, INIT, {"theta": {"qpos": "hinge"}}
    )
    model = pendulum(tmp_path, bind=scene_io.bind, init=scene_io.init, outputs=scene_io.outputs)
    assert dict(model.parameters) == {"L": 0.5, "m": 1.0} and model.outputs == ("theta",)


def test_every_problem_is_reported_at_once(tmp_path):
    with pytest.raises(ConfigError) as exc:
        pendulum(
            tmp_path,
            bind={"m": [{"field": "body_mass", "name": "nope"}]},
            outputs={"x": {"xpos": "nope", "axis": 0}, "y": {"qpos": "elbow"}},
        )
    paths = [p.path for p in exc.value.problems]
    assert paths == ["model.bind.m[0].name", "model.outputs.x.xpos", "model.outputs.y.qpos"]


def test_only_hinge_and_slide_joints_have_one_coordinate(tmp_path):
    scene = SCENE.replace('type="hinge" axis="0 1 0"', 'type="ball"')
    with pytest.raises(ConfigError) as exc:
        MujocoModel(xml=write(tmp_path, scene), params={"L": 0.5}, outputs={"q": {"qpos": "hinge"}})
    assert "ball joint" in exc.value.problems[0].message


def test_xml_errors_carry_mujocos_message_and_line(tmp_path):
    broken = SCENE.replace('type="sphere" size="0.05"', 'type="spere" size="0.05"')
    with pytest.raises(ConfigError) as exc:
        MujocoModel(xml=write(tmp_path, broken), params={"L": 0.5}, outputs=OUTPUTS)
    (problem,) = exc.value.problems
    line = broken.splitlines().index(next(s for s in broken.splitlines() if "spere" in s)) + 1
    assert problem.path == "model.xml"
    assert "spere" in problem.message and f"line {line}" in problem.message


def test_a_scene_that_does_not_compile_is_a_config_error(tmp_path):
    massless = SCENE.replace('mass="1"', 'mass="0"').replace('mass="0.2"', 'mass="0"')
    with pytest.raises(ConfigError) as exc:
        MujocoModel(xml=write(tmp_path, massless), params={"L": 0.5}, outputs=OUTPUTS)
    assert "mass and inertia" in exc.value.problems[0].message


def test_a_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError) as exc:
        MujocoModel(xml=tmp_path / "nope.xml", outputs=OUTPUTS)
    assert exc.value.problems[0].path == "model.xml"


# --------------------------------------------------------------------------- the grid


@pytest.mark.parametrize(
    ("times", "fragment"),
    [
        (np.linspace(0.0, 1.0, 7), "whole number"),  # 1/6 s is 83.33 steps of 2 ms
        (np.array([0.0, 0.5, 0.4]), "increase"),
        (np.array([-0.002, 0.0]), "start"),
        (np.zeros((2, 2)), "1-D"),
    ],
)
def test_a_grid_the_timestep_cannot_reach_is_a_config_error(tmp_path, times, fragment):
    model = pendulum(tmp_path)
    for call in (lambda: model.check_times(times), lambda: model.simulate({}, times)):
        with pytest.raises(ConfigError) as exc:
            call()
        assert exc.value.problems[0].path == "time"
        assert fragment in exc.value.problems[0].message


def test_a_grid_may_start_after_zero_and_records_only_its_times(tmp_path):
    model = pendulum(tmp_path)
    late = np.array([0.3, 0.302, 0.9])
    out = model.simulate({}, late)
    expected = reference(spelled(0.5), late)
    for name in OUTPUTS:
        assert out[name].shape == (1, 3)
        np.testing.assert_array_equal(out[name][0], expected[name])


def test_a_node_whose_bound_timestep_misses_the_grid_fails_alone(tmp_path):
    model = pendulum(tmp_path, bind={"dt": [{"field": "opt.timestep"}]})
    out = model.simulate({"dt": np.array([0.001, 0.003])}, TIMES)  # 0.1 s is 33.3 steps of 3 ms
    assert np.isfinite(out["theta"][0]).all() and np.isnan(out["theta"][1]).all()
    with pytest.raises(ModelError, match="whole number of the scene's timesteps"):
        model.simulate({"dt": np.array([0.003])}, TIMES)


# --------------------------------------------------------------------------- failed runs

# A unit mass on a spring of stiffness k, semi-implicit Euler at h = 10 ms: stable while
# sqrt(k) h < 2, i.e. k < 4e4 N/m, and blowing up geometrically beyond.
SPRING = """\
<mujoco model="spring">
  <option timestep="0.01" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="mass">
      <joint name="slide" type="slide" axis="1 0 0" stiffness="1"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
    </body>
  </worldbody>
</mujoco>
"""


def euler_spring(k: float, times: np.ndarray, h: float = 0.01) -> np.ndarray:
    """x at ``times`` of x'' = -k x, x(0) = 0.1: v += h a(x); x += h v (MuJoCo's Euler)."""
    x, v, out = 0.1, 0.0, []
    for step in range(round(times[-1] / h) + 1):
        if np.isclose(step * h, times).any():
            out.append(x)
        v -= h * k * x
        x += h * v
    return np.array(out)


def test_divergence_fails_only_the_diverged_nodes(tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)  # MuJoCo would write MUJOCO_LOG.TXT here
    model = MujocoModel(
        xml=write(tmp_path, SPRING),
        bind={"k": [{"field": "jnt_stiffness", "name": "slide"}]},
        init={"qpos": {"slide": 0.1}},
        outputs={"x": {"qpos": "slide"}},
    )
    times = np.linspace(0.0, 2.0, 21)
    k = np.array([1e2, 3.9e4, 4.1e4, 1e6])
    out = model.simulate({"k": k}, times)
    for i in (0, 1):
        # the same recurrence; the stable case at the edge grows to ~1e1 with round-off
        np.testing.assert_allclose(out["x"][i], euler_spring(k[i], times), rtol=1e-9)
    assert np.isnan(out["x"][2:]).all()
    with pytest.raises(ModelError) as exc:
        model.simulate({"k": k[3:]}, times)
    assert "diverged" in str(exc.value) and "mjWARN_BADQACC" in str(exc.value)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert capfd.readouterr() == ("", "")


def test_a_node_whose_scene_does_not_compile_fails_alone(tmp_path):
    scene = SCENE.replace('size="0.05" mass="1"', 'size="{{ r }}" mass="1"')
    model = MujocoModel(
        xml=write(tmp_path, scene), params={"L": 0.5, "r": 0.05}, init=INIT, outputs=OUTPUTS
    )
    out = model.simulate({"r": np.array([0.05, -0.05])}, TIMES)
    np.testing.assert_array_equal(out["theta"][0], reference(spelled(0.5), TIMES)["theta"])
    assert np.isnan(out["theta"][1]).all()
    with pytest.raises(ModelError, match="MuJoCo cannot build the scene"):
        model.simulate({"r": np.array([-0.05])}, TIMES)


def test_placeholders_must_not_change_the_scene_structure(tmp_path):
    scene = (
        SCENE.replace('name="tip" pos', 'name="tip{{ s }}" pos')
        .replace('objname="tip"', 'objname="tip{{ s }}"')
        .replace('site="tip"', 'site="tip{{ s }}"')
    )
    model = MujocoModel(
        xml=write(tmp_path, scene),
        params={"L": 0.5, "s": 1.0},
        outputs={"theta": {"qpos": "hinge"}},
    )
    out = model.simulate({"s": np.array([2.0, 10.0])}, TIMES)  # "tip10.0" is a longer name
    assert np.isfinite(out["theta"][0]).all() and np.isnan(out["theta"][1]).all()
    with pytest.raises(ModelError, match="structure"):
        model.simulate({"s": np.array([10.0])}, TIMES)


# --------------------------------------------------------------------------- batch mechanics


def test_results_do_not_depend_on_the_number_of_threads(tmp_path, monkeypatch):
    model = pendulum(tmp_path)
    lengths = {"L": np.linspace(0.3, 0.9, 7)}
    runs = []
    for threads in ("1", "3"):
        monkeypatch.setenv("OMP_NUM_THREADS", threads)
        runs.append(model.simulate(lengths, TIMES))
    for name in OUTPUTS:
        np.testing.assert_array_equal(runs[0][name], runs[1][name])


@pytest.mark.parametrize(
    ("params", "path"),
    [
        ({"nope": np.array([1.0])}, "inputs.nope"),
        ({"L": np.ones((2, 2))}, "inputs.L"),
        ({"L": np.ones(2), "damping": np.ones(3)}, "inputs"),
    ],
)
def test_bad_batch_inputs_are_config_errors(tmp_path, params, path):
    model = pendulum(tmp_path, bind={"damping": [{"field": "dof_damping", "name": "hinge"}]})
    with pytest.raises(ConfigError) as exc:
        model.simulate(params, TIMES)
    assert exc.value.problems[-1].path == path


def test_the_factory_pickles_and_builds_the_model(tmp_path):
    factory = MujocoModelFactory(
        xml=write(tmp_path, SCENE),
        params={"L": 0.5},
        bind={"m": [{"field": "body_mass", "name": "bob"}]},
        init=INIT,
        outputs=OUTPUTS,
    )
    clone = pickle.loads(pickle.dumps(factory))
    assert clone == factory
    model = clone()
    assert model.outputs == tuple(OUTPUTS)
    np.testing.assert_array_equal(
        model.simulate({"m": np.array([1.0])}, TIMES)["theta"][0],
        reference(spelled(0.5), TIMES)["theta"],
    )


def test_pcmb_reports_an_xml_error_as_a_config_error_before_running(tmp_path, capsys):
    broken = SCENE.replace('type="sphere" size="0.05"', 'type="spere" size="0.05"')
    write(tmp_path, broken)
    config = tmp_path / "study.yaml"
    config.write_text(
        "name: broken\n"
        "model:\n"
        "  kind: mujoco\n"
        "  xml: scene.xml\n"
        "  params: {L: 0.5}\n"
        "  outputs: {theta: {qpos: hinge}}\n"
        "time: {start: 0.0, stop: 1.0, points: 11}\n"
        "inputs:\n"
        "  L: {dist: uniform, low: 0.4, high: 0.6}\n"
        "method: {kind: collocation, order: 2}\n"
        f"output: {tmp_path / 'out.h5'}\n",
        encoding="utf-8",
    )
    assert main(["run", str(config)]) == 2
    message = capsys.readouterr().err
    line = broken.splitlines().index(next(s for s in broken.splitlines() if "spere" in s)) + 1
    assert "model.xml" in message and "spere" in message and f"line {line}" in message
    assert not (tmp_path / "out.h5").exists()


def test_pcmb_run_names_the_diverged_nodes_and_exits_3(tmp_path, capsys):
    write(tmp_path, SPRING)
    config = tmp_path / "study.yaml"
    config.write_text(
        "name: spring\n"
        "model:\n"
        "  kind: mujoco\n"
        "  xml: scene.xml\n"
        "  bind: {k: [{field: jnt_stiffness, name: slide}]}\n"
        "  init: {qpos: {slide: 0.1}}\n"
        "  outputs: {x: {qpos: slide}}\n"
        "time: {start: 0.0, stop: 2.0, points: 21}\n"
        "inputs:\n"
        "  k: {dist: uniform, low: 1.0e2, high: 1.0e5}\n"  # unstable above 4e4
        "method: {kind: collocation, order: 3}\n"
        "execution: {jobs: 1, chunk_size: 4}\n"  # one batch: abort sees both failures
        f"output: {tmp_path / 'out.h5'}\n",
        encoding="utf-8",
    )
    assert main(["run", str(config)]) == 3
    message = capsys.readouterr().err
    # Gauss-Legendre nodes of U[1e2, 1e5]: 6.9e3, 3.3e4 are stable, 6.7e4, 9.3e4 diverge
    assert message.count("mjWARN_BADQACC") == 2
    assert "diverged" in message
