"""Trust: a resumed run never mixes old and new model code, an FMU's aliased variables are
not two inputs, and the FMU cache is never taken from another user's hands.

FMUs are built with pythonfmu at test time (DampedOscillator, co-simulation FMI 2.0:
x'' + c x' + k x = 0 stepped by its exact solution) and edited as the zip archives they are.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from cli_process import pcmb_cli, pcmb_here

ROOT = Path(__file__).resolve().parents[1]

# --------------------------------------------------------------------------- helpers

FMU_CONFIG = """\
name: trust-fmu
model:
  kind: fmu
  fmu: {fmu}
  params: {{x0: 1.0, v0: 0.0}}
  outputs: [x]
time: {{start: 0.0, stop: 2.0, points: 11}}
inputs:
{inputs}
method: {{kind: collocation, order: 2, validation: 0}}
execution: {{jobs: 1}}
output: out.h5
"""
K_INPUT = "  k: {dist: uniform, low: 3.5, high: 4.5}"
C_INPUT = "  c: {dist: uniform, low: 0.2, high: 0.6}"


@pytest.fixture
def oscillator_fmu(fmu_dir: Path) -> Path:
    """DampedOscillator.fmu of the session's FMUs (``fmu_dir`` in conftest.py)."""
    return fmu_dir / "DampedOscillator.fmu"


def edited_fmu(source: Path, dest: Path, edit: dict[str, object]) -> Path:
    """A copy of the FMU ``source`` at ``dest`` with members replaced: name -> new bytes, or a
    function of the old bytes."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(dest, "w") as new:
        for item in old.infolist():
            data = old.read(item.filename)
            change = edit.get(item.filename)
            if change is not None:
                data = change(data) if callable(change) else change
            new.writestr(item, data)
    return dest


def damped_x(times: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """x of x'' + c x' + k x = 0 from x = 1 at rest, (N, T) for (N,) k and c."""
    from pcmb.references import damped_oscillator

    return np.array([damped_oscillator(times, ki, ci) for ki, ci in zip(k, c, strict=True)])


# --------------------------------------------------------------------------- item 2: resume

# The model's entry imports helper.py (beside it) and reads data/scale.txt (listed under
# model.files); FAIL_ABOVE=a makes the nodes above a fail, so that an aborted run leaves a
# journal of the nodes below it.
ENTRY = """
import os
from pathlib import Path

import pcmb

import helper

SCALE = Path(__file__).with_name("data") / "scale.txt"


@pcmb.pointwise(outputs=("y",))
def line(params, times):
    limit = os.environ.get("FAIL_ABOVE")
    if limit is not None and params["a"] > float(limit):
        raise RuntimeError("stopped here")
    scale = float(SCALE.read_text())
    return {"y": scale * helper.slope(params["a"]) * times}
"""
HELPER = "def slope(a):\n    return a\n"
PYTHON_CONFIG = """\
name: trust-resume
model:
  kind: python
  entry: model.py:line
  params: {a: 1.0}
  files: [data/scale.txt]
time: {start: 0.0, stop: 1.0, points: 3}
inputs:
  a: {dist: uniform, low: 1.0, high: 3.0}
method: {kind: collocation, order: 3, validation: 0}
execution: {jobs: 1, chunk_size: 1}
output: out.h5
"""


@pytest.fixture
def interrupted(tmp_path: Path) -> Path:
    """A python study whose run stopped with 2 of its 4 nodes finished, its journal kept."""
    (tmp_path / "model.py").write_text(ENTRY)
    (tmp_path / "helper.py").write_text(HELPER)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "scale.txt").write_text("1.0\n")
    (tmp_path / "study.yaml").write_text(PYTHON_CONFIG)
    stopped = pcmb_cli("run", "study.yaml", "--quiet", cwd=tmp_path, env={"FAIL_ABOVE": "2.0"})
    assert stopped.returncode == 3, stopped.stderr
    assert (tmp_path / "out.h5.journal").is_dir()
    return tmp_path


