"""Command-line faults: a sweep folder two sweeps write at once, a journal no flag could get
past, dask's logs under --quiet, a foreign file at the output path."""

from __future__ import annotations

import csv
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import gated_pcmb, pcmb_cli, pcmb_here

import pcmb
from pcmb.cli import main
from pcmb.config.schema import load_config
from pcmb.errors import ResultFileError, UsageError
from pcmb.run.journal import Journal
from pcmb.study import Study
from pcmb.sweep.runner import LEDGER

GROWTH = '''
import os
import time

import numpy as np


class Growth:
    """y = exp(a t); slow on purpose: waits while the file named by $GATE exists (and says
    so in $GATE.reached)."""

    outputs = ("y",)

    def __init__(self, a=0.5):
        self.parameters = {"a": a}

    def simulate(self, params, times):
        gate = os.environ.get("GATE")
        if gate and os.path.exists(gate):
            open(gate + ".reached", "w").close()
        while gate and os.path.exists(gate):
            time.sleep(0.01)
        a = np.asarray(params["a"], float)
        return {"y": np.exp(a[:, None] * times)}
'''


def _growth_sweep(folder: Path) -> Path:
    """A one-input sweep of ``Growth``: collocation orders 1 and 2 against order 4."""
    (folder / "growth.py").write_text(GROWTH)
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            """\
            name: growth
            model:
              kind: python
              entry: growth.py:Growth
              params: {a: 0.5}
            time: {start: 0.0, stop: 1.0, points: 5}
            inputs:
              a: {dist: uniform, low: 0.0, high: 1.0}
            method: {kind: collocation, order: 2, validation: 0}
            execution: {jobs: 1, chunk_size: 1}
            output: out.h5
            sweep:
              methods:
                - {kind: collocation, order: [1, 2]}
              reference: {kind: collocation, order: 4}
            """
        )
    )
    return config


# -- 10: one sweep at a time in a folder ------------------------------------------------------


