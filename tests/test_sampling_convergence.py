"""Sampling methods through the study pipeline converge at their known rates (Ishigami).

The estimator is the pipeline's sample mean (``StudyResult.mean`` of a sampling study);
its root-mean-square error over R seeds is measured at N = 2^7 .. 2^13 and compared with
the theory:

- Monte Carlo: RMSE = σ / √N exactly, σ² = Var f = 13.84.
- Latin hypercube: RMSE ≈ √(V_res / N), V_res the variance of f minus its additive part
  (Stein 1987). For Ishigami the only interaction is x1·x3, V_res = V_13 = 3.37: the same
  N^-1/2 rate with a constant about half of Monte Carlo's.
- Scrambled Sobol' (N a power of two): RMSE = O(N^-3/2 (log N)^{(d-1)/2}) for smooth f
  (Owen 1997); over this range we ask for a slope of -0.9 or steeper ("close to N^-1").

Tolerances: with R = 24 seeds an RMSE estimate has a relative standard deviation of about
1/√(2R) = 0.14, so a log-log slope fitted over 7 sizes spaced by a factor 2 has a standard
deviation of 0.14 / √Σ(x - x̄)² = 0.04, and the average log-ratio to the theory over 7
sizes one of 0.14 / √7 = 0.055. The bounds below are about 3.5 of those (0.15 on slopes, a
factor e^0.2 ≈ 1.22 on constants, widened to 1.35 for LHS whose formula is asymptotic).
Seeds are fixed, so the test is deterministic.
"""

import numpy as np
import pytest

import pcmb
from pcmb.references import ishigami, ishigami_moments

pytestmark = pytest.mark.slow  # 500 small studies in this process, about 3 s

SIZES = 2 ** np.arange(7, 14)
SEEDS = range(24)
INPUTS = {name: pcmb.Uniform(-np.pi, np.pi) for name in ("x1", "x2", "x3")}


class Ishigami:
    """The Ishigami function as a batch model with one output time."""

    outputs = ("y",)

    def simulate(self, params, times):
        x = np.column_stack([params["x1"], params["x2"], params["x3"]])
        return {"y": ishigami(x)[:, None] * np.ones(times.size)}


def _rmse(method):
    """(len(SIZES),) RMSE of the pipeline's sample mean over the seeds."""
    exact = ishigami_moments().mean
    errors = np.empty((len(SEEDS), SIZES.size))
    for i, seed in enumerate(SEEDS):
        for j, size in enumerate(SIZES):
            study = pcmb.Study(
                Ishigami(),
                INPUTS,
                [0.0],
                method=method,
                samples=int(size),
                seed=seed,
                backend="inprocess",  # the estimator is under test, not the workers
                chunk_size=int(size),  # one batch a study, as a batch model takes it
            )
            errors[i, j] = study.run().mean("y")[0] - exact
    return np.sqrt(np.mean(errors**2, axis=0))


@pytest.fixture(scope="module")
def rmse():
    return {method: _rmse(method) for method in ("montecarlo", "lhs", "sobol")}


def _slope(values):
    return np.polyfit(np.log(SIZES), np.log(values), 1)[0]


def _log_ratio(values, theory):
    return float(np.mean(np.log(values / theory)))


def test_monte_carlo_error_is_sigma_over_root_n(rmse):
    variance = ishigami_moments().variance
    assert _slope(rmse["montecarlo"]) == pytest.approx(-0.5, abs=0.15)
    assert abs(_log_ratio(rmse["montecarlo"], np.sqrt(variance / SIZES))) < 0.2


def test_latin_hypercube_removes_the_additive_variance(rmse):
    exact = ishigami_moments()
    interaction = exact.variance * exact.total[2]  # V_13: the non-additive part
    assert _slope(rmse["lhs"]) == pytest.approx(-0.5, abs=0.15)
    assert abs(_log_ratio(rmse["lhs"], np.sqrt(interaction / SIZES))) < np.log(1.35)
    assert np.all(rmse["lhs"] < rmse["montecarlo"])


def test_scrambled_sobol_converges_close_to_one_over_n(rmse):
    assert _slope(rmse["sobol"]) < -0.9
    # At N = 8192 the error is far below Monte Carlo's (N^-1 vs N^-1/2: a factor ~90 here).
    assert rmse["sobol"][-1] < rmse["montecarlo"][-1] / 10
