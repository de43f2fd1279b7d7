"""What each command imports and starts before its work (issue 24): whole processes, no
timing asserts; the times are in docs/benchmarks.md."""

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.special as sp
from cli_process import pcmb_cli

import pcmb
from pcmb.chaos.polynomials import NUMPY_RULE_POINTS, Hermite, Legendre
from pcmb.config.schema import load_config
from pcmb.errors import ConfigError
from pcmb.study import Study

ROOT = Path(__file__).resolve().parents[1]


def _loaded(code: str, modules: list[str]) -> dict[str, bool]:
    """Which of ``modules`` are in ``sys.modules`` after running ``code`` in a fresh
    interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps([m in sys.modules for m in {modules!r}]))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return dict(zip(modules, json.loads(out.stdout.strip().splitlines()[-1]), strict=True))


def test_reading_the_config_schema_imports_no_scipy_nor_joblib():
    heavy = ["scipy.special", "scipy.linalg", "joblib"]
    assert _loaded("import pcmb.config.schema", heavy) == dict.fromkeys(heavy, False)


@pcmb.pointwise(outputs=("y",))
def _line(params, times):
    return {"y": params["a"] * times + params["b"] ** 2}


#: A design with rounds: its held-out runs are made beside the fit.
_ROUNDS = {"kind": "adaptive", "tolerance": 1e-2, "max_runs": 200}


def test_the_held_out_runs_go_on_while_the_expansions_are_fitted(monkeypatch):
    """The workers make the held-out runs of a design with rounds (known only after them,
    so not joined to its runs) while the main process fits and draws the statistics: the
    held-out runs here wait until the fit has begun (on the code before, which ran them first,
    they waited in vain, for the guard's 20 s)."""
    fitting = threading.Event()
    seen = []
    run_held_out, recover = Study._run_held_out, Study._recover

    def held_out_after_the_fit_began(self, *args, **kwargs):
        seen.append(fitting.wait(timeout=20))
        return run_held_out(self, *args, **kwargs)

    def recover_and_say_so(self, *args, **kwargs):
        fitting.set()
        return recover(self, *args, **kwargs)

    monkeypatch.setattr(Study, "_run_held_out", held_out_after_the_fit_began)
    monkeypatch.setattr(Study, "_recover", recover_and_say_so)
    inputs = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}
    study = Study(_line, inputs, np.linspace(0.0, 2.0, 5), method=_ROUNDS, execution={"jobs": 1})
    result = study.run()
    assert seen == [True]
    assert result.held_out is not None and result.held_out.ok.all()


def test_a_run_that_fails_while_its_held_out_runs_go_on_waits_for_them(monkeypatch):
    """No run is left going behind a failed ``Study.run``: the held-out runs sent beside the
    fit end before the error reaches the caller (who may own the pool and reuse it)."""
    ended = []
    run_held_out = Study._run_held_out

    def slow_held_out(self, *args, **kwargs):
        time.sleep(1.0)
        found = run_held_out(self, *args, **kwargs)
        ended.append(True)
        return found

    def broken_fit(self, *args, **kwargs):
        raise RuntimeError("the fit broke")

    monkeypatch.setattr(Study, "_run_held_out", slow_held_out)
    monkeypatch.setattr(Study, "_recover", broken_fit)
    inputs = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}
    study = Study(_line, inputs, np.linspace(0.0, 2.0, 5), method=_ROUNDS, execution={"jobs": 1})
    with pytest.raises(RuntimeError, match="the fit broke"):
        study.run()
    assert ended == [True]
    assert not [t for t in threading.enumerate() if t.name == "pcmb-held-out"]


def test_a_run_leaves_the_sweeps_settings_to_sweep_and_validate():
    """A plain run ignores ``sweep:`` and so does not build the designs of its settings (the
    quarter car's sweep: 35 designs, 0.2-0.7 s); validate still refuses a bad one at its
    key."""
    path = ROOT / "configs" / "quarter_car.yaml"
    text = path.read_text().replace("max_runs: 2000", "max_runs: 3")
    assert "max_runs: 3" in text
    config = load_config(path, text=text, check_sweep=False)
    assert config.sweep is not None
    with pytest.raises(ConfigError, match=r"sweep\.methods\[2\]\.max_runs"):
        load_config(path, text=text)


def test_validate_checks_the_model_in_one_child_without_a_pool():
    """``pcmb validate`` builds the model in one worker process it starts (the isolation),
    never a loky pool: joblib stays unimported in its own process; nor scipy (the nodes'
    Gauss rules are numpy's, the sweep's Gauss-Patterson points need no scipy)."""
    config = ROOT / "configs" / "quarter_car.yaml"
    code = (
        "import contextlib, io\nfrom pcmb.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main(['validate', {str(config)!r}]) == 0"
    )
    assert _loaded(code, ["joblib", "scipy", "pcmb.run.executor"]) == {
        "joblib": False,
        "scipy": False,
        "pcmb.run.executor": True,
    }


