"""Studies larger than their memory budget: running moments, the reservoir, streamed studies.

References: numpy's two-pass mean and std over every run held at once (round-off apart, the
streamed ones must equal them), exact quantiles of the full sample, and the uninterrupted run
of the same study (a resumed streamed study must end with the same file, to the bit).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.analysis.reservoir import Reservoir
from pcmb.analysis.running_moments import RunningMoments
from pcmb.analysis.statistics import AnalysisSettings
from pcmb.analysis.streaming import stream_statistics
from pcmb.chaos.expansion import sample_std
from pcmb.chaos.inputs import Uniform
from pcmb.config.schema import load_config
from pcmb.errors import ConfigError, ModelRunError, UsageError
from pcmb.run.memory import MIN_RESERVOIR_ROWS, check_memory, parse_memory
from pcmb.store import load

TIMES = np.linspace(0.0, 2.0, 21)
INPUTS = {"a": Uniform(0.5, 1.5), "b": Uniform(1.0, 3.0)}
SAMPLES = 3000
#: A budget below the 7 copies of 3000 runs × 21 times × 2 outputs (7.1 MB) a study held in
#: memory counts, and above what it needs streamed with a reservoir of every run (4.3 MB).
ALL_IN_RESERVOIR = "5MB"
#: A budget that keeps a reservoir of a few hundred runs.
SMALL_RESERVOIR = "1MB"


@pcmb.batched(outputs=("x", "v"))
def wave(params, times):
    a, b = params["a"][:, None], params["b"][:, None]
    return {"x": a * np.sin(b * times) + 3.0, "v": a * b * np.cos(b * times)}


METHOD = {"kind": "montecarlo", "samples": SAMPLES, "seed": 1}


def _study(model=wave, method=METHOD, **execution) -> pcmb.Study:
    return pcmb.Study(
        model,
        INPUTS,
        TIMES,
        method=method,
        execution={"jobs": 1, "backend": "inprocess", **execution},
        analysis=AnalysisSettings(psd=(), quantiles=(0.05, 0.5, 0.95)),
    )


@pytest.fixture(scope="module")
def held(tmp_path_factory: pytest.TempPathFactory) -> pcmb.StudyResult:
    """The study held in memory, the reference."""
    return _study().run(tmp_path_factory.mktemp("held") / "out.h5")


# -- running moments -------------------------------------------------------------------------


def test_running_moments_equal_the_two_pass_ones_over_uneven_blocks() -> None:
    rng = np.random.default_rng(3)
    runs = rng.normal(5.0, 2.0, size=(1000, 7))
    runs[:, 3] = 1.25  # an output that does not vary
    moments = RunningMoments(7)
    for block in np.split(runs, [1, 2, 50, 333, 334, 900]):
        moments.add(block)
    assert moments.count == 1000
    np.testing.assert_allclose(moments.mean, runs.mean(axis=0), rtol=1e-14)
    np.testing.assert_allclose(moments.std(), runs.std(axis=0, ddof=1), rtol=1e-13)
    assert moments.std()[3] == 0.0  # exactly, as sample_std gives it


@pytest.mark.parametrize("size", [1e200, 1e-200])
def test_running_moments_of_values_near_the_float_limits_equal_sample_std(size) -> None:
    """Squares of 1e200 overflow and of 1e-200 underflow: kept in power-of-two units, the
    running std is the in-memory path's (sample_std scales the same way)."""
    rows = size * np.array([[3.0], [1.0], [1.0], [2.0]])
    moments = RunningMoments(1)
    moments.add(rows[:1])
    moments.add(rows[1:])
    np.testing.assert_allclose(moments.std(), sample_std(rows), rtol=1e-15)
    np.testing.assert_allclose(moments.mean, rows.mean(axis=0), rtol=1e-15)


def test_running_moments_keep_a_small_spread_on_a_large_offset() -> None:
    # E[y²] − E[y]² would lose every digit here (1e16 · eps ~ 1 against a variance of 1).
    rng = np.random.default_rng(4)
    spread = rng.normal(0.0, 1.0, size=(4000, 1))
    moments = RunningMoments(1)
    for block in np.array_split(1e8 + spread, 40):
        moments.add(block)
    exact = spread.std(ddof=1)  # the offset does not change the std
    # Each block's two-pass squares and the merge err by a few eps · 1e8 relative to 1.
    np.testing.assert_allclose(moments.std(), exact, rtol=5 * np.finfo(float).eps * 1e8)


# -- the reservoir ---------------------------------------------------------------------------


def test_a_reservoir_as_large_as_the_stream_holds_every_row() -> None:
    rows = np.arange(60.0).reshape(30, 2)
    reservoir = Reservoir(40, 2)
    for start in range(0, 30, 7):
        reservoir.add(rows[start : start + 7], np.arange(start, min(start + 7, 30)))
    np.testing.assert_array_equal(reservoir.rows, rows)
    np.testing.assert_array_equal(reservoir.index, np.arange(30))