@pytest.mark.slow
@pytest.mark.parametrize(
    ("edited", "content"),
    [("helper.py", "def slope(a):\n    return 2 * a\n"), ("data/scale.txt", "2.0\n")],
)
def test_resume_refuses_an_edited_imported_module_or_listed_file(
    interrupted: Path, edited: str, content: str
) -> None:
    folder = interrupted
    journal = sorted((folder / "out.h5.journal").iterdir())
    changed = folder / edited
    original = changed.read_text()
    changed.write_text(content)
    refused = pcmb_here("run", "study.yaml", "--quiet", "--resume", cwd=folder)
    assert refused.returncode == 2, refused.stderr
    assert f"model file {changed.resolve()} has changed since" in refused.stderr
    assert not (folder / "out.h5").exists()
    assert sorted((folder / "out.h5.journal").iterdir()) == journal

    changed.write_text(original)  # the old content again: resumable, every node the same code
    resumed = pcmb_cli("run", "study.yaml", "--quiet", "--resume", cwd=folder)
    assert resumed.returncode == 0, resumed.stderr
    import pcmb

    result = pcmb.load(folder / "out.h5")
    np.testing.assert_array_equal(result.values["y"], result.params[:, [0]] * result.times)


@pytest.mark.slow
def test_a_missing_listed_model_file_is_named_at_its_key(tmp_path: Path) -> None:
    (tmp_path / "model.py").write_text(ENTRY)
    (tmp_path / "helper.py").write_text(HELPER)
    (tmp_path / "study.yaml").write_text(PYTHON_CONFIG)
    done = pcmb_here("validate", "study.yaml", cwd=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "model.files[0]: file " in done.stderr and "scale.txt does not exist" in done.stderr


def test_a_package_entry_reports_the_modules_it_loaded_from_its_folder_tree(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pcmb.adapters.python.model import PythonModelFactory

    monkeypatch.setattr(sys, "path", list(sys.path))  # the model extends it

    name = f"trust_pkg_{tmp_path.name.replace('-', '_')}"  # a fresh name in this process
    package = tmp_path / name
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "util.py").write_text("def slope(a):\n    return a\n")
    (tmp_path / f"{name}_shared.py").write_text("OFFSET = 0.0\n")
    # A folder of installed packages inside the tree (a virtual environment) does not count.
    installed = tmp_path / "venv" / "site-packages"
    installed.mkdir(parents=True)
    (installed / f"{name}_installed.py").write_text("")
    (package / "model.py").write_text(
        "import sys\n"
        f"sys.path.append({str(installed)!r})\n"
        f"import {name}_installed\n"
        f"import {name}_shared\n"
        f"from {name}.util import slope\n\n"
        "import pcmb\n\n\n"
        "@pcmb.pointwise(outputs=('y',))\n"
        "def line(params, times):\n"
        "    return {'y': slope(params['a']) * times}\n"
    )
    factory = PythonModelFactory(f"{name}.model:line", tmp_path, {"a": 1.0})
    factory()
    assert factory.model_files() == [package / "model.py"]
    assert factory.loaded_files() == sorted(
        [
            package / "__init__.py",
            package / "model.py",
            package / "util.py",
            tmp_path / f"{name}_shared.py",
        ]
    )


def test_a_models_files_do_not_include_another_models_loaded_in_the_same_process(
    tmp_path: Path,
) -> None:
    """A notebook or a warm worker that built another model of the same folder first must
    not count that model's modules: the journal would then differ from a fresh process's,
    and a resume be refused as "changed"."""
    from pcmb.adapters.python.model import PythonModelFactory

    stem = f"sibling_{tmp_path.name.replace('-', '_')}"  # fresh module names in this process
    (tmp_path / f"{stem}_helper.py").write_text("SCALE = 2.0\n")
    (tmp_path / f"{stem}_other.py").write_text("OFFSET = 1.0\n")
    (tmp_path / "first.py").write_text(
        f"import pcmb\nimport {stem}_helper\n\n\n@pcmb.pointwise(outputs=('y',))\n"
        f"def line(params, times):\n    return {{'y': {stem}_helper.SCALE * times}}\n"
    )
    (tmp_path / "second.py").write_text(
        f"import pcmb\nfrom {stem}_other import OFFSET\n\n\n@pcmb.pointwise(outputs=('y',))\n"
        "def line(params, times):\n    return {'y': times + OFFSET}\n"
    )
    first = PythonModelFactory("first.py:line", tmp_path, {})
    second = PythonModelFactory("second.py:line", tmp_path, {})
    first()
    alone = first.loaded_files()
    second()
    assert first.loaded_files() == alone == [tmp_path / "first.py", tmp_path / f"{stem}_helper.py"]


@pytest.mark.parametrize("kind", ["python", "command", "mujoco", "fmu"])
def test_every_adapter_declares_the_files_its_model_reads(
    kind: str, oscillator_fmu: Path, tmp_path: Path
) -> None:
    from pcmb.adapters.protocol import ModelFactory
    from pcmb.adapters.registry import spec_class
    from pcmb.config.loader import parse_yaml
    from pcmb.run.fingerprint import model_files

    if kind == "mujoco":
        pytest.importorskip("mujoco")
    examples = ROOT / "tests" / "data" / "adapters"
    text = (examples / f"{kind}.yaml").read_text()
    text = text.replace("${PYTHON}", sys.executable).replace(
        "${FMU_DIR}", str(oscillator_fmu.parent)
    )
    data, _, problems = parse_yaml(text, kind)
    assert not problems
    factory = spec_class(kind).model_validate(data["model"]).factory(examples)
    assert type(factory).model_files is not ModelFactory.model_files
    found = model_files(factory)
    assert found and all(path.is_absolute() and path.is_file() for path in found), found


# --------------------------------------------------------------------------- item 4: aliases


@pytest.mark.slow
def test_fmu_variables_aliasing_one_value_reference_are_not_two_inputs(
    oscillator_fmu: Path, tmp_path: Path
) -> None:
    # c gets k's value reference: the two names are aliases of one value of the FMU.
    aliased = edited_fmu(
        oscillator_fmu,
        tmp_path / "Aliased.fmu",
        {
            "modelDescription.xml": lambda xml: xml.replace(
                b'name="c" valueReference="1"', b'name="c" valueReference="0"'
            )
        },
    )
    (tmp_path / "study.yaml").write_text(
        FMU_CONFIG.format(fmu=aliased, inputs=f"{K_INPUT}\n{C_INPUT}")
    )
    for command in (("validate", "study.yaml"), ("run", "study.yaml", "--quiet")):
        done = pcmb_here(*command, cwd=tmp_path)
        assert done.returncode == 2, done.stdout + done.stderr
        assert re.search(r"inputs\.c: .*inputs\.k", done.stderr), done.stderr
        assert "valueReference 0" in done.stderr
        assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.h5").exists()

    # From Python, where no validator runs, the study refuses it before any node.
    import pcmb
    from pcmb.adapters.fmu.factory import FmuModelFactory
    from pcmb.errors import UsageError

    study = pcmb.Study(
        FmuModelFactory(fmu=aliased, outputs=("x",)),
        {"k": pcmb.Uniform(3.5, 4.5), "c": pcmb.Uniform(0.2, 0.6)},
        np.linspace(0.0, 2.0, 11),
        order=1,
        jobs=1,
        validation=0,
    )
    with pytest.raises(UsageError, match=r"inputs\.c: 'c' and 'k' \(inputs\.k\)"):
        study.run(tmp_path / "python.h5")
    assert not (tmp_path / "python.h5.journal").exists()


# --------------------------------------------------------------------------- item 9: FMU cache


def study_env(cache: Path) -> dict[str, str]:
    """The environment of a run whose per-user cache folder is ``cache``."""
    return {"XDG_CACHE_HOME": str(cache)}


def plant(archive: Path, folder: Path, marker: Path) -> None:
    """Extract ``archive`` into ``folder`` with its model code tampered: it writes ``marker``
    when loaded and steps the oscillator with twice its stiffness."""
    with zipfile.ZipFile(archive) as zipped:
        zipped.extractall(folder)
    code = folder / "resources" / "DampedOscillator.py"
    text = code.read_text().replace("w = math.sqrt(self.k", "w = math.sqrt(2 * self.k")
    code.write_text(f"open({str(marker)!r}, 'w').close()\n" + text)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["edited", "linked"])
