"""Distributions: germ maps, their inverses, and the germ/physical laws they promise."""

import numpy as np
import pytest
import scipy.stats as st

from pcmb.chaos.inputs import Beta, Gamma, LogUniform, Normal, Transformed, Uniform
from pcmb.chaos.polynomials import Hermite, Jacobi, Laguerre, Legendre

INPUTS = [
    Uniform(0.025, 0.075),
    Beta(2.0, 5.0, 800.0, 1200.0),
    Normal(3.0, 0.5),
    Gamma(2.5, 0.3, 1.0),
    LogUniform(1e-3, 20.0),
    Transformed(st.lognorm(0.25, scale=2.0), germ="normal"),
    Transformed(st.triang(0.3, loc=1.0, scale=2.0), germ="uniform"),
    Transformed(st.truncnorm(-1.5, 2.0, loc=1.0, scale=0.2), germ="uniform"),
]


@pytest.mark.parametrize("dist", INPUTS, ids=lambda d: d.describe()["dist"])
def test_round_trip(dist):
    xi = dist.family.germ.ppf(np.linspace(0.001, 0.999, 41))
    np.testing.assert_allclose(dist.to_germ(dist.to_physical(xi)), xi, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("dist", INPUTS, ids=lambda d: d.describe()["dist"])
def test_germ_pushes_forward_to_the_physical_law(dist):
    """T(ξ) with ξ from the germ has the physical CDF: F(T(ξ)) = G(ξ) at every quantile."""
    u = np.linspace(0.01, 0.99, 25)
    xi = dist.family.germ.ppf(u)
    np.testing.assert_allclose(dist.physical.cdf(dist.to_physical(xi)), u, rtol=1e-9)


@pytest.mark.parametrize("dist", INPUTS, ids=lambda d: d.describe()["dist"])
def test_samples_follow_the_law(dist):
    samples = dist.sample(20_000, np.random.default_rng(1))
    # Kolmogorov–Smirnov at a fixed seed; p > 1e-3 fails only for a wrong law.
    assert st.kstest(samples, dist.physical.cdf).pvalue > 1e-3


def test_askey_families():
    assert Uniform(0, 1).family == Legendre()
    assert Normal(0, 1).family == Hermite()
    assert Gamma(3.0, 1.0).family == Laguerre(2.0)
    # scipy Beta(alpha, beta): density ∝ (1+ξ)^(alpha-1) (1-ξ)^(beta-1) -> Jacobi(beta-1, alpha-1).
    assert Beta(2.0, 5.0, 0, 1).family == Jacobi(4.0, 1.0)


def test_papers_beta_convention():
    """The papers' Beta(a, b), density ∝ (1-ξ)^a (1+ξ)^b, is scipy Beta(b + 1, a + 1)."""
    a, b = 1.0, 3.0
    dist = Beta(alpha=b + 1, beta=a + 1, low=-1.0, high=1.0)
    xi = np.linspace(-0.9, 0.9, 7)
    ratio = dist.pdf(xi) / ((1 - xi) ** a * (1 + xi) ** b)
    np.testing.assert_allclose(ratio, ratio[0])


def test_pdf_matches_scipy():
    np.testing.assert_allclose(Normal(1.0, 2.0).pdf([0.0, 1.0]), st.norm(1, 2).pdf([0.0, 1.0]))


def test_transformed_tails_stay_finite():
    """Mapping through survival functions keeps |ξ| = 8 (p ~ 1e-15) finite and monotone."""
    dist = Transformed(st.lognorm(0.25), germ="normal")
    theta = dist.to_physical([-8.0, 0.0, 8.0])
    assert np.all(np.isfinite(theta)) and np.all(np.diff(theta) > 0)
    np.testing.assert_allclose(dist.to_germ(theta), [-8.0, 0.0, 8.0], rtol=1e-8)


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (lambda: Uniform(1.0, 1.0), "low must be < high"),
        (lambda: Uniform(0.0, float("nan")), "high must be a finite number"),
        (lambda: Beta(0.0, 1.0, 0, 1), "alpha must be > 0"),
        (lambda: Beta(1.0, 1.0, 2, 1), "low must be < high"),
        (lambda: Normal(0.0, -1.0), "std must be > 0"),
        (lambda: Gamma(-1.0, 1.0), "shape must be > 0"),
        (lambda: Gamma(1.0, 0.0), "scale must be > 0"),
        (lambda: LogUniform(0.0, 1.0), "low must be > 0"),
        (lambda: LogUniform(2.0, 1.0), "low must be < high"),
        (lambda: Transformed(st.poisson(3.0)), "continuous scipy.stats"),
        (lambda: Transformed(st.norm(), germ="gamma"), "germ must be"),
    ],
)
def test_invalid_parameters_name_the_problem(factory, message):
    with pytest.raises(ValueError, match=message):
        factory()


def test_describe_is_json_ready():
    import json

    for dist in INPUTS:
        assert json.loads(json.dumps(dist.describe()))["dist"] == dist.describe()["dist"]


@pytest.mark.parametrize("dist", INPUTS, ids=lambda d: d.describe()["dist"])
def test_description_round_trip(dist):
    from pcmb.chaos.inputs import from_description

    rebuilt = from_description(dist.describe())
    xi = np.linspace(-0.9, 0.9, 5)
    np.testing.assert_array_equal(rebuilt.to_physical(xi), dist.to_physical(xi))
    assert rebuilt.describe() == dist.describe()


@pytest.mark.parametrize("dist", INPUTS, ids=lambda d: d.describe()["dist"])
def test_expectation_matches_scipy(dist):
    assert dist.expectation() == pytest.approx(float(dist.physical.mean()), rel=1e-12, abs=1e-14)


def test_loguniform_is_uniform_in_the_logarithm_with_a_legendre_germ():
    dist = LogUniform(1e-3, 10.0)
    assert dist.family == Legendre()
    np.testing.assert_allclose(dist.to_physical([-1.0, 0.0, 1.0]), [1e-3, 0.1, 10.0], rtol=1e-12)
    assert dist.law == "loguniform(low=0.001, high=10)"
