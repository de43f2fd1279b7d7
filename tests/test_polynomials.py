"""1-D orthonormal families and Gauss rules against their defining properties."""

import numpy as np
import pytest
import scipy.integrate as si
import scipy.special as sp

from pcmb.chaos.polynomials import Hermite, Jacobi, Laguerre, Legendre
from pcmb.references import gamma_moment, jacobi_moment, normal_moment, uniform_moment

FAMILIES = [
    Legendre(),
    Jacobi(alpha=1.0, beta=1.0),
    Jacobi(alpha=0.5, beta=2.5),
    Jacobi(alpha=-0.5, beta=-0.5),  # alpha + beta = -1 exercises the k = 1 special case
    Hermite(),
    Laguerre(alpha=0.0),
    Laguerre(alpha=1.5),
]


@pytest.mark.parametrize("family", FAMILIES, ids=repr)
def test_weights_are_probabilities(family):
    for q in (1, 2, 7, 30):
        rule = family.gauss_rule(q)
        assert rule.nodes.shape == rule.weights.shape == (q,)
        assert np.all(rule.weights > 0)
        assert rule.weights.sum() == pytest.approx(1.0, abs=1e-14)
        assert np.all(np.diff(rule.nodes) > 0)


def exact_moment(family, m):
    """E[ξ^m] of the germ in closed form (scipy's loc/scale moments are numerical)."""
    if isinstance(family, Hermite):
        return normal_moment(m)
    if isinstance(family, Laguerre):
        return gamma_moment(m, family.alpha)
    if isinstance(family, Legendre):
        return uniform_moment(m)
    return jacobi_moment(m, family.alpha, family.beta)


@pytest.mark.parametrize("family", FAMILIES, ids=repr)
@pytest.mark.parametrize("q", [1, 3, 6, 10])
def test_rule_is_exact_to_degree_2q_minus_1(family, q):
    """E[ξ^m] from the rule equals the germ's exact raw moment for m <= 2q - 1."""
    rule = family.gauss_rule(q)
    for m in range(2 * q):
        exact = exact_moment(family, m)
        approx = rule.integrate(rule.nodes**m)
        # Round-off of the sum scales with E|ξ|^m (odd moments cancel to zero).
        scale = rule.integrate(np.abs(rule.nodes) ** m)
        assert approx == pytest.approx(exact, rel=1e-12, abs=1e-13 * scale)


@pytest.mark.parametrize("family", FAMILIES, ids=repr)
def test_discrete_orthonormality_to_degree_20(family):
    """Vᵀ W V = I for a 21-point rule up to degree 20 — the property collocation relies on."""
    degree = 20
    rule = family.gauss_rule(degree + 1)
    values = family.evaluate(rule.nodes, degree)
    gram = values.T @ (rule.weights[:, None] * values)
    np.testing.assert_allclose(gram, np.eye(degree + 1), atol=1e-12)


@pytest.mark.parametrize("family", FAMILIES, ids=repr)
def test_continuous_orthonormality_by_adaptive_quadrature(family):
    """Orthonormality under the germ density, checked by an independent integrator."""
    low, high = family.support
    for i, j in [(0, 0), (1, 1), (3, 3), (2, 5), (4, 4), (1, 4)]:

        def integrand(x, i=i, j=j):
            p = family.evaluate(x, max(i, j))
            return p[i] * p[j] * family.germ.pdf(x)

        value, _ = si.quad(integrand, low, high, limit=200, epsabs=1e-12)
        assert value == pytest.approx(float(i == j), abs=1e-9)


def test_matches_scipy_classical_polynomials():
    """Normalised scipy.special polynomials are the same functions."""
    x = np.linspace(-0.95, 0.95, 11)
    legendre = Legendre().evaluate(x, 6)
    for k in range(7):
        np.testing.assert_allclose(legendre[:, k], np.sqrt(2 * k + 1) * sp.eval_legendre(k, x))
    hermite = Hermite().evaluate(3 * x, 6)
    for k in range(7):
        expected = sp.eval_hermitenorm(k, 3 * x) / np.sqrt(sp.factorial(k))
        np.testing.assert_allclose(hermite[:, k], expected, atol=1e-12)
    laguerre = Laguerre(0.0).evaluate(4 + 4 * x, 6)
    for k in range(7):
        # Laguerre polynomials L_k are orthonormal for e^{-x} up to sign (-1)^k.
        np.testing.assert_allclose(
            laguerre[:, k], (-1) ** k * sp.eval_laguerre(k, 4 + 4 * x), atol=1e-11
        )


def test_evaluate_is_vectorised_over_any_shape():
    x = np.zeros((2, 3, 4))
    assert Legendre().evaluate(x, 5).shape == (2, 3, 4, 6)


def test_invalid_arguments_are_rejected():
    with pytest.raises(ValueError, match="degree"):
        Legendre().evaluate([0.0], -1)
    with pytest.raises(ValueError, match="at least one point"):
        Hermite().gauss_rule(0)
    with pytest.raises(ValueError, match="> -1"):
        Jacobi(-1.0, 0.0)
    with pytest.raises(ValueError, match="> -1"):
        Laguerre(-2.0)


@pytest.mark.parametrize("family", FAMILIES, ids=repr)
def test_numpy_draws_equal_the_scipy_germ_draws(family):
    """The fast numpy sampler is the scipy.stats germ's rvs, draw for draw."""
    ours = family.sample(1000, np.random.default_rng(3))
    theirs = family.germ.rvs(size=1000, random_state=np.random.default_rng(3))
    np.testing.assert_allclose(ours, theirs, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize(
    "family", [Legendre(), Jacobi(1.5, 0.5), Hermite(), Laguerre(2.0)], ids=lambda f: repr(f)
)
def test_the_quantile_is_the_germs_inverse_cdf(family):
    # Against scipy.stats' ppf of the same germ (which the quantile avoids importing).
    u = np.linspace(0.001, 0.999, 41)
    assert family.quantile(u) == pytest.approx(family.germ.ppf(u), rel=1e-12, abs=1e-14)
    assert family.germ.cdf(family.quantile(u)) == pytest.approx(u, rel=1e-12)