def test_every_row_is_equally_likely_to_be_kept() -> None:
    n, size, trials = 200, 20, 2000
    kept = np.zeros(n)
    for seed in range(trials):
        reservoir = Reservoir(size, 1, seed)
        for start in range(0, n, 64):
            block = np.arange(start, min(start + 64, n))
            reservoir.add(block[:, None], block)
        assert np.unique(reservoir.index).size == size
        kept[reservoir.index] += 1
    # Each count is Binomial(2000, 0.1): mean 200, sd 13.4; 5 sd over 200 counts.
    assert np.abs(kept - trials * size / n).max() < 5 * np.sqrt(trials * 0.1 * 0.9)


def test_reservoir_quantiles_are_within_their_documented_accuracy() -> None:
    rng = np.random.default_rng(5)
    runs = rng.lognormal(0.0, 1.0, size=(100_000, 3))
    size = 2000
    reservoir = Reservoir(size, 3, seed=9)
    for start in range(0, runs.shape[0], 4096):
        reservoir.add(runs[start : start + 4096], np.arange(start, start + 4096))
    for level in (0.05, 0.5, 0.95):
        estimate = np.quantile(reservoir.rows, level, axis=0)
        # The level of the estimate among all runs: p ± sqrt(p (1 − p) / size), 4 sd.
        reached = (runs <= estimate).mean(axis=0)
        assert np.abs(reached - level).max() < 4 * np.sqrt(level * (1 - level) / size)


def test_stream_statistics_do_not_depend_on_how_the_runs_were_cut_into_records() -> None:
    rng = np.random.default_rng(6)
    runs = rng.normal(size=(500, 4))
    status = np.ones(500, dtype=np.int8)
    status[[7, 300]] = 2  # failed: left out

    def records(cuts):
        for part in np.split(np.arange(500), cuts):
            yield part, {"y": runs[part, :3], "z": runs[part, 3:]}, status[part]

    found = [
        stream_statistics(records(cuts), {"y": 3, "z": 1}, 64, 50, seed=2)
        for cuts in ([10, 11, 200], [250], list(range(1, 500)))
    ]
    ok = runs[status == 1]
    for moments, reservoir in found:
        np.testing.assert_array_equal(moments["y"].mean, found[0][0]["y"].mean)
        np.testing.assert_array_equal(moments["z"].std(), found[0][0]["z"].std())
        np.testing.assert_array_equal(reservoir.rows, found[0][1].rows)
    np.testing.assert_allclose(found[0][0]["y"].mean, ok[:, :3].mean(axis=0), rtol=1e-13)
    np.testing.assert_array_equal(found[0][1].rows, runs[found[0][1].index])


# -- execution.memory ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "size", "share"),
    [
        ("2GB", 2 * 10**9, None),
        ("512 MiB", 512 * 2**20, None),
        (123, 123, None),
        ("80%", None, 0.8),
    ],
)
def test_memory_settings_parse(text, size, share) -> None:
    budget = parse_memory(text)
    assert (budget.size, budget.share) == (size, share)


@pytest.mark.parametrize("text", ["lots", "0", "150%", "0%", "2 elephants", "-1GB", True, 1.5])
def test_a_bad_execution_memory_is_a_config_error_naming_the_key(tmp_path: Path, text) -> None:
    (tmp_path / "model.py").write_text(
        "import pcmb\n\n@pcmb.pointwise(outputs=('y',))\ndef f(params, times):\n"
        "    return {'y': params['a'] * times}\n"
    )
    config = f"""\
name: m
model: {{kind: python, entry: model.py:f, params: {{a: 1.0}}}}
time: {{start: 0.0, stop: 1.0, points: 3}}
inputs:
  a: {{dist: uniform, low: 0.0, high: 1.0}}
method: {{kind: montecarlo, samples: 10}}
execution:
  memory: {text if isinstance(text, str) else repr(text).lower()}
"""
    with pytest.raises(ConfigError) as raised:
        load_config(tmp_path / "study.yaml", text=config)
    assert "execution.memory" in str(raised.value)
    with pytest.raises(UsageError, match="memory"):
        _study(memory=text)


# -- streamed studies ------------------------------------------------------------------------