def test_legendre_and_hermite_gauss_rules_import_no_scipy():
    """The nodes of uniform and normal inputs come from numpy's Gauss rules: a run or a
    validate of such a config never waits for scipy.special's import (0.1-0.3 s) to make
    them."""
    code = (
        "from pcmb.chaos.polynomials import Hermite, Legendre\n"
        "Legendre().gauss_rule(6), Hermite().gauss_rule(6)"
    )
    assert _loaded(code, ["scipy.special"]) == {"scipy.special": False}


def test_kronrod_patterson_extensions_are_computed_once(monkeypatch):
    """Each adaptive or Smolyak design of a family reuses its Gauss-Patterson points:
    validating the quarter car's sweep built them 30 times (10 adaptive designs × 3 inputs,
    0.13 s)."""
    from pcmb.chaos import nested

    calls = []
    extend = nested._extend

    def counted(*args):
        calls.append(args[2])
        return extend(*args)

    monkeypatch.setattr(nested, "_extend", counted)
    nested._extensions.cache_clear()  # what tests before this one filled
    first = nested.gauss_patterson().nodes(3)
    again = nested.gauss_patterson().nodes(3)
    np.testing.assert_array_equal(first, again)
    assert len(calls) == len(nested.gauss_patterson().added)


@pytest.mark.parametrize(
    ("family", "roots"),
    [(Legendre(), sp.roots_legendre), (Hermite(), sp.roots_hermitenorm)],
    ids=["legendre", "hermite"],
)
def test_numpy_rules_equal_scipys(family, roots):
    """Legendre and Hermite rules (numpy's up to NUMPY_RULE_POINTS) equal scipy's roots_*
    (Newton-polished), an independent implementation: nodes to 1e-14 of the largest, weights
    to 1e-12 of the largest (against 40-digit rules, both are within 2e-13 of the largest
    weight at 30 to 80 points); past it they are scipy's (numpy's overflow at 371)."""
    for q in [*range(1, NUMPY_RULE_POINTS + 1), 371, 572]:
        rule = family.gauss_rule(q)
        nodes, weights = roots(q)
        np.testing.assert_allclose(rule.nodes, nodes, rtol=0, atol=1e-14 * max(1, nodes[-1]))
        weights = weights / weights.sum()
        np.testing.assert_allclose(rule.weights, weights, rtol=0, atol=1e-12 * weights.max())


def test_a_pdf_imports_no_scipy():
    """A study's PDFs take their bandwidth's cosine transform from numpy's FFT: scipy.fft's
    import (0.2 s) doubled the cost of the first PDF of every run."""
    code = (
        "import numpy as np\nfrom pcmb.chaos.density import kernel_density\n"
        "kernel_density(np.random.default_rng(0).normal(size=1000))"
    )
    assert _loaded(code, ["scipy"]) == {"scipy": False}


def test_the_held_out_check_imports_no_scipy():
    """The χ² bound of the held-out check comes from its closed form: scipy.special's import
    (0.2 s) was most of a run's diagnostics."""
    code = (
        "import numpy as np\nfrom pcmb.analysis.diagnostics import holdout_error\n"
        "holdout_error(np.zeros((8, 3)), np.ones((8, 3)), np.zeros(3), np.ones(3), 1.0)"
    )
    assert _loaded(code, ["scipy"]) == {"scipy": False}


_COLLECTOR_MODEL = """
import gc

import numpy as np


class Collector:
    outputs = ("enabled",)

    def __init__(self, a=1.0):
        self.parameters = {"a": a}

    def simulate(self, params, times):
        return {"enabled": np.full((len(params["a"]), times.size), float(gc.isenabled()))}
"""


@pytest.mark.slow  # a whole run in a pcmb process of its own: 1.9 s of CPU
def test_the_command_collects_garbage_while_its_models_run(tmp_path):
    """The command turns garbage collection off only while it imports and reads its config:
    a long study's cycles are still collected (the model runs in pcmb's own process here)."""
    (tmp_path / "collector.py").write_text(_COLLECTOR_MODEL)
    config = tmp_path / "collector.yaml"
    config.write_text(
        "name: collector\n"
        "model: {kind: python, entry: collector.py:Collector}\n"
        "time: {start: 0.0, stop: 1.0, points: 3}\n"
        "inputs: {a: {dist: uniform, low: 1.0, high: 2.0}}\n"
        "method: {kind: collocation, order: 2}\n"
    )
    out = tmp_path / "out.h5"
    done = pcmb_cli("run", str(config), "-o", str(out), "--quiet", "--backend", "inprocess")
    assert done.returncode == 0, done.stderr
    assert np.all(pcmb.load(out).values["enabled"] == 1.0)


def test_main_called_from_python_leaves_the_collector_as_it_was(tmp_path, capsys):
    """Only the command itself (``python -m pcmb.cli``, the console script) changes garbage
    collection; a caller of :func:`pcmb.cli.main` keeps it on and nothing of theirs frozen."""
    import gc

    from pcmb.cli import main

    frozen = gc.get_freeze_count()
    assert main(["validate", str(tmp_path / "missing.yaml")]) == 2
    assert gc.isenabled() and gc.get_freeze_count() == frozen
