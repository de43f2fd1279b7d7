"""Unwritable outputs and full disks: found before anything runs when they can be; otherwise
a clear error (exit 2, no traceback) that keeps every journaled node for ``--resume``.

Full and read-only file systems are real ones: small tmpfs mounts (the tests that need them
are skipped where this process may not mount, i.e. when not root). A disk that fills up
during a run is made by filling the tmpfs at the chosen moment (before a journal record, or
before the result file is written), so the ENOSPC comes from the kernel, not a mock.
"""

from __future__ import annotations

import errno
import gc
import os
import shutil
import subprocess
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb import store
from pcmb.cli import main
from pcmb.run.executor import chunk_bounds
from pcmb.run.journal import Journal
from pcmb.run.output import check_output, estimate_size

MODEL = '''
import numpy as np


class Counted:
    """y = a t + b², z = a b; appends the batch size of every call to ``log``."""

    outputs = ("y", "z")

    def __init__(self, a=1.0, b=0.0, log=""):
        self.parameters = {"a": a, "b": b}
        self.log = log

    def simulate(self, params, times):
        a, b = np.broadcast_arrays(np.asarray(params["a"], float), np.asarray(params["b"], float))
        if self.log:
            with open(self.log, "a") as handle:
                handle.write(f"{a.size}\\n")
        return {
            "y": a[:, None] * times + b[:, None] ** 2,
            "z": np.repeat((a * b)[:, None], times.size, axis=1),
        }
'''

N_NODES = 64  # order 7 in two inputs: with the nominal run, 13 chunks of 5 runs
N_TIMES = 50
NOMINAL = 1  # every run (a resumed one too) also runs the model at the nominal parameters


def write_config(folder: Path, output: Path, points: int = N_TIMES) -> Path:
    (folder / "counted.py").write_text(MODEL)
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: counted
            model:
              kind: python
              entry: counted.py:Counted
              params: {{a: 1.0, b: 0.0, log: "{folder / "calls.log"}"}}
              outputs: [y, z]
            time: {{start: 0.0, stop: 2.0, points: {points}}}
            inputs:
              a: {{dist: uniform, low: 1.0, high: 3.0}}
              b: {{dist: normal, mean: 0.0, std: 1.0}}
            method: {{kind: collocation, order: 7, validation: 0}}  # counts runs: no held-out ones
            execution: {{jobs: 1}}
            output: {output}
            """
        )
    )
    return config


def nodes_run(folder: Path) -> int:
    log = folder / "calls.log"
    return sum(int(line) for line in log.read_text().split()) if log.exists() else 0


def _mount(folder: Path, options: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root or CAP_SYS_ADMIN): {done.stderr}")


@pytest.fixture
def tmpfs(tmp_path: Path) -> Iterator[callable]:
    """``tmpfs(size, ro=False)`` mounts a small tmpfs at a new folder and returns it;
    every mount is undone at the end (lazily if a file is still open in it)."""
    mounted: list[Path] = []

    def mount(size: str, ro: bool = False) -> Path:
        folder = tmp_path / f"mnt{len(mounted)}"
        _mount(folder, f"size={size},mode=0755" + (",ro" if ro else ""))
        mounted.append(folder)
        return folder

    try:
        yield mount
    finally:
        gc.collect()  # close the journal locks of runs that ended in an error
        for folder in mounted:
            if subprocess.run(["umount", str(folder)], capture_output=True).returncode:
                subprocess.run(["umount", "-l", str(folder)], capture_output=True)


@pytest.fixture
def small_disk(tmp_path: Path, tmpfs) -> tuple[Path, Path]:
    """A 1 MB file system, and the config of a study writing its ``out.h5`` there."""
    folder = tmpfs("1m")
    return folder, write_config(tmp_path, folder / "out.h5")


def fill(folder: Path) -> Path:
    """Fill the file system of ``folder`` to the last byte; returns the filler file."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError as error:
        assert error.errno == errno.ENOSPC
    finally:
        os.close(fd)
    return filler


def assert_clean_failure(err: str, *words: str) -> None:
    assert "Traceback" not in err and "unexpected error" not in err, err
    assert err.startswith("pcmb: file: "), err
    for word in words:
        assert word in err, err


# --------------------------------------------------------------------------- before any run


