"""Inputs that cannot work say so at their config key, before anything runs.

An input whose range overflows floating point (uniform bounds of ±1e308) or whose nodes do
(a normal input of std 1e307) is refused at ``inputs.<name>``, by ``pcmb validate`` where
the range alone shows it; a random process input whose correlation length no term of its
grid resolves is refused at its ``covariance.length``, saying so.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from cli_process import pcmb_here

MODEL = """
import pcmb


@pcmb.pointwise(outputs=("y",))
def model(params, times):
    return {"y": 0.0 * times + 1.0}
"""


def _config(folder: Path, inputs: str, params: str = "a: 0.0") -> Path:
    (folder / "flat_model.py").write_text(MODEL)
    config = folder / "study.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: messages
            model:
              kind: python
              entry: flat_model.py:model
              params: {{{params}}}
              outputs: [y]
            time: {{start: 0.0, stop: 1.0, points: 3}}
            method: {{kind: collocation, order: 2, validation: 0}}
            execution: {{jobs: 1, backend: loky}}
            output: {str(folder / "result.h5")!r}
            inputs:
            """
        )
        + textwrap.indent(inputs, "  ")
        + "\n"
    )
    return config


@pytest.mark.slow
@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize(
    ("law", "said"),
    [
        # The range itself overflows (the uniform's constructor refuses it).
        ("{dist: uniform, low: -1.0e+308, high: 1.0e+308}", "wider than the largest float"),
        # The law is fine, its nodes overflow (the config checks refuse them).
        ("{dist: normal, mean: 1.0e+308, std: 1.0e+308}", "not a finite number"),
    ],
    ids=["uniform-range", "normal-nodes"],
)
def test_an_input_too_wide_for_floats_is_refused_at_the_input(
    tmp_path: Path, command: str, law: str, said: str
) -> None:
    config = _config(tmp_path, f"a: {law}")
    done = pcmb_here(command, str(config))
    stderr = done.stderr
    assert done.returncode == 2, stderr
    assert f"{config}:12: inputs.a: " in stderr and "run_nodes" not in stderr, stderr
    assert said in stderr, stderr
    assert "RuntimeWarning" not in stderr, stderr  # the overflow is the message, not numpy's
    assert not (tmp_path / "result.h5.journal").exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    "covariance",
    [
        "{kind: exponential, sigma: 1.0, length: 1.0e-6}",
        "{kind: squared-exponential, sigma: 1.0, length: 1.0e-6}",
        "{kind: matern, sigma: 1.0, length: 1.0e-6, nu: 1.5}",
    ],
)
def test_a_correlation_length_no_term_resolves_is_named_at_its_key(
    tmp_path: Path, covariance: str
) -> None:
    process = (
        f"r: {{process: kl, covariance: {covariance}, grid: {{start: 0, stop: 10, points: 11}}, "
        "energy: 0.9}"
    )
    config = _config(tmp_path, process, params="r: 0.0")
    done = pcmb_here("validate", str(config))
    stderr = done.stderr
    assert done.returncode == 2, stderr
    assert f"{config}:12: inputs.r.covariance.length: the correlation length 1e-06" in stderr
    assert "no term of the expansion resolves it" in stderr, stderr
    assert "Traceback" not in stderr and "zero-size array" not in stderr, stderr


@pytest.mark.slow
def test_a_process_needing_more_germs_than_grid_points_is_named_at_its_length(
    tmp_path: Path,
) -> None:
    process = (
        "r: {process: kl, covariance: {kind: squared-exponential, sigma: 1.0, length: 0.006}, "
        "grid: {start: 0, stop: 10, points: 11}, energy: 0.9}"
    )
    config = _config(tmp_path, process, params="r: 0.0")
    done = pcmb_here("validate", str(config))
    stderr = done.stderr
    assert done.returncode == 2, stderr
    assert f"{config}:12: inputs.r.covariance.length: the expansion needs " in stderr, stderr
    assert "more than the 11 points of the grid" in stderr and "runs" not in stderr, stderr


@pytest.mark.slow
def test_a_run_count_beyond_the_floats_is_reported_not_a_crash(tmp_path: Path) -> None:
    process = (
        "r: {process: kl, covariance: {kind: exponential, sigma: 1.0, length: 1.0}, "
        "grid: {start: 0, stop: 10, points: 801}, terms: 700}"
    )
    config = _config(tmp_path, process, params="r: 0.0")
    done = pcmb_here("validate", str(config))
    stderr = done.stderr
    assert done.returncode == 2, stderr
    assert "method.order: the design asks for ~10^333 runs" in stderr, stderr
