"""False alarms of the drawn held-out check over a long horizon: the verdict takes the first of
many times, while the flag's margin holds its confidence at each time alone."""

import runpy
from pathlib import Path

import numpy as np
import pytest

from pcmb import Study
from pcmb.analysis.diagnostics import verdict

#: scripts/calibrate_diagnostics.py's cos(1 + t (a + b)), a, b ~ U[0, 1], with its closed form.
CALIBRATION = runpy.run_path(
    str(Path(__file__).parents[1] / "scripts" / "calibrate_diagnostics.py")
)
cosine, cosine_moments = CALIBRATION["cosine"], CALIBRATION["cosine_moments"]
TIMES = np.linspace(0.0, 20.0, 201)
INPUTS = CALIBRATION["CASES"]["cosine"][1]


def _alarms(order: int, seeds: range) -> int:
    """False alarms (a flag where the truth never crosses, or more than 5 % of the horizon
    before it) over ``seeds``."""
    mean, std = cosine_moments(TIMES)
    alarms = 0
    for seed in seeds:
        result = Study(cosine, INPUTS, TIMES, backend="inprocess", order=order, seed=seed).run(
            progress=False
        )
        found = result.diagnostics["y"]
        true = np.fmax(abs(result.mean("y") - mean), abs(result.std("y") - std)) / found.scale
        crossing = verdict(TIMES, true, found.tolerance)
        flag = found.failing_from
        alarms += bool(flag < crossing - 1.0) or (np.isnan(crossing) and not np.isnan(flag))
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
    alarms = _alarms(order, range(30))
    assert alarms <= 3, f"{alarms} false alarms in 30 seeds"
