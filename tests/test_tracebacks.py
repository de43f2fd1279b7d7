"""A failed model run shows the model's own traceback: file, line and code of each frame.

A python model whose helper module (imported by the entry) raises ``KeyError: 'omega'`` at
six nodes is reported once, with the helper's file and line and the frames of the model's
code only, the other five nodes listed on one line; the traceback is kept in the journal and
in the result file (``on_failure: regress``), where ``pcmb inspect`` shows it.
``--backend inprocess`` shows the whole traceback, and ``--pdb`` opens the debugger at the
first exception. A command's failure keeps the tail of its stderr and has no traceback.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_process import pcmb_cli, pcmb_here

import pcmb
from pcmb.config.schema import ExecutionSpec
from pcmb.result import NodeFailure
from pcmb.run.executor import run_nodes

PCMB = Path(pcmb.__file__).resolve().parent

HELPERS = """\
import numpy as np


def rate(k, limit):
    table = {"alpha": 1.0}
    if k > limit:
        return table["omega"] * k
    return k


def response(k, times, limit):
    return np.sin(rate(k, limit) * times)
"""
#: The line of ``rate`` that raises, and its text.
LINE = 7
CODE = 'return table["omega"] * k'

MODEL = """\
import numpy as np
from helpers import response


class Model:
    outputs = ("y",)

    def __init__(self, k=1.0, limit=0.0):
        self.limit = limit

    def simulate(self, params, times):
        k = np.asarray(params["k"])
        return {"y": np.array([response(v, times, self.limit) for v in k])}
"""


def _study(folder: Path, *, limit: float, order: int, on_failure: str, chunk: str = "") -> Path:
    """A one-input study of ``Model`` (entry model.py, helper helpers.py in ``folder``): the
    nodes with k > ``limit`` fail in ``helpers.rate``."""
    (folder / "helpers.py").write_text(HELPERS)
    (folder / "model.py").write_text(MODEL)
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: tracebacks
            model:
              kind: python
              entry: model.py:Model
              params: {{k: 1.0, limit: {limit}}}
              outputs: [y]
            time: {{start: 0.0, stop: 1.0, points: 5}}
            inputs:
              k: {{dist: uniform, low: 0.5, high: 1.5}}
            method: {{kind: collocation, order: {order}, validation: 0}}
            execution: {{jobs: 1, on_failure: {on_failure}{chunk}}}
            output: {str(folder / "out.h5")!r}
            """
        )
    )
    return config


def _node(order: int, index: int) -> str:
    """How a failure names node ``index`` of ``_study``'s collocation of ``order``: the
    Gauss–Legendre point on k ~ U[0.5, 1.5], ``node 3 (k=...)``."""
    points, _ = np.polynomial.legendre.leggauss(order + 1)
    return NodeFailure(index, {"k": 1.0 + 0.5 * points[index]}, "").node


def _frame(folder: Path) -> str:
    return f'File "{folder / "helpers.py"}", line {LINE}, in rate'


@pytest.mark.slow
def test_six_nodes_failing_in_a_helper_show_one_traceback_of_the_models_frames(tmp_path):
    config = _study(tmp_path, limit=0.0, order=5, on_failure="abort", chunk=", chunk_size: 6")
    done = pcmb_here("run", str(config), "--quiet")
    stderr = done.stderr
    assert done.returncode == 3, stderr
    assert "the model failed at 6 of 6 node(s)" in stderr, stderr
    assert f"{_node(5, 0)}: KeyError: 'omega' at helpers.py:{LINE} in rate()" in stderr
    # One traceback, of the model's frames only: the entry's, then the helper's two.
    assert stderr.count("Traceback (most recent call last):") == 1, stderr
    assert stderr.count(_frame(tmp_path)) == 1 and stderr.count(CODE) == 1, stderr
    assert f'File "{tmp_path / "model.py"}", line 13, in simulate' in stderr, stderr
    assert f'File "{tmp_path / "helpers.py"}", line 12, in response' in stderr, stderr
    assert str(PCMB) not in stderr, stderr
    more = f"and 5 more nodes with the same error: {_node(5, 1)}, {_node(5, 2)}, "
    assert more in stderr, stderr
    assert stderr.count("KeyError") == 2, stderr  # the first node's line and its traceback
    # The journal kept for --resume holds the traceback with the failure.
    records = sorted((tmp_path / "out.h5.journal").glob("record-*.npz"))
    kept = [json.loads(text) for path in records for text in np.load(path)["tracebacks"]]
    assert sum(_frame(tmp_path) in found["text"] for found in kept) == 6, kept


