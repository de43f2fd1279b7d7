"""``pcmb sweep``: settings, errors against the reference, files, chart, report, resume."""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.cli import main
from pcmb.config.schema import load_config
from pcmb.designs import method_section
from pcmb.sweep.plan import default_sweep, plan_sweep
from pcmb.sweep.runner import LEDGER
from pcmb.sweep.table import COLUMNS, read_sweep

CONFIGS = sorted((Path(__file__).parent.parent / "configs").glob("*.yaml"))

GROWTH_MODEL = '''
import os
import time

import numpy as np


class Growth:
    """y = exp(a t) + b: E y = (e^t - 1)/t + E b, closed form for a ~ U[0, 1]. A process
    with $GROWTH_DELAY set sleeps that many seconds a run (the config is the same without)."""

    outputs = ("y",)

    def __init__(self, a=0.5, b=0.0):
        self.parameters = {"a": a, "b": b}

    def simulate(self, params, times):
        a = np.asarray(params["a"], float)
        b = np.broadcast_to(np.asarray(params["b"], float), a.shape)
        time.sleep(float(os.environ.get("GROWTH_DELAY", 0.0)) * a.size)
        return {"y": np.exp(a[:, None] * times) + b[:, None]}
'''


def _study(folder: Path, sweep: str, *, points: int = 21) -> Path:
    (folder / "growth.py").write_text(GROWTH_MODEL)
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: growth
            model:
              kind: python
              entry: growth.py:Growth
              params: {{a: 0.5, b: 0.0}}
            time: {{start: 0.0, stop: 2.0, points: {points}}}
            inputs:
              a: {{dist: uniform, low: 0.0, high: 1.0}}
              b: {{dist: uniform, low: -0.1, high: 0.1}}
            method: {{kind: collocation, order: 3}}
            execution: {{jobs: 1}}
            output: out.h5
            """
        )
        + textwrap.dedent(sweep)
    )
    return config


SWEEP = """\
sweep:
  methods:
    - {kind: collocation, order: [1, 2, 3, 4]}
    - {kind: montecarlo, samples: [40, 160], seed: 3}
  reference: {kind: collocation, order: 12}
  replicates: 2
"""


def _exact(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of exp(a t) + b, a ~ U[0, 1], b ~ U[-0.1, 0.1]."""
    t = np.where(times == 0, 1.0, times)
    first = np.where(times == 0, 1.0, np.expm1(t) / t)
    second = np.where(times == 0, 1.0, np.expm1(2 * t) / (2 * t))
    return first, np.sqrt(second - first**2 + 0.2**2 / 12)


