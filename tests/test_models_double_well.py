"""Tests of models/double_well.py against its closed form."""

from __future__ import annotations

import numpy as np
import pytest
from model_loading import GLOBAL_FACTOR, model_class

from pcmb.references import double_well

DoubleWell = model_class("double_well", "DoubleWell")


def test_batch_matches_the_closed_form_on_the_papers_range():
    # The 8 Gauss–Legendre nodes of the paper's U[-0.625, 0.375] (order 7), plus the edges.
    nodes = -0.125 + 0.5 * np.polynomial.legendre.leggauss(8)[0]
    x0 = np.concatenate([nodes, [-0.625, 0.375]])
    times = np.linspace(0.0, 4.0, 401)
    model = DoubleWell()
    out = model.simulate({"x0": x0}, times)
    assert out["x"].shape == (10, 401)
    assert np.abs(out["x"] - double_well(times, x0)).max() <= GLOBAL_FACTOR * model.rtol
    alone = model.simulate({"x0": x0[:1]}, times)["x"]  # B = 1 keeps the promise too
    assert np.abs(alone - double_well(times, x0[:1])).max() <= GLOBAL_FACTOR * model.rtol


def test_equilibria_stay_put_and_the_wells_attract():
    times = np.linspace(0.0, 30.0, 31)
    out = DoubleWell().simulate({"x0": np.array([-1.0, 0.0, 1.0, -0.01, 0.01])}, times)["x"]
    assert np.array_equal(out[:3], np.array([[-1.0], [0.0], [1.0]]) * np.ones(31))
    # From ±0.01 the state leaves 0 at rate 1 and settles in its well by t = 30.
    assert out[3, -1] == pytest.approx(-1.0, abs=1e-9) and out[4, -1] == pytest.approx(
        1.0, abs=1e-9
    )


def test_double_well_rejects_unknown_parameters():
    with pytest.raises(ValueError, match="no parameter 'x1'"):
        DoubleWell(x1=0.0)
