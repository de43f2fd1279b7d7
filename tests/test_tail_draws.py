"""The widened held-out draws of normal inputs (``held_out_draws``): bounded to
±``TAIL_BOUND`` in the germ, weighted back to the inputs' distribution."""

from __future__ import annotations

import numpy as np
import pytest

import pcmb
from pcmb.analysis.diagnostics import TAIL_BOUND, held_out_draws


def test_widened_draws_stay_within_the_bound_and_their_weights_keep_the_normal_moments():
    # One normal input beside a uniform (λ = 4.2): 4000 draws reach the bound but never
    # pass it, in the germ and in the physical input (mean 2, std 3), and the weighted
    # draws give 1, z², z⁴ their standard normal means (1, 1, 3) within four standard
    # errors of independent draws (a Latin hypercube's are smaller).
    inputs = (pcmb.Normal(2.0, 3.0), pcmb.Uniform(0.0, 1.0))
    draws, weights = held_out_draws(inputs, 4000, 11)
    z = draws.nodes[:, 0]
    assert np.abs(z).max() <= TAIL_BOUND
    assert np.abs(z).max() > TAIL_BOUND - 0.5
    assert np.abs(draws.params[:, 0] - 2.0).max() <= 3.0 * TAIL_BOUND
    for power, exact in ((0, 1.0), (2, 1.0), (4, 3.0)):
        weighted = weights * z**power
        noise = weighted.std() / np.sqrt(z.size)
        assert weighted.mean() == pytest.approx(exact, abs=4 * noise)


def test_draws_without_normal_inputs_are_a_plain_latin_hypercube():
    inputs = (pcmb.Uniform(0.0, 1.0), pcmb.Uniform(-1.0, 1.0))
    draws, weights = held_out_draws(inputs, 16, 3)
    assert np.all(weights == 1.0)
    slices = np.sort(np.floor(16 * draws.params[:, 0]))
    assert np.array_equal(slices, np.arange(16))
