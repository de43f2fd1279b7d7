"""Tests of pcmb.run.journal: round trip, superseding records, refusals, atomicity under kills."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pcmb.errors import ResultFileError
from pcmb.result import Status
from pcmb.run import journal as journal_module
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


def test_a_journal_of_another_config_is_refused(tmp_path: Path) -> None:
    make(tmp_path / "j", fingerprint="abc")
    with pytest.raises(ResultFileError, match="was written for a different config; delete it"):
        make(tmp_path / "j", fingerprint="xyz")
    with pytest.raises(ResultFileError, match=r"n_nodes: 10 != 11.*drop --resume"):
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