def _stamps(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``folder`` with its inode and modification time."""
    return {
        str(p.relative_to(folder)): (p.stat().st_ino, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.mark.slow
def test_a_resumed_sweep_is_refused_while_another_writes_the_folder(tmp_path: Path) -> None:
    _growth_sweep(tmp_path)
    sweep = ("sweep", "study.yaml", "-o", "out")
    # The first holds the folder and waits.
    reached = (tmp_path / "gate.reached").exists
    with gated_pcmb(
        *sweep, "--quiet", cwd=tmp_path, gate=tmp_path / "gate", ready=reached
    ) as first:
        before = _stamps(tmp_path / "out")
        second = pcmb_here(*sweep, "--resume", "--quiet", cwd=tmp_path)
        assert second.returncode == 2, second.stderr
        assert _stamps(tmp_path / "out") == before  # nothing written, not even the ledger
        assert f"(PID {first.pid}) is writing the sweep folder out;" in second.stderr
        assert "pcmb.cli sweep study.yaml -o out --quiet" in second.stderr  # its command
        assert "Traceback" not in second.stderr
    folder = tmp_path / "out"
    with open(folder / "sweep.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["method"], r["setting"]) for r in rows] == [
        ("collocation", "order=1"),
        ("collocation", "order=2"),
    ]
    assert all(np.isfinite(float(r["err_mean"])) for r in rows)
    assert not (folder / LEDGER).exists()
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".")]  # no temporaries
    files = ["reference.h5", *(r["file"] for r in rows)]
    assert sorted(p.name for p in folder.glob("*.h5")) == sorted([*files, "sweep.h5"])
    for name in files:
        assert pcmb.load(folder / name).status.min() == 1  # every node ok


# -- 11: --fresh, the way out of a journal that cannot be continued ----------------------------


def _corrupt(journal: Path) -> None:
    journal.mkdir()
    (journal / "journal.json").write_text("{not json")


def _foreign(journal: Path) -> None:
    Journal(journal, "another config", 16, ("y", "z"), 5).close()


def _headless(journal: Path) -> None:
    journal.mkdir()
    (journal / "record-000000.npz").write_bytes(b"not a zip")


@pytest.mark.slow
@pytest.mark.parametrize("spoil", [_corrupt, _foreign, _headless])
def test_a_journal_that_cannot_be_continued_has_a_way_out(
    tmp_path, linear_study, capsys, spoil
) -> None:
    config = linear_study()
    out = tmp_path / "out.h5"
    spoil(tmp_path / "out.h5.journal")
    assert main(["run", str(config), "--quiet"]) == 2
    refused = capsys.readouterr().err
    assert "--fresh" in refused and "Traceback" not in refused
    assert main(["run", str(config), "--quiet", "--resume"]) == 2
    refused = capsys.readouterr().err
    assert "--fresh" in refused and "drop --resume" not in refused
    assert not out.exists()
    assert main(["run", str(config), "--quiet", "--fresh"]) == 0
    result = pcmb.load(out)
    np.testing.assert_allclose(result.mean("y"), 2 * result.times + 1, atol=1e-12)
    assert not (tmp_path / "out.h5.journal").exists()


_HOLDER = """
import fcntl, os, sys

fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)
fcntl.flock(fd, fcntl.LOCK_EX)
os.write(fd, f"{os.getpid()}\\n".encode())
print("locked", flush=True)
sys.stdin.read()
"""


def test_fresh_never_discards_a_journal_a_live_run_holds(tmp_path, linear_study, capsys) -> None:
    config = linear_study()
    journal = tmp_path / "out.h5.journal"
    _corrupt(journal)
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(journal / "lock")],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline() == "locked\n"
        assert main(["run", str(config), "--quiet", "--fresh"]) == 2
        err = capsys.readouterr().err
        assert f"(PID {holder.pid})" in err
        assert (journal / "journal.json").read_text() == "{not json"
    finally:
        holder.kill()
        holder.wait()
        holder.stdin.close()
        holder.stdout.close()


def test_fresh_leaves_a_folder_that_is_not_a_journal(tmp_path, linear_study, capsys) -> None:
    config = linear_study()
    journal = tmp_path / "out.h5.journal"
    _corrupt(journal)
    (journal / "notes.txt").write_text("mine")
    assert main(["run", str(config), "--quiet", "--fresh"]) == 2
    err = capsys.readouterr().err
    assert "notes.txt" in err and str(journal) in err
    assert (journal / "notes.txt").read_text() == "mine"


@pytest.mark.slow
def test_fresh_in_the_python_api(tmp_path, linear_study) -> None:
    study = Study.from_config(load_config(linear_study()))
    out = tmp_path / "api.h5"
    _foreign(Path(f"{out}.journal"))
    with pytest.raises(ResultFileError, match="--fresh"):
        study.run(out, resume=True, progress=False)
    with pytest.raises(UsageError, match="fresh"):
        study.run(out, resume=True, fresh=True, progress=False)
    result = study.run(out, fresh=True, progress=False)
    np.testing.assert_allclose(result.mean("y"), 2 * result.times + 1, atol=1e-12)


@pytest.mark.slow
def test_a_sweep_with_an_unreadable_ledger_starts_over_with_fresh(tmp_path, capsys) -> None:
    config = _growth_sweep(tmp_path)
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / LEDGER).write_text("{broken")
    (folder / "reference.h5.journal").mkdir()
    (folder / "reference.h5.journal" / "journal.json").write_text("{broken")
    assert main(["sweep", str(config), "-o", str(folder), "--quiet"]) == 2
    assert "--fresh" in capsys.readouterr().err
    assert main(["sweep", str(config), "-o", str(folder), "--quiet", "--resume"]) == 2
    assert "--fresh" in capsys.readouterr().err
    assert main(["sweep", str(config), "-o", str(folder), "--quiet", "--fresh"]) == 0
    assert (folder / "sweep.csv").is_file() and not (folder / LEDGER).exists()
    assert not (folder / "reference.h5.journal").exists()


# -- 15: --quiet silences dask; a foreign file at the output is not overwritten ---------------

DYING = '''
import os

import numpy as np


class Dying:
    """y = a t; the worker process dies at a > 0.9."""

    outputs = ("y",)

    def __init__(self, a=0.5):
        self.parameters = {"a": a}

    def simulate(self, params, times):
        a = np.asarray(params["a"], float)
        if a.size == 1 and a[0] > 0.9:
            os._exit(3)
        return {"y": a[:, None] * times}
'''


@pytest.fixture(scope="module")
def local_cluster_starts() -> None:
    distributed = pytest.importorskip("distributed")
    try:
        with distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
        ):
            pass
    except Exception as error:  # no sockets, no process spawning, ...
        pytest.skip(f"dask's LocalCluster cannot start here: {error}")


@pytest.mark.slow
def test_quiet_silences_dask_logging(tmp_path, local_cluster_starts) -> None:
    (tmp_path / "dying.py").write_text(DYING)
    (tmp_path / "study.yaml").write_text(
        textwrap.dedent(
            """\
            name: dying
            model: {kind: python, entry: dying.py:Dying, params: {a: 0.5}, outputs: [y]}
            time: {start: 0.0, stop: 1.0, points: 3}
            inputs:
              a: {dist: uniform, low: 0.0, high: 1.0}
            method: {kind: montecarlo, samples: 8, seed: 1}
            execution: {jobs: 1, chunk_size: 1, on_failure: regress}
            output: out.h5
            """
        )
    )
    done = pcmb_cli("run", "study.yaml", "--backend", "dask", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "distributed" not in done.stderr, done.stderr
    assert "worker process died" in done.stderr  # pcmb's own report of the node stays


def _foreign_h5(path: Path) -> bytes:
    with h5py.File(path, "w") as file:
        file["data"] = np.arange(3.0)
    return path.read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("make", [_foreign_h5, lambda p: (p.write_bytes(b"notes"), b"notes")[1]])
def test_a_foreign_file_at_the_output_is_not_overwritten(
    tmp_path, linear_study, capsys, make
) -> None:
    config = linear_study()
    out = tmp_path / "out.h5"
    before = make(out)
    assert main(["run", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "not a pcmb result" in err and "--force" in err
    assert out.read_bytes() == before
    assert not (tmp_path / "out.h5.journal").exists()
    assert main(["validate", str(config)]) == 2  # the same check, without running
    assert "not a pcmb result" in capsys.readouterr().err
    assert main(["run", str(config), "--quiet", "--force"]) == 0
    assert pcmb.load(out).status.min() == 1


def test_a_pcmb_result_at_the_output_is_rewritten_without_force(tmp_path, linear_study) -> None:
    config = linear_study()
    assert main(["run", str(config), "--quiet"]) == 0
    stamp = (tmp_path / "out.h5").stat().st_mtime_ns
    assert main(["run", str(config), "--quiet"]) == 0
    assert (tmp_path / "out.h5").stat().st_mtime_ns != stamp


def test_force_in_the_python_api(tmp_path, linear_study) -> None:
    study = Study.from_config(load_config(linear_study()))
    out = tmp_path / "api.h5"
    before = _foreign_h5(out)
    with pytest.raises(ResultFileError, match="not a pcmb result"):
        study.run(out, progress=False)
    assert out.read_bytes() == before
    assert not Path(f"{out}.journal").exists()
    study.run(out, force=True, progress=False)
    assert pcmb.load(out).status.min() == 1
