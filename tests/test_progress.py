"""Progress where long work happens: a line per 5 % of the nodes in a log, the phases
between the runs with their seconds, and the runs a resume reused."""

from __future__ import annotations

import io
import re

import pytest
from cli_process import pcmb_here
from test_resume import PYTHON_CONFIG, PYTHON_MODEL, run_and_kill

from pcmb.run.progress import Progress, phase


def test_a_log_gets_a_line_per_5_percent_of_the_total():
    stream = io.StringIO()
    progress = Progress(100, 0, stream)
    for _ in range(100):
        progress.advance(1)
    progress.close()
    lines = stream.getvalue().splitlines()
    assert [line.split()[1] for line in lines] == [f"{k}/100" for k in range(5, 101, 5)]
    assert "\r" not in stream.getvalue()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_one_line_rewritten_in_place():
    stream = _Terminal()
    progress = Progress(4, 0, stream)
    for _ in range(4):
        progress.advance(1)
    progress.close()
    text = stream.getvalue()
    assert text.startswith("\rpcmb: ") and text.count("\n") == 1
    assert text.rstrip().endswith("ETA 0:00:00") and "4/4 nodes (100%)" in text


def test_work_found_done_is_said_first():
    stream = io.StringIO()
    progress = Progress(100, 30, stream)
    for _ in range(70):
        progress.advance(1)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "pcmb: 30 of 100 nodes reused from the journal"
    assert [line.split()[1] for line in lines[1:]] == [f"{k}/100" for k in range(35, 101, 5)]


def test_a_phase_says_what_and_how_long():
    stream = io.StringIO()
    with phase("fitting 2 outputs", stream):
        pass
    assert re.fullmatch(r"pcmb: fitting 2 outputs \.\.\. \d+\.\d s\n", stream.getvalue())
    with phase("silent", None):
        pass


@pytest.mark.slow
def test_a_run_in_a_log_shows_its_runs_and_phases_and_a_resume_its_reused_runs(tmp_path):
    python_study = tmp_path
    (python_study / "model.py").write_text(PYTHON_MODEL)
    (python_study / "study.yaml").write_text(PYTHON_CONFIG)

    def pcmb_run(*args: str) -> str:
        done = pcmb_here("run", "study.yaml", *args, cwd=python_study)  # stderr: a log
        assert done.returncode == 0, done.stderr
        return done.stderr

    said = pcmb_run("-o", "fresh.h5")
    assert "\r" not in said  # not a terminal: lines, not a line redrawn in place
    for expected in (
        "16/16 nodes (100%)",
        "fitting 1 output (chaos order 3) ...",
        "diagnostics ...",
        "writing fresh.h5 ...",
    ):
        assert expected in said, said
    run_and_kill(python_study, after=5)
    reused = re.search(r"pcmb: (\d+) of 16 nodes reused from the journal", pcmb_run("--resume"))
    assert reused is not None and int(reused.group(1)) >= 5
