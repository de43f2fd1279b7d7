"""Held-out runs that fail in the tails a drawn check widens its normal inputs into, beyond the
design's nodes: left out of the check, never a reason to stop a study (docs/diagnostics.md)."""

import functools

import executor_models as em
import numpy as np
import pytest

import pcmb
from pcmb.cli import main
from pcmb.config.schema import ExecutionSpec
from pcmb.errors import ModelRunError
from pcmb.result import Status
from pcmb.run.executor import run_nodes

TIMES = np.linspace(0.0, 2.0, 21)
STIFFNESS = pcmb.Normal(1.0, 0.25)

#: A stiffness that must be positive: K ~ N(1, 0.25) is negative 4 σ below its mean, where
#: the check's widened draws (N(0, 4.2²) within ±6 in the germ) often go, the design's nodes
#: (order 4: ±2.9 σ) never.
STIFFNESS_MODEL = """\
import numpy as np
import pcmb


@pcmb.batched(outputs=("y",))
def stiffness(params, times):
    K = params["K"]
    if np.any(K <= 0):
        raise ValueError(f"stiffness must be positive, got {K.min()}")
    c = params.get("c", np.ones_like(K))
    return {"y": np.sqrt(K)[:, None] * np.exp(-c[:, None] * times)}
"""
stiffness = {}
exec(STIFFNESS_MODEL, stiffness)
stiffness = stiffness["stiffness"]


def _tail_records(result):
    return [w.message for w in result.warnings if w.code == "nodes-failed"]


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
@pytest.mark.parametrize("order", [4, "auto"], ids=["joined", "after-rounds"])
@pytest.mark.parametrize(
    ("seed", "inputs"),
    [
        # The seeds of 0-5 whose lowest draw lies below -4 σ (seeds 1 and 2: -3.5 and -2.9).
        *((seed, {"K": STIFFNESS, "c": pcmb.Uniform(0.5, 1.5)}) for seed in (0, 3, 4, 5)),
        (0, {"K": STIFFNESS}),
    ],
    ids=[*(f"drawn-{seed}" for seed in (0, 3, 4, 5)), "placed"],
)
def test_a_held_out_run_failing_in_a_normal_tail_does_not_abort(seed, inputs, order):
    """Under ``on_failure: abort`` the study finishes, its check drawn widened or placed; the
    failed tail runs are left out of the check and named, with the input whose tail they lie
    in and the model's error."""
    study = pcmb.Study(
        stiffness,
        inputs,
        TIMES,
        method={"kind": "collocation", "order": order, "seed": seed},
        execution={"backend": "inprocess", "on_failure": "abort"},
    )
    result = study.run()
    held_out = result.held_out
    failed = ~held_out.ok
    assert np.all(held_out.params[failed, 0] <= 0)
    assert np.all(held_out.params[~failed, 0] > 0)
    assert failed.any()  # the lowest draw: K < 0
    (record,) = _tail_records(result)
    assert f"{failed.sum()} of {failed.size} held-out run(s) failed in the tails of K" in record
    assert "beyond the design's nodes" in record
    assert "stiffness must be positive" in record
    assert "held-out run " in record and "node " not in record.replace("design's nodes", "")


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_pcmb_run_finishes_a_study_whose_held_out_runs_fail_in_the_tails(tmp_path, capsys):
    """The same study from a config file: exit 0, and the file holds the record."""
    (tmp_path / "stiff.py").write_text(STIFFNESS_MODEL)
    config = tmp_path / "stiff.yaml"
    config.write_text(
        "name: stiff\n"
        "model: {kind: python, entry: stiff.py:stiffness, params: {K: 1.0, c: 1.0}}\n"
        "time: {start: 0.0, stop: 2.0, points: 21}\n"
        "inputs:\n"
        "  K: {dist: normal, mean: 1.0, std: 0.25}\n"
        "  c: {dist: uniform, low: 0.5, high: 1.5}\n"
        "method: {kind: collocation, order: 4, seed: 3}\n"
        "execution: {backend: inprocess, on_failure: abort}\n"
        f"output: {tmp_path / 'stiff.h5'}\n"
    )
    assert main(["run", str(config)]) == 0
    result = pcmb.load(tmp_path / "stiff.h5")
    assert not result.held_out.ok.all()  # seed 3 draws K = -0.4 (germ -5.6)
    assert any("in the tails of K" in record for record in _tail_records(result))


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_a_held_out_run_failing_within_the_design_s_range_still_aborts(tmp_path):
    """A held-out run inside the design's nodes in every input is no tail draw: its failure
    stops the study under ``on_failure: abort``, as before; ``--resume`` then finishes it from
    the journal, which holds a failed tail draw too, and runs none of the design's nodes."""
    inputs = {"a": STIFFNESS, "b": pcmb.Uniform(0.0, 1.0)}
    settings = {
        "method": {"kind": "collocation", "order": 4, "seed": 3},
        "outputs": ["y"],
        "execution": {"backend": "inprocess", "on_failure": "abort", "nominal_run": False},
    }
    plain = pcmb.Study(em.PositiveRamp, inputs, TIMES, params={"bad": [], "switch": ""}, **settings)
    held_out = plain.run().held_out
    assert not held_out.ok.all()  # a tail draw at a < 0
    reach = np.abs(plain.node_set().nodes[:, 0]).max()
    inside = np.flatnonzero(np.abs(held_out.germ[:, 0]) < reach)
    switch = tmp_path / "switch"
    switch.touch()
    params = {"bad": [held_out.params[inside[-1], 0]], "switch": str(switch)}
    study = pcmb.Study(em.PositiveRamp, inputs, TIMES, params=params, **settings)
    with pytest.raises(ModelRunError, match="the model failed at 1 of 8 held-out run"):
        study.run(tmp_path / "r.h5")
    switch.unlink()
    em.SwitchedRamp.RAN.clear()
    resumed = study.run(tmp_path / "r.h5", resume=True)
    design = set(map(tuple, plain.node_set().params.tolist()))
    assert not design & set(em.SwitchedRamp.RAN)  # the design's runs come from the journal
    np.testing.assert_array_equal(resumed.held_out.ok, held_out.ok)
    assert any("in the tails of a" in record for record in _tail_records(resumed))


