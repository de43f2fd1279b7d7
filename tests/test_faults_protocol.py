"""Faults of the model protocol: a model whose result breaks the protocol at one node only.

A per-point function that returns a scalar, an empty dict, ``None`` or a (1, T) array at one
node, after others succeeded, is a failure of that node (named with its parameters) under
the failure policy, and the journal keeps the finished nodes; only a model that breaks the
protocol at every node it tried is a model error (exit 3, nothing left behind).
"""

from __future__ import annotations

import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from cli_process import pcmb_here

import pcmb
from pcmb.result import Status

#: Order 31 on one input: 32 nodes, cut into 16 chunks of two (the default rule).
ORDER = 31
NODES = pcmb.TensorGrid([pcmb.Uniform(0.0, 1.0)], (ORDER,)).params[:, 0]
#: The model breaks the protocol above this value of ``a``: at the last node only.
CUT = float(0.5 * (NODES[-2] + NODES[-1]))

MODEL = '''
import os

import numpy as np

import pcmb

BAD = {{
    "scalar": lambda times: {{"y": float("nan")}},
    "empty": lambda times: {{}},
    "none": lambda times: None,
    "row": lambda times: {{"y": np.zeros((1, times.size))}},
}}


@pcmb.pointwise(outputs=("y",))
def model(params, times):
    """y = a t; breaks the protocol (``how``) above ``cut`` while the file ``broken`` exists,
    or everywhere with ``cut`` < 0. Every call appends its ``a`` to ``calls.log``."""
    with open({log!r}, "a") as log:
        log.write(f"{{params['a']!r}}\\n")
    if params["a"] > params["cut"] and os.path.exists({flag!r}):
        return BAD[params["how"]](times)
    return {{"y": params["a"] * times}}
'''


def _study(folder: Path, how: str, policy: str, cut: float = CUT) -> Path:
    """A study of the model above, broken (``how``) above ``cut``; returns the config."""
    log, flag = folder / "calls.log", folder / "broken"
    (folder / "protocol_model.py").write_text(MODEL.format(log=str(log), flag=str(flag)))
    flag.touch()
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: protocol
            model:
              kind: python
              entry: protocol_model.py:model
              params: {{a: 0.5, cut: {cut!r}, how: {how}}}
              outputs: [y]
            time: {{start: 0.0, stop: 1.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 0.0, high: 1.0}}
            method: {{kind: collocation, order: {ORDER}, validation: 0}}
            execution: {{jobs: 1, backend: loky, on_failure: {policy}, nominal_run: false}}
            output: {str(folder / "result.h5")!r}
            """
        )
    )
    return config


def _run(config: Path, *extra: str) -> tuple[int, str]:
    process = pcmb_here("run", str(config), "--quiet", *extra)
    return process.returncode, process.stderr


def _journaled(journal: Path) -> dict[int, int]:
    """Node index -> status of the journal's records (later records win)."""
    status: dict[int, int] = {}
    for record in sorted(journal.glob("record-*.npz")):
        with np.load(record) as data:
            status.update(zip(data["indices"].tolist(), data["status"].tolist(), strict=True))
    return status


def _calls(folder: Path) -> list[float]:
    return [float(line) for line in (folder / "calls.log").read_text().split()]


@pytest.mark.slow
@pytest.mark.parametrize("how", ["scalar", "empty", "none", "row"])
def test_a_protocol_break_at_one_node_aborts_keeping_the_finished_nodes(
    tmp_path: Path, how: str
) -> None:
    config = _study(tmp_path, how, "abort")
    code, stderr = _run(config)
    assert code == 3, stderr
    assert "model failure" in stderr and "1 of 32 node(s)" in stderr, stderr
    assert f"node {ORDER} (a={NODES[-1]:.6g})" in stderr, stderr
    journal = tmp_path / "result.h5.journal"
    status = _journaled(journal)
    assert sum(s == Status.OK for s in status.values()) == ORDER, status
    assert status[ORDER] == Status.FAILED
    assert not (tmp_path / "result.h5").exists()

    (tmp_path / "broken").unlink()  # the model is fixed (its data, not its code)
    before = len(_calls(tmp_path))
    code, stderr = _run(config, "--resume")
    assert code == 0, stderr
    assert _calls(tmp_path)[before:] == [NODES[-1]]  # only the failed node ran again
    assert not journal.exists()
    result = pcmb.load(tmp_path / "result.h5")
    np.testing.assert_allclose(result.mean("y"), 0.5 * np.linspace(0.0, 1.0, 5), atol=1e-12)