def _rows(folder: Path) -> list[dict[str, str]]:
    with open(folder / "sweep.csv", newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def swept(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep")
    config = _study(folder, SWEEP)
    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        assert main(["sweep", str(config), "-o", str(folder / "out"), "--quiet"]) == 0
    # 4 collocation orders + 2 Monte Carlo sizes (x 2 replicates).
    assert said.getvalue().rstrip().endswith("(6 settings, 8 studies with replicates)")
    return folder / "out"


@pytest.mark.slow
def test_the_csv_errors_are_those_computed_from_the_result_files(swept):
    rows = _rows(swept)
    assert list(rows[0]) == list(COLUMNS)
    reference = pcmb.load(swept / "reference.h5")
    mean, std = _exact(reference.times)  # the reference is trusted: order 12 is exact here
    np.testing.assert_allclose(reference.mean("y"), mean, rtol=1e-12)
    np.testing.assert_allclose(reference.std("y"), std, rtol=1e-10)
    # 4 collocation orders + 2 Monte Carlo sizes x 2 replicates, one output.
    assert len(rows) == 8
    for row in rows:
        result = pcmb.load(swept / row["file"])
        scale = np.max(reference.std("y"))
        err_mean = np.max(np.abs(result.mean("y") - reference.mean("y"))) / scale
        err_std = np.max(np.abs(result.std("y") - reference.std("y"))) / scale
        rms = np.sqrt(np.mean((result.std("y") - reference.std("y")) ** 2)) / scale
        np.testing.assert_allclose(float(row["err_mean"]), err_mean, rtol=1e-5, atol=1e-300)
        np.testing.assert_allclose(float(row["err_std"]), err_std, rtol=1e-5, atol=1e-300)
        np.testing.assert_allclose(float(row["err_std_rms"]), rms, rtol=1e-5, atol=1e-300)
        assert int(row["runs"]) == result.n_nodes
        assert float(row["seconds"]) >= float(row["model_seconds"]) > 0
    settings = [(r["method"], r["setting"], r["replicate"]) for r in rows]
    assert settings[:4] == [("collocation", f"order={p}", "0") for p in (1, 2, 3, 4)]
    assert ("montecarlo", "samples=160", "1") in settings


def test_collocation_converges_and_monte_carlo_sits_at_its_standard_error(swept):
    rows = _rows(swept)
    chaos = [float(r["err_std"]) for r in rows if r["method"] == "collocation"]
    # Gauss-Legendre on exp(a t), t <= 2: each added point gains a factor
    # (t/2)^2 / ((2n+1)(2n+2)) <= 1/12 in the error; allow a factor 5 for the constant.
    for coarse, fine in itertools.pairwise(chaos):
        assert fine < coarse / 5
    reference = pcmb.load(swept / "reference.h5")
    floor = read_sweep(swept / "sweep.h5").floors["y"]
    assert floor == (0.0, 0.0)  # a quadrature reference has no sampling noise
    for row in rows:
        if row["method"] != "montecarlo":
            continue
        n = int(row["runs"])
        # max over 21 times of |error| of a mean of n runs: well within 5 standard errors.
        bound = 5 * np.max(reference.std("y")) / np.sqrt(n) / np.max(reference.std("y"))
        assert 0 < float(row["err_mean"]) < bound


def test_the_h5_table_holds_the_csv_rows_and_the_per_time_curves(swept):
    table = read_sweep(swept / "sweep.h5")
    rows = _rows(swept)
    assert [r.file for r in table.rows] == [r["file"] for r in rows]
    assert table.mean_curves.shape == (len(rows), 21)
    for row, curve in zip(table.rows, table.std_curves, strict=True):
        assert np.max(curve) == pytest.approx(row.err_std, rel=1e-12)
    assert (swept / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_of_a_sweep_draws_the_chart_and_the_table(swept, capsys):
    assert main(["report", str(swept / "sweep.h5"), "-o", str(swept / "report")]) == 0
    page = (swept / "report" / "index.html").read_text()
    assert '<img src="sweep.png"' in page and "samples=160" in page
    assert (swept / "report" / "sweep.png").stat().st_size > 10_000


@pytest.mark.slow
def test_a_reference_file_replaces_sweep_reference(tmp_path, swept):
    config = _study(tmp_path, SWEEP.replace("  reference: {kind: collocation, order: 12}\n", ""))
    out = tmp_path / "out"
    reference = swept / "reference.h5"
    assert main(["sweep", str(config), "-o", str(out), "--reference", str(reference)]) == 0
    assert not (out / "reference.h5").exists()
    mine, theirs = _rows(out), _rows(swept)
    for a, b in zip(mine, theirs, strict=True):
        assert (a["setting"], a["err_mean"], a["err_std"]) == (
            b["setting"],
            b["err_mean"],
            b["err_std"],
        )


def test_without_any_reference_nothing_runs(tmp_path, capsys):
    config = _study(tmp_path, SWEEP.replace("  reference: {kind: collocation, order: 12}\n", ""))
    assert main(["sweep", str(config), "-o", str(tmp_path / "out")]) == 2
    assert "sweep.reference" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_reference_on_another_grid_is_refused(tmp_path, swept, capsys):
    config = _study(tmp_path, SWEEP, points=11)
    code = main(
        [
            "sweep",
            str(config),
            "-o",
            str(tmp_path / "o"),
            "--reference",
            str(swept / "reference.h5"),
        ]
    )
    assert code == 2
    assert "another time grid" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sweep", "key", "words"),
    [
        (
            "sweep:\n  methods: [{kind: collocation, order: [1, 2], level: [1, 2]}]\n",
            "sweep.methods[0]",
            "found order, level",
        ),
        (
            "sweep:\n  methods: [{kind: collocation, order: [1, -2]}]\n",
            "sweep.methods[0].order[1]",
            "",
        ),
        ("sweep:\n  methods: [{kind: montecarlo, samples: [10, 0]}]\n", "samples[1]", ""),
        ("sweep:\n  methods: [{kind: nonsense, order: [1]}]\n", "sweep.methods[0].kind", ""),
        (
            "sweep:\n  methods: [{kind: collocation, order: [1]}]\n  outputs: [q]\n",
            "sweep.outputs[0]",
            "'q' is not an output",
        ),
        (
            "sweep:\n  methods: [{kind: collocation, order: [1]}]\n  reference: {kind: x}\n",
            "sweep.reference.kind",
            "",
        ),
    ],
)
def test_bad_sweeps_name_their_key_before_anything_runs(tmp_path, capsys, sweep, key, words):
    config = _study(tmp_path, sweep)
    assert main(["sweep", str(config), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{key}:" in err and words in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
    assert main(["validate", str(config)]) == 2  # the same check, without running


def _sweep_process(folder: Path) -> subprocess.Popen[bytes]:
    """``pcmb sweep`` of ``folder/study.yaml`` in a child whose model runs take 10 ms each."""
    return subprocess.Popen(
        [sys.executable, "-m", "pcmb.cli", "sweep", "study.yaml", "-o", "out", "--quiet"],
        cwd=folder,
        env={**os.environ, "GROWTH_DELAY": "0.01"},
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def _finished(folder: Path) -> dict[str, dict]:
    ledger = folder / "out" / LEDGER
    with contextlib.suppress(OSError, ValueError):
        return json.loads(ledger.read_text())["settings"]
    return {}


@pytest.mark.slow
def test_a_sweep_killed_midway_resumes_where_it_stopped(tmp_path):
    slow = """\
    sweep:
      methods:
        - {kind: collocation, order: [1, 2, 3]}
        - {kind: montecarlo, samples: [400], seed: 1}
      reference: {kind: collocation, order: 6}
    """
    config = _study(tmp_path, slow)
    process = _sweep_process(tmp_path)  # slow: killed within the 4 s of Monte Carlo runs
    try:
        deadline = time.monotonic() + 90
        while len(_finished(tmp_path)) < 3:  # the reference and two orders
            assert process.poll() is None, process.stderr.read().decode()
            assert time.monotonic() < deadline
            time.sleep(0.02)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        process.stderr.close()
    done = _finished(tmp_path)
    assert not (tmp_path / "out" / "sweep.csv").exists()
    stamps = {stem: (tmp_path / "out" / f"{stem}.h5").stat().st_mtime_ns for stem in done}
    assert main(["sweep", str(config), "-o", str(tmp_path / "out"), "--quiet"]) == 2  # no --resume
    assert main(["sweep", str(config), "-o", str(tmp_path / "out"), "--resume", "--quiet"]) == 0
    for stem, stamp in stamps.items():  # finished settings were read back, not run again
        assert (tmp_path / "out" / f"{stem}.h5").stat().st_mtime_ns == stamp
    assert not (tmp_path / "out" / LEDGER).exists()
    resumed = _rows(tmp_path / "out")
    assert main(["sweep", str(config), "-o", str(tmp_path / "clean"), "--quiet"]) == 0
    clean = _rows(tmp_path / "clean")
    assert [(r["setting"], r["err_mean"], r["err_std"]) for r in resumed] == [
        (r["setting"], r["err_mean"], r["err_std"]) for r in clean
    ]


def _runs(config, spec) -> int:
    """Runs of a method block: its design's, or its budget when it runs in rounds."""
    design = pcmb.Study.from_config(config.model_copy(update={"method": spec})).design
    return getattr(design, "budget", design.runs)


@pytest.mark.slow
@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_every_config_has_a_sweep_of_rising_cost_and_a_finer_reference(path, request):
    text = path.read_text(encoding="utf-8")
    if "ngspice" in text and shutil.which("ngspice") is None:
        pytest.skip("ngspice is not on PATH (apt-get install ngspice, or conda-forge's ngspice)")
    if "../models/fmu/build" in text:  # the FMU is built at test time
        text = text.replace("../models/fmu/build", str(request.getfixturevalue("fmu_dir")))
    config = load_config(path, text=text)
    plan = plan_sweep(config)
    assert plan.settings and plan.reference is not None
    own = [s for s in plan.settings if s.entry == 0]
    runs = [_runs(config, s.spec) for s in own]
    assert runs == sorted(runs) and len(set(runs)) == len(runs)
    assert _runs(config, plan.reference.spec) > runs[-1]


def test_inspect_of_a_sweep_gives_the_cheapest_setting_reaching_each_accuracy(swept, capsys):
    assert main(["inspect", str(swept / "sweep.h5")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("coll"))
    chaos = [r for r in _rows(swept) if r["method"] == "collocation"]
    cells = []
    for target in (1e-2, 1e-4):
        runs = min(int(r["runs"]) for r in chaos if float(r["err_std"]) <= target)
        cells.append(f"{runs} runs")
    assert [cell for cell in cells if cell in line] == cells
    assert line.index(cells[0]) < line.rindex(cells[1])


def _quarter_car(tmp_path: Path, sweep: str, extra_input: str = "") -> Path:
    """configs/quarter_car.yaml on 0..0.5 s with another sweep: section."""
    source = Path(__file__).parent.parent / "configs" / "quarter_car.yaml"
    text = source.read_text(encoding="utf-8").replace(
        "../models", str(source.parent.parent / "models")
    )
    text = text.replace(
        "time: {start: 0.0, stop: 3.0, points: 301}", "time: {start: 0.0, stop: 0.5, points: 51}"
    )
    text = text[: text.index("\nsweep:")] + "\n" + textwrap.dedent(sweep)
    text = text.replace("inputs:\n", f"inputs:\n{extra_input}")
    text = text.replace("pdf_times: [3.0]", "pdf_times: [0.5]").replace(
        "pdf_freqs: [1.33, 3.0]", "pdf_freqs: [3.0]"
    )
    config = tmp_path / "quarter_car.yaml"
    config.write_text(text, encoding="utf-8")
    return config


INTRUSIVE = """\
sweep:
  methods:
    - {kind: galerkin, order: [1, 2, 3]}
    - {kind: linearization}
  reference: {kind: collocation, order: 8}
  outputs: [x1]
"""


@pytest.mark.slow
def test_intrusive_methods_join_a_sweep_without_runs(tmp_path):
    config = _quarter_car(tmp_path, INTRUSIVE)
    assert main(["sweep", str(config), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    rows = _rows(tmp_path / "out")
    galerkin = [r for r in rows if r["method"] == "galerkin"]
    assert [r["setting"] for r in galerkin] == ["order=1", "order=2", "order=3"]
    assert all(r["runs"] == "0" and float(r["seconds"]) > 0 for r in rows)
    errors = [float(r["err_std"]) for r in galerkin]
    assert errors[2] < errors[0]  # Galerkin converges to the collocation reference
    (linearization,) = [r for r in rows if r["method"] == "linearization"]
    assert linearization["setting"] == "kind=linearization"
    assert np.isfinite(float(linearization["err_std"]))


def test_an_intrusive_setting_the_model_cannot_take_is_refused_before_anything_runs(
    tmp_path, capsys
):
    mass = "  Ms: {dist: uniform, low: 200.0, high: 300.0}\n"
    config = _quarter_car(tmp_path, INTRUSIVE, extra_input=mass)
    assert main(["sweep", str(config), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "sweep.methods[0].kind: galerkin" in err and "not polynomial in ['Ms']" in err
    assert "sweep.methods[1].kind: linearization" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_plain_run_leaves_the_sweeps_model_checks_to_sweep_and_validate(tmp_path, capsys):
    # pcmb run ignores sweep:, so it does not pay for checking Galerkin's polynomial form in
    # a worker; validate still finds the problem, at its key.
    mass = "  Ms: {dist: uniform, low: 200.0, high: 300.0}\n"
    config = _quarter_car(tmp_path, INTRUSIVE, extra_input=mass)
    assert main(["validate", str(config)]) == 2
    assert "sweep.methods[0].kind: galerkin" in capsys.readouterr().err
    output = tmp_path / "run.h5"
    assert main(["run", str(config), "-o", str(output), "--quiet"]) == 0
    assert output.exists()


@pytest.mark.parametrize(
    "method",
    [
        {"kind": "collocation", "order": 3},
        {"kind": "collocation", "grid": "smolyak", "level": 2},
        {"kind": "collocation", "order": "auto", "max_runs": 200},
        {"kind": "lhs", "samples": 64},
        {"kind": "regression", "samples": 64, "order": 4, "tolerance": 0.01},
        {"kind": "adaptive", "tolerance": 1e-3},
        {"kind": "galerkin", "order": 2},
        {"kind": "linearization"},
    ],
)
def test_the_default_sweep_of_every_method_is_made_of_valid_method_blocks(method):
    # The design says which key its cost is; a method without one (linearization) is run as
    # it is, beside Monte Carlo, instead of being given a max_runs list it does not take.
    found = default_sweep(method_section(method), 100)
    for block in [*found["methods"], found["reference"]]:
        values = {k: v[0] if isinstance(v, list) else v for k, v in block.items()}
        method_section(values)


def test_the_default_sweep_of_order_auto_starts_at_its_first_round():
    """order: auto's budgets rise from 1/8 of max_runs, but never below its first round (3^5 =
    243 runs for 5 inputs): a budget below it is refused."""
    found = default_sweep(method_section({"kind": "collocation", "order": "auto"}), 243)
    (swept,) = [block for block in found["methods"] if block["kind"] == "collocation"]
    assert min(swept["max_runs"]) == 243 and max(swept["max_runs"]) == 1000