def test_a_tolerated_failure_does_not_stop_an_aborting_campaign():
    """``stop_on_failure`` stops dispatching at a failure, but not at a ``tolerated`` node's."""
    params = {"a": np.array([-1.0, 1.0, 2.0, 3.0])}
    model = functools.partial(em.RaisingRamp, [-1.0])
    execution = ExecutionSpec(backend="inprocess")
    run = {"execution": execution, "chunk_size": 1, "stop_on_failure": True}
    stopped = run_nodes(model, params, TIMES, ["y"], **run)
    assert np.any(stopped.status == Status.PENDING)
    tolerated = np.array([True, False, False, False])
    went_on = run_nodes(model, params, TIMES, ["y"], tolerated=tolerated, **run)
    assert list(went_on.status) == [Status.FAILED, Status.OK, Status.OK, Status.OK]


def _refusing_beyond(limit):
    """A model of standard normal inputs that raises where one of them lies beyond ±``limit``."""

    @pcmb.batched(outputs=("y",))
    def refusing(params, times):
        z = np.column_stack(list(params.values()))
        if np.any(np.abs(z) > limit):
            raise ValueError(f"an input beyond ±{limit:g}: {np.abs(z).max():.2f}")
        return {"y": z.sum(axis=1)[:, None] * np.sin(times)}

    return refusing


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_a_model_failing_within_three_sigma_of_many_normal_inputs_aborts():
    """A Karhunen–Loève forcing of 10 normal germs on a Smolyak grid whose nodes reach ±1.73:
    most held-out draws lie beyond them in some germ, but a model that fails beyond ±2 (a bug
    that 37 % of real inputs meet) fails where its inputs are not rare; such a failure is no
    tail draw's and stops the study (it finished with a nodes-failed record)."""
    inputs = {f"xi{i}": pcmb.Normal(0.0, 1.0) for i in range(10)}
    study = pcmb.Study(
        _refusing_beyond(2.0),
        inputs,
        TIMES,
        method={"kind": "collocation", "grid": "smolyak", "level": 1, "seed": 0},
        execution={"backend": "inprocess", "on_failure": "abort"},
    )
    assert np.abs(study.node_set().nodes).max() < 2.0  # the design's nodes all work
    with pytest.raises(ModelRunError, match=r"the model failed at \d of 8 held-out run"):
        study.run()


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_a_check_most_of_whose_runs_fail_in_the_tails_aborts():
    """One normal input at order 4, its held-out runs placed (±3.9, ±5.0, 0.66, −2.0, 2.2,
    −6.1): a model that refuses its input beyond ±3 σ fails at 5 of the 8, all in the tails.
    The check cannot stand on the other 3: the study stops and says why."""
    study = pcmb.Study(
        _refusing_beyond(3.0),
        {"K": pcmb.Normal(0.0, 1.0)},
        TIMES,
        method={"kind": "collocation", "order": 4},
        execution={"backend": "inprocess", "on_failure": "abort"},
    )
    with pytest.raises(ModelRunError) as raised:
        study.run()
    message = str(raised.value)
    assert "the model failed at 5 of 8 held-out run(s)" in message
    assert "5 of them in the tails, more than 50% of the check's runs: too many" in message


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_tail_draws_are_retried_under_on_failure_retry():
    """Under ``on_failure: retry`` a tail draw is retried like any run: a failure is not known
    to be the tail's until it recurs (a killed worker, a lost licence), and one left out costs
    the check a run where a surrogate errs most; a failure that recurs costs ``retries`` calls
    of its one run. A tail draw failing once is then kept; under ``abort`` it is left out."""
    inputs = {"a": STIFFNESS}
    method = {"kind": "collocation", "order": 4}
    execution = {"backend": "inprocess", "chunk_size": 1, "nominal_run": False}
    plain = pcmb.Study(em.Ramp, inputs, TIMES, method=method, outputs=["y"], execution=execution)
    held_out = plain.run().held_out
    tails = held_out.params[np.abs(held_out.germ[:, 0]) > 3, 0]
    assert tails.size == 5  # placed at ±3.9, ±5.0 and -6.1 σ

    def flaky(policy):
        params = {"bad": tails[:2].tolist(), "failures": 1, "nonce": policy}
        settings = {"on_failure": policy, "retries": 1, **execution}
        study = pcmb.Study(
            em.FlakyRamp,
            inputs,
            TIMES,
            params=params,
            method=method,
            outputs=["y"],
            execution=settings,
        )
        return study.run()

    retried = flaky("retry")
    assert retried.held_out.ok.all() and not _tail_records(retried)
    left_out = flaky("abort")
    assert left_out.held_out.ok.sum() == 6
    (record,) = _tail_records(left_out)
    assert "transient failure 1" in record