def test_an_output_that_is_a_directory_is_refused_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "taken.h5"
    out.mkdir()
    config = write_config(tmp_path, out)
    assert main(["validate", str(config)]) == 2
    assert_clean_failure(capsys.readouterr().err, str(out), "is a directory")
    assert main(["run", str(config), "--quiet"]) == 2
    assert_clean_failure(capsys.readouterr().err, str(out), "is a directory")
    assert nodes_run(tmp_path) == 0 and not Path(f"{out}.journal").exists()


@pytest.mark.slow
def test_an_output_below_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    out = tmp_path / "file" / "sub" / "out.h5"
    config = write_config(tmp_path, out)
    for command in ("validate", "run"):
        assert main([command, str(config)]) == 2
        assert_clean_failure(capsys.readouterr().err, str(out), "ENOTDIR")
    assert nodes_run(tmp_path) == 0


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes through chmod 0o500")
def test_an_unwritable_folder_is_refused_before_anything_runs(tmp_path, capsys):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        out = folder / "out.h5"
        config = write_config(tmp_path, out)
        assert main(["validate", str(config)]) == 2
        assert_clean_failure(capsys.readouterr().err, str(out), "not writable")
        assert main(["run", str(config), "--quiet"]) == 2
        assert_clean_failure(capsys.readouterr().err, str(out), "EACCES")
        assert nodes_run(tmp_path) == 0 and not Path(f"{out}.journal").exists()
    finally:
        folder.chmod(0o700)


@pytest.mark.slow
def test_a_read_only_file_system_is_refused_before_anything_runs(tmp_path, tmpfs, capsys):
    out = tmpfs("64k", ro=True) / "results" / "out.h5"
    config = write_config(tmp_path, out)
    assert main(["validate", str(config)]) == 2
    assert_clean_failure(capsys.readouterr().err, str(out), "not writable")
    assert main(["run", str(config), "--quiet"]) == 2
    assert_clean_failure(capsys.readouterr().err, str(out), "EROFS")
    assert nodes_run(tmp_path) == 0


@pytest.mark.slow
def test_too_little_space_is_refused_before_anything_runs(tmp_path, tmpfs, capsys):
    out = tmpfs("64k") / "out.h5"
    config = write_config(tmp_path, out)
    assert main(["validate", str(config)]) == 2
    err = capsys.readouterr().err
    assert_clean_failure(err, str(out), "not enough space", "ENOSPC", "free")
    assert main(["run", str(config), "--quiet"]) == 2
    assert_clean_failure(capsys.readouterr().err, str(out), "not enough space")
    assert nodes_run(tmp_path) == 0 and not Path(f"{out}.journal").exists()


@pytest.mark.slow
def test_validate_prints_the_estimated_size(tmp_path, capsys):
    config = write_config(tmp_path, tmp_path / "out.h5")
    assert main(["validate", str(config)]) == 0
    size = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("size"))
    assert "result file" in size and "journal" in size and "free there" in size
    assert main(["run", str(config), "--quiet"]) == 0
    # The estimate is an upper bound, and not a wild one.
    estimate = estimate_size(N_NODES, N_TIMES, 2, 2)
    written = (tmp_path / "out.h5").stat().st_size
    assert written < estimate.result < 4 * written


def test_check_output_creates_the_folder_only_when_asked(tmp_path):
    out = tmp_path / "a" / "b" / "out.h5"
    assert check_output(out) > 0
    assert not (tmp_path / "a").exists()
    check_output(out, create=True)
    assert (tmp_path / "a" / "b").is_dir() and list((tmp_path / "a" / "b").iterdir()) == []


# --------------------------------------------------------------------------- during a run


