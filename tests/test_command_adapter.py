"""``kind: command`` from a config file: what its failures report, and its documentation.

(Where its config errors point is checked with the other config errors, tests/test_config.py.)

The simulator is tests/data/sim_decay.py, run by this interpreter as a real process: its
parameter ``mode`` selects a misbehaviour (1: a message on stderr and exit code 3). Nodes of
``mode ~ U[0, 1.4]`` at chaos order 3 are the Gauss points 0.097, 0.46, 0.94 and 1.30, so
node 3 fails and nodes 0-2 succeed.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.adapters.command import CommandModel
from pcmb.adapters.command.spec import CommandModelSpec, CommandOutputSpec
from pcmb.cli import main
from pcmb.errors import ModelError

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"
SIMULATOR = DATA / "sim_decay.py"
STDERR_LINE = "something went wrong in the solver"  # what sim_decay.py prints in mode 1


def config_text(model: str, run_dir: Path, **execution: str) -> str:
    """A study of sim_decay.py with ``model`` lines added to the model section."""
    options = ", ".join(f"{k}: {v}" for k, v in {"jobs": 2, **execution}.items())
    return f"""\
name: failing
model:
  kind: command
  command: [{sys.executable}, sim_decay.py, out.csv]
  files: [{SIMULATOR}]
  params: {{k: 2.0, y0: 1.0, mode: 0.0}}
  outputs: [y]
  output: {{file: out.csv}}
  run_dir: {run_dir}
{model}time: {{start: 0.0, stop: 2.0, points: 5}}
inputs:
  mode: {{dist: uniform, low: 0.0, high: 1.4}}
method: {{kind: collocation, order: 3, validation: 0}}
execution: {{{options}}}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "study.yaml"
    path.write_text(text, encoding="utf-8")
    return path


# --------------------------------------------------------------------------- failures


def kept_directories(run_dir: Path) -> list[Path]:
    return sorted(run_dir.iterdir()) if run_dir.exists() else []


def test_a_failed_node_reports_its_stderr_and_kept_directory(tmp_path, capsys):
    run_dir = tmp_path / "nodes"
    config = write(tmp_path, config_text("", run_dir, on_failure="abort"))
    out = tmp_path / "out.h5"
    assert main(["run", str(config), "-o", str(out), "--quiet"]) == 3
    err = capsys.readouterr().err
    (kept,) = kept_directories(run_dir)  # keep: failed is the default: the others are gone
    assert json.loads((kept / "params.json").read_text())["params"]["mode"] > 1.0
    assert STDERR_LINE in (kept / "stderr.txt").read_text()
    expected = (
        f"node 3 (mode=1.3028): ModelError: exited with code 3; last lines of stderr.txt: "
        f"'{STDERR_LINE}' [work directory kept: {kept}]"
    )
    assert f"  {expected}\n" in err
    assert not out.exists()


@pytest.mark.slow
def test_regress_names_every_kept_directory_in_a_warning_record(tmp_path, capsys):
    run_dir = tmp_path / "nodes"
    text = config_text("", run_dir, on_failure="regress").replace("validation: 0", "validation: 16")
    out = tmp_path / "out.h5"
    assert main(["run", str(write(tmp_path, text)), "-o", str(out), "--quiet"]) == 0
    result = pcmb.load(out)
    (failure,) = result.failures
    assert failure.index == 3
    assert f"'{STDERR_LINE}' [work directory kept: {run_dir}" in failure.message
    records = [w for w in result.warnings if w.code == "nodes-failed"]
    assert len(records) == 2  # the collocation nodes, and the held-out runs
    assert str(failure) in records[0].message
    # mode in [1, 1.4) fails: exactly the held-out runs placed there (Leja points of one
    # input, docs/diagnostics.md), some but not all of them.
    failed = int(np.sum(result.held_out.params[:, 0] >= 1.0))
    assert 0 < failed < 16 and int(np.sum(~result.held_out.ok)) == failed
    assert records[1].message.startswith(f"{failed} of 16 held-out run(s) failed and were left")
    kept = kept_directories(run_dir)
    assert len(kept) == 1 + failed  # one node, and the failed held-out runs
    for workdir in kept:
        named = [w for w in records if f"[work directory kept: {workdir}]" in w.message]
        assert len(named) == 1, workdir
        assert STDERR_LINE in (workdir / "stderr.txt").read_text()
    capsys.readouterr()
    assert main(["inspect", str(out)]) == 0
    shown = capsys.readouterr().out
    assert f"\nfailed   {failure}" in shown
    for record in records:
        assert f"\nwarning  {record}" in shown


@pytest.mark.parametrize(("keep", "kept"), [("none", 0), ("all", 5)])
def test_keep_none_and_all(tmp_path, capsys, keep, kept):
    run_dir = tmp_path / "nodes"
    config = write(tmp_path, config_text(f"  keep: {keep}\n", run_dir, on_failure="regress"))
    assert main(["run", str(config), "-o", str(tmp_path / "out.h5"), "--quiet"]) == 0
    assert len(kept_directories(run_dir)) == kept  # all: 4 nodes and the nominal run
    (failure,) = pcmb.load(tmp_path / "out.h5").failures
    assert STDERR_LINE in failure.message
    assert ("work directory kept" in failure.message) == (keep == "all")