@pytest.mark.filterwarnings("ignore::pcmb.PcmbWarning")
def test_the_tail_share_is_judged_over_the_whole_check(monkeypatch):
    """A second batch of held-out runs is judged with the first: at order 6 (nodes to ±3.75)
    seed 8 draws two tail runs among its first 8, and its one more run at a germ of -4.07; all
    three failing is 3 of the check's 9 runs, not too many, though the second batch's one run
    fails (it stopped the study)."""
    monkeypatch.setattr("pcmb.study.more_runs", lambda found: 1)
    inputs = {"a": STIFFNESS, "b": pcmb.Uniform(0.0, 1.0)}
    settings = {
        "method": {"kind": "collocation", "order": 6, "seed": 8},
        "outputs": ["y"],
        "execution": {"backend": "inprocess", "on_failure": "abort", "nominal_run": False},
    }
    held_out = pcmb.Study(em.Ramp, inputs, TIMES, **settings).run().held_out
    assert held_out.ok.size == 9
    tails = np.flatnonzero(np.abs(held_out.germ[:, 0]) > 3.75)
    assert list(tails) == [0, 2, 8], held_out.germ[tails, 0]
    bad = held_out.params[tails, 0].tolist()
    result = pcmb.Study(em.RaisingRamp, inputs, TIMES, params={"bad": bad}, **settings).run()
    assert list(np.flatnonzero(~result.held_out.ok)) == [0, 2, 8]
    assert all("in the tails of a" in record for record in _tail_records(result))