@pytest.mark.slow
def test_disk_full_before_the_result_file_keeps_the_journal_for_resume(
    tmp_path, small_disk, monkeypatch, capsys
):
    folder, config = small_disk
    out = folder / "out.h5"
    image = store._image
    filler: list[Path] = []

    def full_then_image(*args, **kwargs):
        filler.append(fill(folder))  # another program fills the disk as the runs end
        return image(*args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(store, "_image", full_then_image)
        assert main(["run", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert_clean_failure(err, f"result file {out}", "ENOSPC", "--resume", f"{out}.journal")
    assert nodes_run(tmp_path) == N_NODES + NOMINAL
    assert not out.exists() and not list(folder.glob(".out.h5.*"))  # no partial file
    journal = Path(f"{out}.journal")
    assert len(list(journal.glob("record-*.npz"))) == len(
        chunk_bounds(N_NODES + NOMINAL)
    )  # the nominal run in the last

    # The user frees space and resumes: the file is written, no node runs again.
    filler[0].unlink()
    assert main(["run", str(config), "--quiet", "--resume"]) == 0
    assert nodes_run(tmp_path) == N_NODES + 2 * NOMINAL and not journal.exists()
    result = pcmb.load(out)
    np.testing.assert_allclose(result.mean("y"), 2 * result.times + 1, atol=1e-12)


@pytest.mark.slow
def test_a_journal_moved_to_another_disk_resumes_there(tmp_path, small_disk, monkeypatch, capsys):
    folder, config = small_disk
    image = store._image
    with monkeypatch.context() as patch:
        patch.setattr(store, "_image", lambda *a, **k: (fill(folder), image(*a, **k))[1])
        assert main(["run", str(config), "--quiet"]) == 2
    capsys.readouterr()
    gc.collect()
    # No space can be freed there: move the finished work beside another output.
    other = tmp_path / "elsewhere" / "other.h5"
    other.parent.mkdir()
    shutil.move(f"{folder / 'out.h5'}.journal", f"{other}.journal")
    assert main(["run", str(config), "-o", str(other), "--quiet", "--resume"]) == 0
    assert nodes_run(tmp_path) == N_NODES + 2 * NOMINAL and pcmb.load(other).n_nodes == N_NODES


@pytest.mark.slow
def test_disk_full_during_the_journal_keeps_the_finished_records(
    tmp_path, small_disk, monkeypatch, capsys
):
    folder, config = small_disk
    out = folder / "out.h5"
    record = Journal.record
    calls = []

    def filling_record(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 6:  # five chunks are journaled, then the disk is full
            fill(folder)
        return record(self, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(Journal, "record", filling_record)
        assert main(["run", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert_clean_failure(err, "journal record", str(folder), "ENOSPC", "--resume")
    journal = Path(f"{out}.journal")
    assert len(list(journal.glob("record-*.npz"))) == 5
    assert not list(journal.glob(".tmp-*"))  # the partial record is gone
    first = nodes_run(tmp_path)
    # The nodes and the nominal run are one campaign: 65 runs in chunks of 5.
    chunks = chunk_bounds(N_NODES + NOMINAL)
    journaled = chunks[4][1]
    assert first >= chunks[5][1]  # the five journaled chunks and the sixth, whose record failed

    # The user makes room (here: the file system grows) and resumes: only the nodes that
    # were not journaled run again.
    subprocess.run(["mount", "-o", "remount,size=4m", str(folder)], check=True)
    assert main(["run", str(config), "--quiet", "--resume"]) == 0
    assert nodes_run(tmp_path) - first == N_NODES - journaled + NOMINAL
    fresh = tmp_path / "fresh.h5"
    assert main(["run", str(config), "-o", str(fresh), "--quiet"]) == 0
    for name in ("y", "z"):
        np.testing.assert_array_equal(pcmb.load(out).values[name], pcmb.load(fresh).values[name])


def test_write_result_names_the_problem_and_leaves_no_partial_file(tmp_path, tmpfs):
    folder = tmpfs("64k")
    config = write_config(tmp_path, tmp_path / "out.h5")
    assert main(["run", str(config), "--quiet"]) == 0
    result = pcmb.load(tmp_path / "out.h5")
    with pytest.raises(pcmb.ResultFileError, match=r"result file .*ENOSPC.*free some space"):
        store.write_result(folder / "big.h5", result, provenance={})
    assert list(folder.iterdir()) == []


def test_an_output_that_became_a_directory_during_the_run_is_named(tmp_path):
    config = write_config(tmp_path, tmp_path / "out.h5")
    assert main(["run", str(config), "--quiet"]) == 0
    result = pcmb.load(tmp_path / "out.h5")
    (tmp_path / "now_a_folder.h5").mkdir()
    with pytest.raises(pcmb.ResultFileError, match=r"now_a_folder.h5: is a directory \(EISDIR\)"):
        store.write_result(tmp_path / "now_a_folder.h5", result, provenance={})
    assert not list(tmp_path.glob(".now_a_folder.h5.*"))