def test_a_study_over_its_memory_streams_and_gives_the_same_statistics(
    tmp_path: Path, held: pcmb.StudyResult
) -> None:
    output = tmp_path / "streamed.h5"
    streamed = _study(memory=ALL_IN_RESERVOIR).run(output)
    assert streamed.values["x"].shape == (0, TIMES.size)  # no run held
    for name in ("x", "v"):
        np.testing.assert_allclose(streamed.mean(name), held.mean(name), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(streamed.std(name), held.std(name), rtol=1e-12)
        # The reservoir holds every run here: the quantiles are the exact ones.
        np.testing.assert_array_equal(
            streamed.analysis.outputs[name].quantiles, held.analysis.outputs[name].quantiles
        )
    written = load(output)
    assert not Path(f"{output}.journal").exists()
    for name in ("x", "v"):
        np.testing.assert_array_equal(written.values[name], held.values[name])
        np.testing.assert_array_equal(written.mean(name), held.mean(name))
    np.testing.assert_array_equal(written.status, held.status)


def test_a_file_whose_runs_exceed_the_memory_is_read_without_them(
    tmp_path: Path, held: pcmb.StudyResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A streamed file read back on a machine with less memory than its runs take: the
    statistics from the file, as the streamed result had them, and no run held."""
    output = tmp_path / "streamed.h5"
    streamed = _study(memory=ALL_IN_RESERVOIR).run(output)
    runs_bytes = SAMPLES * TIMES.size * 2 * 8
    monkeypatch.setattr("pcmb.store.available_memory", lambda: runs_bytes)  # 80 %: too little
    read = load(output)
    for name in ("x", "v"):
        assert read.values[name].shape == (0, TIMES.size)
        np.testing.assert_array_equal(read.mean(name), streamed.mean(name))
        np.testing.assert_array_equal(read.std(name), streamed.std(name))
    np.testing.assert_array_equal(read.status, held.status)
    monkeypatch.setattr("pcmb.store.available_memory", lambda: 2 * runs_bytes)  # it fits
    np.testing.assert_array_equal(load(output).values["x"], held.values["x"])


def test_a_streamed_study_with_a_small_reservoir_keeps_quantiles_within_their_accuracy(
    tmp_path: Path, held: pcmb.StudyResult
) -> None:
    study = _study(memory=SMALL_RESERVOIR)
    estimate = study.memory_estimate(SAMPLES, ("x", "v"))
    plan = check_memory(estimate, study.memory, inputs=2, streams=None)[1]
    assert MIN_RESERVOIR_ROWS <= plan.reservoir_rows < SAMPLES
    streamed = study.run(tmp_path / "out.h5")
    np.testing.assert_allclose(streamed.std("x"), held.std("x"), rtol=1e-12)
    runs = held.values["x"]
    for level, band in zip(
        (0.05, 0.5, 0.95), streamed.analysis.outputs["x"].quantiles, strict=True
    ):
        reached = (runs <= band).mean(axis=0)[1:]  # t = 0: every run is 3.0
        sd = np.sqrt(level * (1 - level) / plan.reservoir_rows)
        assert np.abs(reached - level).max() < 4 * sd + 1 / SAMPLES


def test_a_streamed_study_resumes_to_the_same_file(tmp_path: Path) -> None:
    flag = tmp_path / "fail"
    flag.touch()

    @pcmb.batched(outputs=("x", "v"))
    def flaky(params, times):
        if flag.exists() and (params["a"] > 1.2).any():
            raise RuntimeError("not now")
        # Products and sums only: a node's values do not depend on its batch (numpy's sin
        # may differ in the last bit between a batch and a single node, re-run alone).
        a, b = params["a"][:, None], params["b"][:, None]
        return {"x": a * times + b * times**2 + 3.0, "v": a * b * times}

    settings = {"memory": ALL_IN_RESERVOIR, "chunk_size": 100, "on_failure": "abort"}
    output = tmp_path / "resumed.h5"
    with pytest.raises(ModelRunError):
        _study(flaky, **settings).run(output)
    assert Path(f"{output}.journal").is_dir() and not output.exists()
    flag.unlink()
    resumed = _study(flaky, **settings).run(output, resume=True)
    whole = _study(flaky, **settings).run(tmp_path / "whole.h5")
    for name in ("x", "v"):
        np.testing.assert_array_equal(resumed.mean(name), whole.mean(name))
        np.testing.assert_array_equal(resumed.std(name), whole.std(name))
        np.testing.assert_array_equal(
            load(output).values[name], load(tmp_path / "whole.h5").values[name]
        )


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"kind": "collocation", "order": 3}, "method.kind collocation"),
        ({**METHOD, "fit": "regression", "order": 2}, "fit: regression"),
    ],
)
def test_a_study_that_cannot_stream_is_refused_naming_execution_memory(
    tmp_path: Path, changes: dict, reason: str
) -> None:
    study = _study(method=changes, memory="10kB")
    with pytest.raises(UsageError) as raised:
        study.run(tmp_path / "out.h5")
    message = str(raised.value)
    assert "execution.memory" in message and reason in message and "cannot stream" in message
    assert list(tmp_path.iterdir()) == []  # refused before anything ran or was written


def test_a_study_kept_in_memory_cannot_stream() -> None:
    with pytest.raises(UsageError, match="without an output file"):
        _study(memory=ALL_IN_RESERVOIR).run(None)