@pytest.mark.slow
def test_regress_stores_the_traceback_in_the_file_and_inspect_shows_it(tmp_path):
    config = _study(tmp_path, limit=1.35, order=7, on_failure="regress")
    done = pcmb_here("run", str(config), "--quiet")
    assert done.returncode == 0, done.stderr
    where = f"KeyError: 'omega' at helpers.py:{LINE} in rate()"
    assert where in done.stderr and _frame(tmp_path) in done.stderr, done.stderr
    assert done.stderr.count(CODE) == 1, done.stderr
    assert f"and 1 more node with the same error: {_node(7, 7)}" in done.stderr

    result = pcmb.load(tmp_path / "out.h5")
    assert [f.index for f in result.failures] == [6, 7]
    for failure in result.failures:
        assert failure.traceback is not None and _frame(tmp_path) in failure.traceback.text
        assert failure.traceback.text.rstrip().endswith("KeyError: 'omega'")
        assert where in str(failure)
    inspected = pcmb_here("inspect", str(tmp_path / "out.h5"))
    assert inspected.returncode == 0, inspected.stderr
    assert f"failed   {_node(7, 6)}: {where}" in inspected.stdout, inspected.stdout
    assert _frame(tmp_path) in inspected.stdout and CODE in inspected.stdout
    assert "failed   and 1 more node with the same error: node 7" in inspected.stdout


@pytest.mark.slow
def test_a_file_without_tracebacks_still_loads(tmp_path):
    config = _study(tmp_path, limit=1.35, order=7, on_failure="regress")
    assert pcmb_here("run", str(config), "--quiet").returncode == 0
    with h5py.File(tmp_path / "out.h5", "a") as file:  # as a file of before tracebacks
        del file.attrs["failure_tracebacks"]
    result = pcmb.load(tmp_path / "out.h5")
    assert [(f.index, f.traceback) for f in result.failures] == [(6, None), (7, None)]
    assert str(result.failures[0]) == f"{_node(7, 6)}: KeyError: 'omega'"


@pytest.mark.slow  # a pcmb process of its own
def test_inprocess_shows_the_whole_traceback(tmp_path):
    config = _study(tmp_path, limit=0.0, order=5, on_failure="abort", chunk=", chunk_size: 6")
    done = pcmb_cli("run", str(config), "--quiet", "--backend", "inprocess")
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("Traceback (most recent call last):") == 1, done.stderr
    assert _frame(tmp_path) in done.stderr
    assert f'File "{PCMB / "run" / "worker.py"}"' in done.stderr, done.stderr


@pytest.mark.slow  # a pcmb process of its own
def test_pdb_opens_the_debugger_at_the_first_model_exception(tmp_path):
    config = _study(tmp_path, limit=0.0, order=5, on_failure="abort", chunk=", chunk_size: 6")
    done = pcmb_cli("run", str(config), "--pdb", stdin="p table\nq\n")
    assert done.returncode == 3, done.stderr
    # Once, at the helper's line, with its locals: the other five failures run on.
    assert done.stdout.count(f"> {tmp_path / 'helpers.py'}({LINE})rate()") == 1, done.stdout
    assert "{'alpha': 1.0}" in done.stdout, done.stdout
    assert "the model failed at 6 of 6 node(s)" in done.stderr, done.stderr


