"""Tests of pcmb.run.journal and pcmb.run.fingerprint: round trip, superseding records,
refusals, atomicity under kills, the lock, the file table and which files a model has.

Whole runs killed, edited and resumed are in ``tests/test_resume.py``."""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.adapters.command.model import command_files
from pcmb.adapters.mujoco.files import mjcf_files
from pcmb.adapters.python.model import python_entry_files
from pcmb.errors import ResultFileError, UsageError
from pcmb.result import Status
from pcmb.run import journal as journal_module
from pcmb.run.fingerprint import MISSING, Fingerprint, changed_files, digest_files, model_files
from pcmb.run.journal import Journal

OUTPUTS = ("x", "v")
N_TIMES = 7


def make(directory: Path, fingerprint: str = "abc", n_nodes: int = 10) -> Journal:
    return Journal(directory, fingerprint, n_nodes, OUTPUTS, N_TIMES)


def chunk(indices: list[int], seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {name: rng.standard_normal((len(indices), N_TIMES)) for name in OUTPUTS}


def test_records_survive_reopening_bit_for_bit(tmp_path: Path) -> None:
    first = make(tmp_path / "j")
    a, b = chunk([0, 1, 2], 1), chunk([5, 6], 2)
    b["x"][1] = np.nan
    first.record([0, 1, 2], a, [Status.OK] * 3)
    first.record([5, 6], b, [Status.OK, Status.FAILED], {6: "ValueError: boom"})
    indices, values, status = make(tmp_path / "j").completed()
    np.testing.assert_array_equal(indices, [0, 1, 2, 5, 6])
    np.testing.assert_array_equal(status, [1, 1, 1, 1, 2])
    for name in OUTPUTS:
        np.testing.assert_array_equal(values[name], np.concatenate([a[name], b[name]]))
    assert make(tmp_path / "j").messages() == {6: "ValueError: boom"}


def test_a_later_record_supersedes_an_earlier_one(tmp_path: Path) -> None:
    journal = make(tmp_path / "j")
    journal.record([3, 4], chunk([3, 4], 1), [Status.FAILED, Status.OK], {3: "died"})
    again = make(tmp_path / "j")  # the resumed run appends after the existing records
    fixed = chunk([3], 2)
    again.record([3], fixed, [Status.OK])
    indices, values, status = make(tmp_path / "j").completed()
    np.testing.assert_array_equal(indices, [3, 4])
    np.testing.assert_array_equal(status, [Status.OK, Status.OK])
    np.testing.assert_array_equal(values["x"][0], fixed["x"][0])
    assert make(tmp_path / "j").messages() == {}


def test_chunks_give_every_node_once_in_node_order_with_its_latest_values(
    tmp_path: Path,
) -> None:
    journal = make(tmp_path / "j")
    first, late = chunk([6, 2, 3, 4], 1), chunk([3], 2)  # a record need not be sorted
    journal.record([6, 2, 3, 4], first, [Status.OK, Status.OK, Status.FAILED, Status.OK], {3: "x"})
    journal.record([0, 1], chunk([0, 1], 3), [Status.OK, Status.OK])
    make(tmp_path / "j").record([3], late, [Status.OK])  # node 3 re-run alone on a resume
    reopened = make(tmp_path / "j")
    indices, status = reopened.statuses()
    np.testing.assert_array_equal(indices, [0, 1, 2, 3, 4, 6])
    assert status.tolist() == [Status.OK] * 6
    pieces = list(reopened.chunks())
    # Runs of consecutive nodes of one record: [0, 1], [2], [3] (the later record), [4], [6].
    assert [piece[0].tolist() for piece in pieces] == [[0, 1], [2], [3], [4], [6]]
    expected = {2: first["x"][1], 3: late["x"][0], 4: first["x"][3], 6: first["x"][0]}
    for node, row in expected.items():
        found = next(values["x"][0] for idx, values, _ in pieces if idx[0] == node)
        np.testing.assert_array_equal(found, row)
    _, completed, _ = reopened.completed()
    np.testing.assert_array_equal(np.concatenate([v["v"] for _, v, _ in pieces]), completed["v"])


def test_a_journal_of_another_config_is_refused(tmp_path: Path) -> None:
    make(tmp_path / "j", fingerprint="abc")
    with pytest.raises(ResultFileError, match="was written for a different config; delete it"):
        make(tmp_path / "j", fingerprint="xyz")
    with pytest.raises(ResultFileError, match=r"n_nodes: 10 != 11.*--fresh"):
        make(tmp_path / "j", n_nodes=11)
    with pytest.raises(ResultFileError, match="outputs"):
        Journal(tmp_path / "j", "abc", 10, ("x",), N_TIMES)


def test_things_that_are_not_journals_are_refused(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    with pytest.raises(ResultFileError, match="not a directory"):
        make(tmp_path / "file")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "record-000000.npz").write_bytes(b"")
    with pytest.raises(ResultFileError, match="not a pcmb journal"):
        make(tmp_path / "d")
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "journal.json").write_text("{not json")
    with pytest.raises(ResultFileError, match=r"cannot read journal\.json"):
        make(tmp_path / "m")