def test_a_planted_fmu_cache_entry_never_runs(
    oscillator_fmu: Path, tmp_path: Path, how: str
) -> None:
    marker = tmp_path / "planted-code-ran"
    digest = hashlib.sha256(oscillator_fmu.read_bytes()).hexdigest()[:32]
    cache = tmp_path / "cache"
    # Where pcmb extracted an FMU (the shared temporary folder, anyone could plant it: the
    # run's $TMPDIR, this test's own so that no other test process meets it), and where it
    # does now: the user's own cache, private, whose entries it checks (an entry edited in
    # place, or a link to a folder elsewhere).
    temporary = tmp_path / "tmp"
    shared = temporary / "pcmb-fmu" / digest
    private = cache / "pcmb" / "fmu" / digest
    plant(oscillator_fmu, shared, marker)
    if how == "edited":
        plant(oscillator_fmu, private, marker)
        private.chmod(0o700)
    else:
        plant(oscillator_fmu, tmp_path / "elsewhere", marker)
        private.parent.mkdir(parents=True)
        private.symlink_to(tmp_path / "elsewhere")
    for folder in (cache / "pcmb", cache / "pcmb" / "fmu"):
        folder.chmod(0o700)
    (tmp_path / "study.yaml").write_text(
        FMU_CONFIG.format(fmu=oscillator_fmu, inputs=f"{K_INPUT}\n{C_INPUT}")
    )
    environment = {**study_env(cache), "TMPDIR": str(temporary)}
    done = pcmb_cli("run", "study.yaml", "--quiet", env=environment, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not marker.exists()
    import pcmb

    result = pcmb.load(tmp_path / "out.h5")
    np.testing.assert_allclose(
        result.values["x"], damped_x(result.times, *result.params.T), atol=1e-12
    )
    # The tampered entry was replaced by the archive's own content.
    assert not private.is_symlink()
    with zipfile.ZipFile(oscillator_fmu) as zipped:
        genuine = zipped.read("resources/DampedOscillator.py")
    assert (private / "resources" / "DampedOscillator.py").read_bytes() == genuine


@pytest.mark.slow
@pytest.mark.parametrize("folder", ["pcmb", "pcmb/fmu"])
@pytest.mark.parametrize("spoiled", ["owned by uid 65534", "writable by other users"])
def test_an_fmu_cache_folder_of_another_user_or_open_to_all_is_refused(
    oscillator_fmu: Path, tmp_path: Path, folder: str, spoiled: str
) -> None:
    cache = tmp_path / "cache"
    spoilt = cache / folder
    spoilt.mkdir(parents=True, mode=0o700)
    if spoiled.startswith("owned"):
        if os.getuid() != 0:
            pytest.skip("giving a folder to another user (chown) needs root")
        os.chown(spoilt, 65534, 65534)  # nobody
    else:
        spoilt.chmod(0o777)
    (tmp_path / "study.yaml").write_text(FMU_CONFIG.format(fmu=oscillator_fmu, inputs=K_INPUT))
    done = pcmb_cli("run", "study.yaml", "--quiet", env=study_env(cache), cwd=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"model.fmu: the FMU cache folder {spoilt} is {spoiled}" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.h5").exists()
    assert not any(p.name not in ("fmu",) for p in (cache / "pcmb").iterdir())
    assert not (cache / "pcmb" / "fmu").exists() or not any((cache / "pcmb" / "fmu").iterdir())
