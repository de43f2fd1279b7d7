"""The stored PDFs against closed-form laws, at the 10^5 surrogate draws pcmb uses.

The L1 error ∫|f̂ - f| of a Gaussian KDE at its AMISE-optimal bandwidth is about 0.011 for
a normal law at M = 10^5 (bias and noise alike ~ M^(-2/5)); a law rougher than the table
(256 points) is held to what the table's step allows, not to that.
"""

import numpy as np
import pytest
from scipy import stats

from pcmb.chaos.density import kernel_density

DRAWS = 100_000


def _l1_error(value, density, cdf):
    """∫|f̂ - f| of the table, linearly interpolated, against the law of CDF ``cdf``."""
    fine = np.linspace(value[0], value[-1], 200_001)
    step = fine[1] - fine[0]
    edges = cdf(np.concatenate([fine - step / 2, [fine[-1] + step / 2]]))
    inside = np.sum(np.abs(np.interp(fine, value, density) * step - np.diff(edges)))
    return inside + edges[0] + 1.0 - edges[-1]  # the law's mass beyond the table


def _mass_beyond(value, density, low, high):
    """The table's mass below ``low`` and above ``high``."""
    fine = np.linspace(value[0], value[-1], 200_001)
    table = np.interp(fine, value, density)
    step = fine[1] - fine[0]
    return np.sum(table[fine < low]) * step, np.sum(table[fine > high]) * step


def _two_wells(spread):
    """A mixture of N(-1, spread²) and N(1, spread²) in equal parts."""
    return lambda v: 0.5 * (stats.norm(-1, spread).cdf(v) + stats.norm(1, spread).cdf(v))


def test_two_narrow_peaks_are_not_smeared_into_one_wide_law():
    rng = np.random.default_rng(3)
    spread = 0.1
    samples = rng.choice([-1.0, 1.0], DRAWS) + spread * rng.standard_normal(DRAWS)
    value, density, h = kernel_density(samples)
    # AMISE-optimal h of two far-apart normals: spread (8 / (3 M))^(1/5) = 0.0122; ISJ
    # estimates it within a few percent at M = 10^5 (Scott's σ M^(-1/5) = 0.10 is 8 times it).
    assert h == pytest.approx(spread * (8 / (3 * DRAWS)) ** 0.2, rel=0.05)
    # Two normals: twice a normal's error at half the draws each, ~0.015 (Scott's h: 0.33).
    assert _l1_error(value, density, _two_wells(spread)) < 0.03


def test_peaks_narrower_than_the_table_keep_their_mass_where_the_draws_are():
    rng = np.random.default_rng(4)
    samples = rng.choice([-1.0, 1.0], DRAWS) + 0.02 * rng.standard_normal(DRAWS)
    value, density, h = kernel_density(samples)
    # h is held at the table's step, (max - min) / 249, not Scott's 0.1 (21 % smeared out).
    assert h == pytest.approx(np.ptp(samples) / 249)
    below, above = _mass_beyond(value, density, samples.min(), samples.max())
    assert below + above < 1e-3
    # The peaks (σ = 0.02) span 5 table steps: the error is that of sampling them, < 0.15.
    assert _l1_error(value, density, _two_wells(0.02)) < 0.15


@pytest.mark.parametrize(
    "law", [stats.uniform(), stats.beta(0.5, 0.5)], ids=["uniform", "beta(0.5, 0.5)"]
)
def test_no_mass_beyond_the_hard_bounds_of_a_law(law):
    samples = law.rvs(DRAWS, random_state=np.random.default_rng(5))
    value, density, _ = kernel_density(samples)
    # The draws pile up against 0 and 1: the table ends at them, the kernel mass reflected.
    assert (value[0], value[-1]) == (samples.min(), samples.max())
    assert sum(_mass_beyond(value, density, 0.0, 1.0)) == 0.0
    assert np.trapezoid(density, value) == pytest.approx(1.0, abs=1e-3)
    # Uniform: flat inside, reflection leaves noise and an edge effect of ~ h = 0.004; the
    # beta's infinite peaks at the ends are cut at the table's step: 0.06 measured vs 0.24.
    assert _l1_error(value, density, law.cdf) < 0.1


def test_the_double_well_at_t_4_stays_between_the_wells():
    # x(4) of x' = x - x³, x0 ~ U[-0.625, 0.375]: every solution stays in (-1, 1), piled
    # against ±1; the review found 27 % and 15 % of the stored PDF beyond them.
    rng = np.random.default_rng(6)
    e = np.exp(4.0)
    x0 = rng.uniform(-0.625, 0.375, DRAWS)
    samples = x0 * e / np.sqrt(1.0 + x0**2 * (e**2 - 1.0))
    value, density, _ = kernel_density(samples)
    assert sum(_mass_beyond(value, density, -1.0, 1.0)) == 0.0


def test_a_skewed_and_a_normal_law_are_estimated_to_the_method_s_accuracy():
    rng = np.random.default_rng(7)
    normal = rng.standard_normal(DRAWS)
    value, density, h = kernel_density(normal)
    # AMISE-optimal h of N(0, 1): (4 / (3 M))^(1/5) = 0.106, Scott's rule's neighbour.
    assert h == pytest.approx((4 / (3 * DRAWS)) ** 0.2, rel=0.05)
    assert _l1_error(value, density, stats.norm.cdf) < 0.02
    # Lognormal: its right tail stretches the table (step 0.33): the error is the table's.
    skewed = stats.lognorm(1.0).rvs(DRAWS, random_state=rng)
    value, density, _ = kernel_density(skewed)
    assert sum(_mass_beyond(value, density, 0.0, np.inf)) < 1e-3  # Scott's: 3.7 %


def test_a_far_outlier_leaves_the_bulk_s_mass_in_the_table():
    # One draw at 10^4 beside 10^5 of N(0, 1): the table's step is 40, and a kernel narrower
    # than it would be sampled at a point or two (Scott's h = 3.2 left 0.03 % of the mass).
    samples = np.append(np.random.default_rng(9).standard_normal(DRAWS - 1), 1e4)
    value, density, h = kernel_density(samples)
    assert h >= value[1] - value[0]
    assert np.trapezoid(density, value) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("size", [1, 2, 7, 4096])
def test_the_bandwidths_cosine_transform_is_scipys_dct(size):
    """The ISJ bandwidth's type-II cosine transform against scipy.fft's, an independent
    implementation, to round-off."""
    from scipy.fft import dct

    from pcmb.chaos.density import _cosine_transform

    values = np.random.default_rng(size).random(size)
    expected = dct(values, type=2)
    assert np.allclose(_cosine_transform(values), expected, rtol=0, atol=1e-13 * size)


def test_a_tail_that_thins_out_is_not_taken_for_a_hard_bound():
    """A normal's ends thin out: its table runs three bandwidths past the draws on both sides,
    with no kernel mass reflected back (a sign slip once called every end of 30 or more draws
    piled up, so every PDF stopped at its extreme draws)."""
    samples = np.random.default_rng(8).standard_normal(DRAWS)
    value, density, h = kernel_density(samples)
    assert value[0] == pytest.approx(samples.min() - 3 * h, rel=1e-12)
    assert value[-1] == pytest.approx(samples.max() + 3 * h, rel=1e-12)
    # The mass past the extreme draws is the kernel's own: a few 1e-5 of it, not zero.
    below, above = _mass_beyond(value, density, samples.min(), samples.max())
    assert below > 0 and above > 0