def test_bad_records_are_rejected(tmp_path: Path) -> None:
    journal = make(tmp_path / "j")
    good = chunk([0, 1], 0)
    with pytest.raises(ValueError, match="distinct and in"):
        journal.record([0, 10], good, [1, 1])
    with pytest.raises(ValueError, match="distinct and in"):
        journal.record([1, 1], good, [1, 1])
    with pytest.raises(ValueError, match=r"Status\.OK"):
        journal.record([0, 1], good, [1, 0])
    with pytest.raises(ValueError, match="exactly the outputs"):
        journal.record([0, 1], {"x": good["x"]}, [1, 1])
    with pytest.raises(ValueError, match=r"shape \(2, 7\)"):
        journal.record([0, 1], {name: v[:, :-1] for name, v in good.items()}, [1, 1])
    with pytest.raises(ValueError, match="equal"):
        journal.record([0, 1], good, [1])
    with pytest.raises(ValueError, match="positive"):
        Journal(tmp_path / "k", "abc", 0, OUTPUTS, N_TIMES)
    with pytest.raises(ValueError, match="distinct"):
        Journal(tmp_path / "k", "abc", 5, ("x", "x"), N_TIMES)
    assert make(tmp_path / "j").completed()[0].size == 0


def test_a_write_interrupted_before_its_rename_leaves_no_record(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    journal = make(tmp_path / "j")
    journal.record([0], chunk([0], 0), [Status.OK])

    def crash(*_: object) -> None:
        raise OSError("killed before the rename")

    with monkeypatch.context() as patch:
        patch.setattr(journal_module.os, "replace", crash)
        with pytest.raises(OSError, match="killed"):
            journal.record([1], chunk([1], 1), [Status.OK])
    assert list((tmp_path / "j").glob(".tmp-*"))  # the half-done write is there ...
    reopened = make(tmp_path / "j")
    np.testing.assert_array_equal(reopened.completed()[0], [0])  # ... and never read
    reopened.record([1], chunk([1], 1), [Status.OK])
    np.testing.assert_array_equal(make(tmp_path / "j").completed()[0], [0, 1])


def test_an_unreadable_record_is_reported_by_name(tmp_path: Path) -> None:
    journal = make(tmp_path / "j")
    journal.record([0, 1], chunk([0, 1], 0), [Status.OK] * 2)
    record = tmp_path / "j" / "record-000000.npz"
    record.write_bytes(record.read_bytes()[:100])  # damage from outside pcmb
    with pytest.raises(ResultFileError, match=r"record-000000\.npz is unreadable"):
        make(tmp_path / "j").completed()


_WRITER = """
import sys
import numpy as np
from pcmb.run.journal import Journal

journal = Journal(sys.argv[1], "abc", 100000, ("x", "v"), 4000)
for i in range(100000):
    values = {"x": np.full((50, 4000), float(i)), "v": np.full((50, 4000), -float(i))}
    journal.record(np.arange(50 * i, 50 * i + 50) % 100000, values, np.ones(50))
"""


def test_a_writer_killed_mid_write_never_corrupts_the_journal(tmp_path: Path) -> None:
    # Each record is ~3 MB, so a kill lands in the middle of a write with high probability.
    script = tmp_path / "writer.py"
    script.write_text(_WRITER)
    directory = tmp_path / "j"
    writer = subprocess.Popen([sys.executable, str(script), str(directory)])
    try:
        deadline = time.monotonic() + 60
        while len(list(directory.glob("record-*.npz"))) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        # Kill while a temporary file exists, i.e. (almost always) in the middle of a write.
        while not list(directory.glob(".tmp-*")) and time.monotonic() < deadline:
            pass
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
    journal = Journal(directory, "abc", 100000, ("x", "v"), 4000)
    indices, values, status = journal.completed()
    count = len(list(directory.glob("record-*.npz")))
    assert count >= 3 and indices.size == 50 * count
    # Every visible record is complete: record i holds the value i for its 50 nodes.
    expected = (indices // 50).astype(float)
    np.testing.assert_array_equal(values["x"], np.repeat(expected[:, None], 4000, axis=1))
    np.testing.assert_array_equal(values["v"][:, -1], -expected)
    assert (status == Status.OK).all()


def test_exists_and_remove(tmp_path: Path) -> None:
    assert not Journal.exists(tmp_path / "j")
    journal = make(tmp_path / "j")
    journal.record([0], chunk([0], 0), [Status.OK])
    assert Journal.exists(tmp_path / "j")
    journal.remove()
    assert not (tmp_path / "j").exists()


def test_remove_lets_go_of_the_lock_and_a_closed_journal_writes_nothing(tmp_path: Path) -> None:
    first = make(tmp_path / "j")
    again = make(tmp_path / "j")  # the same process shares its lock
    again.record([0], chunk([0], 0), [Status.OK])
    assert (tmp_path / "j" / "lock").read_text() == f"{os.getpid()}\n"
    first.remove()
    assert not tmp_path.joinpath("j").exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(ResultFileError, match="no longer locked by this process"):
        again.record([1], chunk([1], 1), [Status.OK])
    fresh = make(tmp_path / "j")
    fresh.close()
    with pytest.raises(ResultFileError, match="no longer locked"):
        fresh.record([1], chunk([1], 1), [Status.OK])
    np.testing.assert_array_equal(make(tmp_path / "j").completed()[0], [])


# -- the lock --------------------------------------------------------------------------------


def test_a_refused_reopening_leaves_this_processs_open_journal_locked(tmp_path: Path) -> None:
    journal = make(tmp_path / "j")
    with pytest.raises(ResultFileError, match="different config"):
        make(tmp_path / "j", fingerprint="xyz")
    journal.record([0], chunk([0], 0), [Status.OK])  # still holds the lock
    Journal.check_free(tmp_path / "j")  # its own lock is no obstacle


_HOLDER = """
import sys
from pcmb.run.journal import Journal

journal = Journal(sys.argv[1], "abc", 10, ("x", "v"), 7)
print("locked", flush=True)
sys.stdin.read()
"""


def test_another_process_holding_the_journal_is_named_and_its_death_frees_it(
    tmp_path: Path,
) -> None:
    directory = tmp_path / "j"
    make(directory).record([0], chunk([0], 0), [Status.OK])  # let go of with the journal
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(directory)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline() == "locked\n"
        busy = rf"another pcmb run \(PID {holder.pid}\) is writing {directory}; wait for it"
        files = sorted(p.name for p in directory.iterdir())
        with pytest.raises(UsageError, match=busy):
            Journal.check_free(directory)
        assert Journal.exists(directory)  # a query, whoever holds the lock
        with pytest.raises(UsageError, match=busy):
            make(directory)
        assert sorted(p.name for p in directory.iterdir()) == files
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
        holder.stdin.close()
        holder.stdout.close()
    # SIGKILL leaves the lock file, but no lock: the journal opens, records intact.
    assert Journal.exists(directory)
    np.testing.assert_array_equal(make(directory).completed()[0], [0])
    assert (directory / "lock").read_text() == f"{os.getpid()}\n"


# -- the file table --------------------------------------------------------------------------


def test_a_changed_model_file_is_refused_by_name(tmp_path: Path) -> None:
    model, data = tmp_path / "model.py", tmp_path / "data.csv"
    model.write_text("x = 1\n")
    data.write_text("1,2\n")

    def fingerprint(digest: str = "abc") -> Fingerprint:
        return Fingerprint(digest, digest_files([data, model]))

    Journal(tmp_path / "j", fingerprint(), 10, OUTPUTS, N_TIMES).record(
        [0], chunk([0], 0), [Status.OK]
    )
    data.write_text("1,2\n")  # same content, new mtime: the same
    Journal(tmp_path / "j", fingerprint(), 10, OUTPUTS, N_TIMES)
    data.write_text("1,3\n")
    with pytest.raises(UsageError, match=f"model file {data} has changed since .*j was written"):
        Journal(tmp_path / "j", fingerprint(), 10, OUTPUTS, N_TIMES)
    model.write_text("x = 2\n")
    with pytest.raises(UsageError, match=f"model files {data}, {model} have changed"):
        Journal(tmp_path / "j", fingerprint(), 10, OUTPUTS, N_TIMES)
    with pytest.raises(ResultFileError, match="different config"):  # settings first
        Journal(tmp_path / "j", fingerprint("xyz"), 10, OUTPUTS, N_TIMES)
    model.write_text("x = 1\n")
    data.write_text("1,2\n")
    journal = Journal(tmp_path / "j", fingerprint(), 10, OUTPUTS, N_TIMES)
    np.testing.assert_array_equal(journal.completed()[0], [0])


def test_file_tables_and_their_differences(tmp_path: Path) -> None:
    (tmp_path / "a").write_bytes(b"a")
    table = digest_files([tmp_path / "a", tmp_path / "nothing", tmp_path / "." / "a"])
    assert list(table) == [str(tmp_path / "a"), str(tmp_path / "nothing")]
    assert table[str(tmp_path / "nothing")] == MISSING
    assert table[str(tmp_path / "a")] == (
        "ca978112ca1bbdcafac231b39a23dc4da786eff8147c4e72b9807785afee48bb"
    )
    assert changed_files({"p": "1", "q": "2"}, {"p": "1", "q": "3", "r": "4"}) == ["q", "r"]


# -- which files a model has -----------------------------------------------------------------


def test_an_mjcf_scene_brings_its_includes_and_asset_files(tmp_path: Path) -> None:
    (tmp_path / "parts").mkdir()
    (tmp_path / "scene.xml").write_text(
        """<mujoco>
  <compiler assetdir="assets" meshdir="meshes"/>
  <include file="parts/robot.xml"/>
  <asset>
    <texture name="sky" type="skybox" fileleft="sky_l.png" fileright="sky_r.png"/>
    <hfield name="ground" file="ground.png" size="1 1 1 1"/>
    <material name="m" rgba="1 0 0 1"/>
  </asset>
  <worldbody><geom type="box" size="{{ w }} 1 1"/></worldbody>
</mujoco>"""
    )
    (tmp_path / "parts" / "robot.xml").write_text(
        """<mujoco>
  <include file="parts/arm.xml"/>
  <asset><mesh name="body" file="body.stl"/><mesh name="x" file="{{ mesh }}"/></asset>
</mujoco>"""
    )
    (tmp_path / "parts" / "arm.xml").write_text("<mujoco><include file='scene.xml'/></mujoco>")
    expected = [
        "assets/sky_l.png",
        "assets/sky_r.png",
        "meshes/body.stl",
        "meshes/ground.png",
        "parts/arm.xml",
        "parts/robot.xml",
        "scene.xml",
    ]
    assert mjcf_files(tmp_path / "scene.xml") == sorted(tmp_path / p for p in expected)
    (tmp_path / "broken.xml").write_text("<mujoco>{{ not xml")
    assert mjcf_files(tmp_path / "broken.xml") == [tmp_path / "broken.xml"]


def test_a_command_model_brings_its_program_templates_files_and_absolute_arguments(
    tmp_path: Path,
) -> None:
    (tmp_path / "data.bin").write_bytes(b"")
    found = command_files(
        ["./bin/sim", "-i", str(tmp_path / "data.bin"), "/nonexistent", "out.csv"],
        ["deck.in"],
        ["mesh/part.msh"],
        tmp_path,
    )
    assert found == [
        tmp_path / "deck.in",
        tmp_path / "mesh" / "part.msh",
        tmp_path / "bin" / "sim",
        tmp_path / "data.bin",
    ]
    assert command_files(["python3", "sim.py"], [], [], tmp_path) == []  # found on PATH


def test_a_python_entry_brings_its_file_or_its_module_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "models" / "pkg").mkdir(parents=True)
    # A package's own code must not run in pcmb's process to find a module's file.
    (tmp_path / "models" / "pkg" / "__init__.py").write_text("RAN = True\n")
    (tmp_path / "models" / "pkg" / "deep_module_for_fingerprints.py").write_text("")
    entry = "pkg.deep_module_for_fingerprints:Model"
    assert python_entry_files("sim/m.py:Model", tmp_path) == [tmp_path / "sim" / "m.py"]
    monkeypatch.syspath_prepend(str(tmp_path / "models"))
    assert python_entry_files(entry, tmp_path / "models") == []
    assert "pkg" not in sys.modules
    # Once imported (as in the worker that built the model), its file is known.
    importlib.import_module("pkg.deep_module_for_fingerprints")
    try:
        assert python_entry_files(entry, tmp_path / "models") == [
            tmp_path / "models" / "pkg" / "deep_module_for_fingerprints.py"
        ]
    finally:
        for name in ("pkg.deep_module_for_fingerprints", "pkg"):
            sys.modules.pop(name, None)
    assert python_entry_files("no_such_module_anywhere:Model", tmp_path) == []
    assert python_entry_files("sys:Model", tmp_path) == []  # built in: no file


_STUDY = """\
name: fp
model: {kind: python, entry: lin.py:f, params: {a: 1.0}}
time: {start: 0.0, stop: 1.0, points: 3}
inputs: {a: {dist: uniform, low: 1.0, high: 2.0}}
method: {kind: collocation, order: 2}
execution: {jobs: 1}
output: out.h5
"""


def _study_fingerprint(folder: Path, text: str = _STUDY) -> Fingerprint:
    from pcmb.config.schema import load_config

    (folder / "lin.py").write_text(
        "import pcmb\n\n\n@pcmb.pointwise(outputs=('y',))\n"
        "def f(params, times):\n    return {'y': params['a'] * times}\n"
    )
    (folder / "study.yaml").write_text(text)
    study = pcmb.Study.from_config(load_config(folder / "study.yaml"))
    return study.fingerprint(study.node_set(), ("y",))


def test_a_study_fingerprint_ignores_what_cannot_change_node_values(tmp_path: Path) -> None:
    base = _study_fingerprint(tmp_path)
    assert base.files == digest_files([tmp_path / "lin.py"])
    for old, new in (
        ("name: fp", "# a comment\nname: fp  # and another"),
        ("name: fp", "name: other"),
        ("output: out.h5", "output: elsewhere.h5"),
        ("{jobs: 1}", "{jobs: 2, backend: inprocess, on_failure: retry, retries: 4}"),
        ("{jobs: 1}", "{jobs: 1}\nanalysis: {psd: [], samples: 1000}"),
    ):
        assert _study_fingerprint(tmp_path, _STUDY.replace(old, new)) == base, new
    for old, new in (
        ("{jobs: 1}", "{jobs: 1, chunk_size: 2}"),
        ("points: 3", "points: 4"),
        ("high: 2.0", "high: 2.5"),
        ("{a: 1.0}", "{a: 1.5}"),
        ("order: 2", "order: 3"),
    ):
        assert _study_fingerprint(tmp_path, _STUDY.replace(old, new)).digest != base.digest, new


def test_api_studies_fingerprint_a_python_entry_factory_by_its_file(tmp_path: Path) -> None:
    from pcmb.adapters.python.model import PythonModelFactory

    _study_fingerprint(tmp_path)  # writes lin.py
    inputs = {"a": pcmb.Uniform(1.0, 2.0)}
    times = np.linspace(0, 1, 3)
    study = pcmb.Study(PythonModelFactory("lin.py:f", tmp_path, {"a": 1.0}), inputs, times, order=2)
    found = study.fingerprint(study.node_set(), ("y",))
    assert found.files == digest_files([tmp_path / "lin.py"])

    @pcmb.pointwise(outputs=("y",))
    def inline(params: dict[str, float], times: np.ndarray) -> dict[str, np.ndarray]:
        return {"y": params["a"] * times}

    study = pcmb.Study(inline, inputs, times, order=2)
    assert study.fingerprint(study.node_set(), ("y",)).files == {}
    assert study.replace(jobs=2).fingerprint(study.node_set(), ("y",)) == study.fingerprint(
        study.node_set(), ("y",)
    )


def test_a_mujoco_study_fingerprints_its_scene_and_includes(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    from pcmb.config.schema import load_config

    (tmp_path / "body.xml").write_text(
        '<mujoco><worldbody><body name="bob" pos="0 0 -1"><joint name="hinge" type="hinge" '
        'axis="0 1 0"/><geom type="sphere" size="0.05" mass="1"/></body></worldbody></mujoco>'
    )
    (tmp_path / "scene.xml").write_text(
        '<mujoco><option timestep="0.01"/><include file="body.xml"/></mujoco>'
    )
    config = tmp_path / "study.yaml"
    config.write_text(
        """name: scene
model:
  kind: mujoco
  xml: scene.xml
  bind: {m: [{field: body_mass, name: bob}]}
  params: {m: 1.0}
  outputs: {theta: {qpos: hinge}}
time: {start: 0.0, stop: 0.1, points: 3}
inputs: {m: {dist: uniform, low: 0.5, high: 1.5}}
method: {kind: collocation, order: 1}
"""
    )
    study = pcmb.Study.from_config(load_config(config))
    assert model_files(study.model_factory) == [tmp_path / "body.xml", tmp_path / "scene.xml"]
    files = study.fingerprint(study.node_set(), ("theta",)).files
    assert list(files) == [str(tmp_path / "body.xml"), str(tmp_path / "scene.xml")]
