"""False alarms of the drawn held-out check over a long horizon: the verdict takes the first of
many times, while the flag's margin holds its confidence at each time alone."""

import runpy
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb import Study
from pcmb.analysis.diagnostics import verdict
from pcmb.references import damped_oscillator

#: scripts/calibrate_diagnostics.py's cos(1 + t (a + b)), a, b ~ U[0, 1], with its closed form.
CALIBRATION = runpy.run_path(
    str(Path(__file__).parents[1] / "scripts" / "calibrate_diagnostics.py")
)
cosine, cosine_moments = CALIBRATION["cosine"], CALIBRATION["cosine_moments"]
TIMES = np.linspace(0.0, 20.0, 201)
INPUTS = CALIBRATION["CASES"]["cosine"][1]
#: The damped oscillator of two inputs (tests/test_economy_audit3.py's FMU, in closed form).
OSCILLATOR_INPUTS = {"k": pcmb.Uniform(3.0, 5.0), "c": pcmb.Uniform(0.05, 0.15)}
OSCILLATOR_TIMES = np.linspace(0.0, 40.0, 401)


@pcmb.batched(outputs=("y",))
def oscillator(params, times):
    """x'' + c x' + k x = 0 from rest at x(0) = 1: its phase drifts with k."""
    return {"y": damped_oscillator(times, params["k"], params["c"])}


def oscillator_moments(times):
    """Mean and std by a Gauss-Legendre product of 200 points in k and 12 in c (within 4e-8
    of one of 400 and 24)."""
    (k, wk), (c, wc) = (np.polynomial.legendre.leggauss(n) for n in (200, 12))
    k, c = np.meshgrid(4.0 + k, 0.1 + 0.05 * c, indexing="ij")
    weights = np.outer(wk, wc).ravel() / 4
    values = damped_oscillator(times, k.ravel(), c.ravel())
    mean = weights @ values
    return mean, np.sqrt(np.maximum(weights @ values**2 - mean**2, 0.0))


def _alarms(model, inputs, times, moments, seeds: range, **method) -> int:
    """False alarms (a flag where the truth never crosses, or more than 5 % of the horizon
    before it) over ``seeds`` of the study of ``model`` with ``method``."""
    mean, std = moments(times)
    alarms = 0
    for seed in seeds:
        result = Study(model, inputs, times, backend="inprocess", seed=seed, **method).run(
            progress=False
        )
        (name,) = result.diagnostics
        found = result.diagnostics[name]
        true = np.fmax(abs(result.mean(name) - mean), abs(result.std(name) - std)) / found.scale
        crossing = verdict(times, true, found.tolerance)
        flag = found.failing_from
        early = flag < crossing - 0.05 * (times[-1] - times[0])
        alarms += bool(early) or (np.isnan(crossing) and not np.isnan(flag))
    return alarms


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="the flag's margin holds 90 % at each time (pcmb/analysis/diagnostics/verdict.py), "
    "not over the horizon: 8 and 10 false alarms of 30; a margin over the times so far (Rice's "
    "formula) cut them to 3 and 1 but left the steepening and spreading responses of "
    "tests/test_diagnostics.py and oscillator_wide unflagged; confirming narrow flags with the "
    "second batch changed none (every seed at order 9 draws it already, and all 25 runs make "
    "the false flags), and requiring the first 8 runs' own pass too cut order 9 to 7 while "
    "oscillator_wide went unflagged on 6-9 seeds of 10 (docs/diagnostics.md)",
)
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
@pytest.mark.parametrize("order", [4, 9])
def test_the_cos_family_flags_falsely_in_at_most_a_tenth_of_seeds(order):
    """Order 9 (true error at most 3.4 %, never crossing 5 %) flagged 10 of 30 seeds, order 4
    (crossing at t = 9.9) flagged 8 of 30 before t = 8.9: each time held its 10 %, the first
    of some twenty nearly independent ones did not."""
    alarms = _alarms(cosine, INPUTS, TIMES, cosine_moments, range(30), order=order)
    assert alarms <= 3, f"{alarms} false alarms in 30 seeds"


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="8 false alarms in 40 seeds (28 in 100), at t = 14.8-26.4 against a true crossing at "
    "30.7: the check's estimate is unbiased (averaged over 400 seeds it is the truth at every "
    "time) and holds about its confidence at each time, but its standard errors, 0.04-0.07 of "
    "the scale from 10 runs, are as large as the tolerance over some 280 times; the Student t "
    "law of 9 degrees of freedom in the flag's margin cut them to 5 (21 of 100) but flagged "
    "later elsewhere, the drawn families' timely flags and this case's own (8 -> 5 of 100): "
    "measured and not kept (docs/diagnostics.md)",
)
@pytest.mark.filterwarnings("ignore::pcmb.errors.PcmbWarning")
def test_the_adaptive_oscillator_flags_falsely_in_at_most_a_tenth_of_seeds():
    """Issue 23, item 4: the damped oscillator of two inputs under ``{kind: adaptive,
    tolerance: 1e-2}`` (41 runs; a drawn check of 8 + 2 runs) passes the tolerance 0.05 at
    t = 30.7; seed 0 flagged it from 14.9 with "8.4 % ± 2.4 %" where the mean's true error is
    0.04 % (the std's 2.4 %)."""
    alarms = _alarms(
        oscillator,
        OSCILLATOR_INPUTS,
        OSCILLATOR_TIMES,
        oscillator_moments,
        range(40),
        method="adaptive",
        tolerance=1e-2,
    )
    assert alarms <= 4, f"{alarms} false alarms in 40 seeds"