def test_pdb_refuses_a_backend_with_workers(tmp_path):
    config = _study(tmp_path, limit=0.0, order=1, on_failure="abort")
    done = pcmb_here("run", str(config), "--pdb", "--backend", "loky")
    assert done.returncode == 2, done.stderr
    assert "--pdb" in done.stderr and "inprocess" in done.stderr, done.stderr
    assert not (tmp_path / "out.h5.journal").exists()


@pytest.mark.parametrize("wrapped", [False, True], ids=["class", "pointwise"])
def test_run_nodes_keeps_the_models_frames_only(tmp_path, monkeypatch, wrapped):
    # Reached through functools.singledispatchmethod (standard-library frames that merely
    # call into the model: dropped) and calling into the standard library (copy: kept), or as
    # a marked function, whose error pcmb's adapter wraps in a ModelError of its own.
    (tmp_path / "dispatched.py").write_text(
        textwrap.dedent(
            """\
            import copy
            import functools

            import pcmb


            class Hook:
                def __deepcopy__(self, memo):
                    raise ValueError("no copy")


            class Model:
                outputs = ("y",)

                @functools.singledispatchmethod
                def simulate(self, params, times):
                    return copy.deepcopy(Hook())


            @pcmb.pointwise(outputs=("y",))
            def point(params, times):
                return copy.deepcopy(Hook())
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    import dispatched

    model = (
        (lambda: pcmb.adapters.python.FunctionModel(dispatched.point, {"a": 1.0}))
        if wrapped
        else dispatched.Model
    )
    found = run_nodes(
        model, {"a": [1.0, 2.0]}, np.linspace(0, 1, 3), ["y"], execution=ExecutionSpec(jobs=1)
    )
    first = found.failures[0]
    assert first.traceback is not None
    text = first.traceback.text
    assert str(first).endswith("ValueError: no copy at dispatched.py:9 in __deepcopy__()")
    assert (first.traceback.error, first.traceback.line) == ("ValueError", 9)
    assert str(PCMB) not in text and "functools.py" not in text, text
    assert "copy.py" in text and text.index("dispatched.py") < text.index("copy.py"), text
    assert text.rstrip().endswith("ValueError: no copy"), text
    assert "ModelError" not in text, text
    assert found.failures[1].traceback == first.traceback


@pytest.mark.slow
def test_a_failed_command_keeps_its_stderr_tail_and_has_no_traceback(tmp_path):
    program = tmp_path / "simulator.py"
    program.write_text(
        "import sys\nprint('solver diverged at step 12', file=sys.stderr)\nsys.exit(3)\n"
    )
    config = tmp_path / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: command
            model:
              kind: command
              command: [{sys.executable!r}, simulator.py]
              files: [simulator.py]
              params: {{k: 1.0}}
              outputs: [y]
              output: {{file: out.csv}}
              run_dir: {str(tmp_path / "runs")!r}
              keep: none
            time: {{start: 0.0, stop: 1.0, points: 3}}
            inputs:
              k: {{dist: uniform, low: 0.5, high: 1.5}}
            method: {{kind: collocation, order: 1, validation: 0}}
            execution: {{jobs: 1, on_failure: abort, chunk_size: 2}}
            output: {str(tmp_path / "out.h5")!r}
            """
        )
    )
    done = pcmb_here("run", str(config), "--quiet")
    assert done.returncode == 3, done.stderr
    assert "last lines of stderr.txt: 'solver diverged at step 12'" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    # Nor does --pdb open a debugger in pcmb's own code for it.
    debugged = pcmb_cli("run", str(config), "--fresh", "--pdb", stdin="q\n")
    assert debugged.returncode == 3, debugged.stderr
    assert "(Pdb)" not in debugged.stdout and "Traceback" not in debugged.stderr


def test_a_worker_loads_no_debugger():
    probe = (
        "import sys\n"
        "from pcmb.run.backends import _warm_up\n"
        "_warm_up()\n"
        "print(sorted({'pdb', 'bdb', 'cmd'} & set(sys.modules)))\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