@pytest.mark.slow
def test_a_protocol_break_at_one_node_is_regressed_over(tmp_path: Path) -> None:
    code, stderr = _run(_study(tmp_path, "scalar", "regress"))
    assert code == 0, stderr
    result = pcmb.load(tmp_path / "result.h5")
    assert list(result.status).count(Status.FAILED) == 1
    assert result.status[ORDER] == Status.FAILED


@pytest.mark.slow
def test_a_protocol_break_at_every_node_is_a_model_error(tmp_path: Path) -> None:
    code, stderr = _run(_study(tmp_path, "scalar", "regress", cut=-1.0))
    assert code == 3, stderr
    assert "model error" in stderr and "returned a float for output 'y'" in stderr, stderr
    assert stderr.count("returned a float") == 1, stderr
    assert len(_calls(tmp_path)) < NODES.size  # it stopped early
    assert not (tmp_path / "result.h5").exists()
    assert not (tmp_path / "result.h5.journal").exists()


COMPLEX_MODEL = '''
import numpy as np

import pcmb


class Batch:
    """y = a t, complex (with an imaginary part) above ``cut``."""

    outputs = ("y",)

    def __init__(self, a=0.5, cut=2.0):
        self.parameters = {"a": a}
        self.cut = cut

    def simulate(self, params, times):
        a = np.asarray(params["a"], dtype=float)
        y = (a[:, None] * times).astype(complex)
        y[a > self.cut] += 1j
        return {"y": y}


@pcmb.pointwise(outputs=("y",))
def point(params, times):
    """y = a t, complex (with an imaginary part) above ``cut``."""
    y = params["a"] * times + 0j
    return {"y": y + 1j if params["a"] > params["cut"] else y}
'''


@pytest.mark.slow
@pytest.mark.parametrize("entry", ["Batch", "point"])
def test_a_complex_output_is_a_failed_node_not_its_real_part(tmp_path: Path, entry: str) -> None:
    (tmp_path / "complex_model.py").write_text(COMPLEX_MODEL)
    config = tmp_path / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: complex
            model:
              kind: python
              entry: complex_model.py:{entry}
              params: {{a: 0.5, cut: {CUT!r}}}
              outputs: [y]
            time: {{start: 0.0, stop: 1.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 0.0, high: 1.0}}
            method: {{kind: collocation, order: {ORDER}, validation: 0}}
            execution: {{jobs: 1, backend: loky, on_failure: abort, nominal_run: false}}
            output: {str(tmp_path / "result.h5")!r}
            """
        )
    )
    code, stderr = _run(config)
    assert code == 3, stderr
    assert f"node {ORDER} (a={NODES[-1]:.6g})" in stderr, stderr
    assert re.search(r"output 'y'( of the [\w -]+)? is complex \(imaginary part up to 1\)", stderr)
    assert "ComplexWarning" not in stderr, stderr
    assert not (tmp_path / "result.h5").exists()


DUPLICATE_WRITER = """
import json
import sys

with open("params.json") as handle:
    document = json.load(handle)
a, times = document["params"]["a"], document["times"]
y, other = [a * t for t in times], [-a * t for t in times]  # two outputs named y
with open(sys.argv[1], "w") as out:
    if sys.argv[1].endswith(".csv"):
        out.write("time,y,y\\n")
        out.writelines(f"{t!r},{p!r},{q!r}\\n" for t, p, q in zip(times, y, other))
    else:
        out.write(f'{{"time": {times}, "y": {y}, "y": {other}}}')
"""

#: What each output format says of an output named twice.
TWICE = {
    "out.csv": "column 'y' appears twice (columns 2 and 3) with different values",
    "out.json": "key 'y' appears more than once, with different values",
}


@pytest.mark.slow
@pytest.mark.parametrize("file", sorted(TWICE))
def test_an_output_named_twice_in_its_file_is_a_failed_run(tmp_path: Path, file: str) -> None:
    (tmp_path / "writer.py").write_text(DUPLICATE_WRITER)
    config = tmp_path / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: duplicate
            model:
              kind: command
              command: [{sys.executable}, writer.py, {file}]
              files: [writer.py]
              params: {{a: 0.5}}
              outputs: [y]
              output: {{file: {file}}}
              keep: none
            time: {{start: 0.0, stop: 1.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 0.0, high: 1.0}}
            method: {{kind: collocation, order: 1, validation: 0}}
            execution: {{jobs: 1, backend: loky, on_failure: abort, nominal_run: false}}
            output: {str(tmp_path / "result.h5")!r}
            """
        )
    )
    code, stderr = _run(config)
    assert code == 3, stderr
    assert "model failure" in stderr and "node 0 (a=" in stderr, stderr
    assert f"cannot parse {file} as {file[4:]}" in stderr and TWICE[file] in stderr, stderr
    assert not (tmp_path / "result.h5").exists()