@pytest.mark.parametrize("mode", [0o777, 0o770], ids=["0777", "0770"])
def test_a_run_dir_others_can_write_is_refused_before_any_run(tmp_path, capsys, mode):
    """Another user who can rename entries of ``run_dir`` could swap a node's work directory
    for a link (and plant its outputs): such a folder is refused at ``model.run_dir``."""
    run_dir = tmp_path / "shared"
    run_dir.mkdir()
    run_dir.chmod(mode)
    config = write(tmp_path, config_text("", run_dir))
    assert main(["validate", str(config)]) == 2
    error = capsys.readouterr().err
    assert "model.run_dir" in error
    assert f"writable by other users (mode {mode:04o})" in error
    assert not list(run_dir.iterdir())


def test_a_sticky_shared_run_dir_like_tmp_is_accepted(tmp_path, capsys):
    run_dir = tmp_path / "sticky"
    run_dir.mkdir()
    run_dir.chmod(0o1777)  # others may add entries but not rename or remove this user's
    config = write(tmp_path, config_text("  keep: none\n", run_dir, on_failure="regress"))
    assert main(["run", str(config), "-o", str(tmp_path / "out.h5"), "--quiet"]) == 0
    assert pcmb.load(tmp_path / "out.h5").failures  # node 3 fails as always; the rest ran


# --------------------------------------------------------------------------- outputs


def test_a_whitespace_table_with_a_missing_column_lists_the_columns_found(tmp_path):
    model = CommandModel(
        [sys.executable, "sim_decay.py", "out.txt"],
        params={"k": 2.0, "y0": 1.0},
        outputs=["y", "z"],
        output_file="out.txt",
        output_format="table",
        files=[str(SIMULATOR)],
        run_dir=tmp_path,
    )
    times = np.linspace(0.0, 2.0, 5)
    with pytest.raises(
        ModelError, match=r"output\(s\) 'z' missing from out.txt \(found: time, y, dy\)"
    ):
        model.simulate({"k": np.array([1.5])}, times)


# --------------------------------------------------------------------------- the docs


def expected_defaults() -> dict[str, str]:
    """Key -> its default as the docs' tables write it (a default of None is described)."""
    fields = {
        **{k: f for k, f in CommandModelSpec.model_fields.items() if k not in ("kind", "output")},
        **{f"output.{k}": f for k, f in CommandOutputSpec.model_fields.items()},
    }
    shown = {}
    for key, field in fields.items():
        if field.is_required():
            shown[key] = "required"
        elif field.default_factory is not None:
            shown[key] = f"`{field.default_factory()!r}`"
        else:
            shown[key] = None if field.default is None else f"`{field.default}`"
    return shown


@pytest.mark.parametrize(
    ("page", "heading"),
    [("README.md", "### Wrapping a program"), ("docs/models.md", "## `kind: command`")],
)
def test_the_readme_and_models_page_list_every_key_with_its_default(page, heading):
    text = (ROOT / page).read_text(encoding="utf-8")
    section = text[text.index(heading) :]
    section = section[: section.index("\n#", 1)]
    rows = dict(re.findall(r"^\| `([\w.]+)` \| ([^|]+?) \|", section, re.MULTILINE))
    expected = expected_defaults()
    assert rows.keys() == expected.keys()
    for key, default in expected.items():
        if default is None:
            assert rows[key] != "required" and not rows[key].startswith("`"), key
        else:
            assert rows[key] == default, key


@pytest.mark.slow
def test_the_ac_sweep_example_is_tensor_collocation_on_a_frequency_axis(tmp_path, capsys):
    """configs/command_frequency_response.yaml against an independent tensor Gauss-Legendre
    quadrature of the closed-form response at the same order: the same nodes and weights,
    so only the CSV's printed digits (repr: round-trip exact) and summation order differ."""
    out = tmp_path / "ac.h5"
    config = ROOT / "configs" / "command_frequency_response.yaml"
    assert main(["run", str(config), "-o", str(out), "--quiet"]) == 0
    result = pcmb.load(out)
    frequencies = np.geomspace(0.05, 2.0, 60)
    np.testing.assert_allclose(result.axes["gain"].values, frequencies, rtol=1e-12)
    x, w = np.polynomial.legendre.leggauss(9)
    k, c = np.meshgrid(4.0 + 0.5 * x, 0.4 + 0.2 * x, indexing="ij")
    weight = np.outer(w, w).ravel() / 4
    omega = 2 * np.pi * frequencies
    gain = 1 / np.abs(k.ravel()[:, None] - omega**2 + 1j * c.ravel()[:, None] * omega)
    mean = weight @ gain
    std = np.sqrt(weight @ (gain - mean) ** 2)
    scale = std.max()
    np.testing.assert_allclose(np.ravel(result.mean("gain")), mean, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(np.ravel(result.std("gain")), std, rtol=0, atol=1e-12 * scale)
    assert main(["inspect", str(out)]) == 0
    assert "on frequency [Hz], 60 points" in capsys.readouterr().out
