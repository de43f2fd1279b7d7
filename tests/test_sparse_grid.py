"""Smolyak sparse grids: nested rules, exact recovery, convergence, node counts, the design."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from pcmb.chaos.basis import PolynomialBasis
from pcmb.chaos.inputs import Beta, Gamma, Normal, Uniform
from pcmb.chaos.nested import (
    ClenshawCurtis,
    Leja,
    LejaContinued,
    gauss_patterson,
    genz_keister,
    interpolatory_weights,
    nested_rule,
)
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.polynomials import Hermite, Jacobi, Laguerre, Legendre
from pcmb.chaos.sparse import (
    SparseGrid,
    combination_coefficients,
    project_sparse,
    smolyak_index_set,
)
from pcmb.designs.base import MethodSettings
from pcmb.designs.smolyak import SparseCollocation
from pcmb.references import (
    gamma_moment,
    ishigami,
    ishigami_moments,
    jacobi_moment,
    normal_moment,
    uniform_moment,
)
from pcmb.result import Design

# -- 1. nested rules ------------------------------------------------------------------------

RULE_CASES = [
    (ClenshawCurtis(), 7, uniform_moment),
    (gauss_patterson(), 4, uniform_moment),
    (genz_keister(), 4, normal_moment),
    (LejaContinued(gauss_patterson()), 6, uniform_moment),
    (LejaContinued(genz_keister()), 6, normal_moment),
    (Leja(Legendre()), 12, uniform_moment),
    (Leja(Hermite()), 12, normal_moment),
    (Leja(Jacobi(1.0, 2.5)), 12, lambda m: jacobi_moment(m, 1.0, 2.5)),
    (Leja(Laguerre(2.0)), 12, lambda m: gamma_moment(m, 2.0)),
]


@pytest.mark.parametrize(
    ("rule", "top", "moment"), RULE_CASES, ids=[repr(rule)[:30] for rule, _, _ in RULE_CASES]
)
def test_nested_rules_are_nested_and_exact_to_their_degree(rule, top, moment):
    """Level l's nodes are the first m_l of level l + 1's; E[p_j] = δ_j0 for j <= e_l (the
    orthonormal basis has E[p_0] = 1 and E[p_j] = 0), and the raw moments E[ξ^m] from the
    closed forms in pcmb.references, for m <= min(e_l, 12). The rules are computed by linear
    solves with condition numbers below ~1e3 (Kronrod–Patterson extensions, interpolatory
    weights): 1e-12 is ~5000 ulps. Monomials are compared relative to E[|ξ|^m] ~ E[ξ^m]."""
    for level in range(top + 1):
        nodes, weights = rule.nodes(level), rule.weights(level)
        assert nodes.shape == weights.shape == (rule.size(level),)
        assert abs(weights.sum() - 1.0) < 1e-13
        assert np.min(np.diff(np.sort(nodes)), initial=1.0) > 1e-6, "nodes must be distinct"
        if level < top:
            np.testing.assert_array_equal(rule.nodes(level + 1)[: nodes.size], nodes)
        exact = rule.exactness(level)
        integrals = weights @ rule.family.evaluate(nodes, exact + 1)
        np.testing.assert_allclose(integrals[: exact + 1], np.eye(1, exact + 1)[0], atol=1e-12)
        if not isinstance(rule, Leja | LejaContinued):
            # The stated degree is sharp: the next one is not integrated.
            assert abs(integrals[exact + 1]) > 1e-9
        for m in range(min(exact, 12) + 1):
            scale = max(1.0, abs(weights) @ np.abs(nodes) ** m)
            assert abs(weights @ nodes**m - moment(m)) < 1e-12 * scale


def test_patterson_and_genz_keister_nodes_match_the_published_tables():
    """Patterson (1968) 7-point rule; Genz & Keister (1996) 9-point rule, there for the
    weight e^{-x²} (nodes x √2 for the standard normal)."""
    seven = np.sort(gauss_patterson().nodes(2))
    published = [0.960491268708020283, 0.774596669241483377, 0.434243749346802558, 0.0]
    np.testing.assert_allclose(seven[3:][::-1], published, atol=1e-15)
    nine = np.sort(genz_keister().nodes(2))
    published = [
        0.0,
        0.52403354748695763,
        1.2247448713915889,
        2.0232301911005157,
        2.959210779063838,
    ]
    np.testing.assert_allclose(nine[4:], np.sqrt(2.0) * np.array(published), rtol=1e-14)


def test_auto_rules_and_their_limits():
    assert nested_rule(Legendre()).name == "gauss-patterson"
    continued = nested_rule(Legendre(), level=5)
    assert isinstance(continued, LejaContinued) and continued.base.name == "gauss-patterson"
    # The continuation keeps the Gauss-Patterson levels, so no level loses exactness.
    np.testing.assert_array_equal(continued.nodes(4), gauss_patterson().nodes(4))
    assert continued.exactness(5) > gauss_patterson().exactness(4)
    assert nested_rule(Hermite()).name == "genz-keister"
    assert nested_rule(Hermite(), level=5).base.name == "genz-keister"
    assert nested_rule(Laguerre(1.0)).name == "leja"
    with pytest.raises(ValueError, match="for normal inputs"):
        nested_rule(Legendre(), "genz-keister")
    with pytest.raises(ValueError, match=r"levels 0\.\.4"):
        nested_rule(Legendre(), "gauss-patterson", level=5)
    with pytest.raises(ValueError, match="unknown rule"):
        nested_rule(Legendre(), "trapezoid")


# -- 2. exactness of the sparse pseudo-spectral projection ----------------------------------

EXACT_CASES = [
    ([Uniform(-1.0, 1.0)] * 2, 4, "auto", None),
    ([Uniform(0.0, 2.0)] * 3, 3, "clenshaw-curtis", None),
    ([Normal(1.0, 2.0)] * 2, 3, "auto", None),
    (
        [Uniform(0.0, 1.0), Normal(0.0, 1.0), Gamma(2.0, 1.0), Beta(2.0, 3.0, 0.0, 1.0)],
        3,
        "auto",
        None,
    ),
    ([Uniform(0.0, 1.0), Normal(2.0, 0.5), Uniform(-1.0, 1.0)], 5, "leja", (1.0, 2.0, 2.5)),
]


def _random_expansion_values(grid, seed):
    coefficients = np.random.default_rng(seed).standard_normal((grid.multi_index.shape[0], 3))
    families = tuple(d.family for d in grid.distributions)
    basis = PolynomialBasis(families, grid.multi_index).evaluate(grid.nodes)
    return coefficients, basis @ coefficients


@pytest.mark.parametrize(("dists", "level", "rule", "weights"), EXACT_CASES)
def test_every_polynomial_of_the_exact_set_is_recovered(dists, level, rule, weights):
    """Proof of the exact set: random coefficients on every term of ``multi_index``, values at
    the nodes, recovered to round-off (the values are O(10²) at most: 1e-10 is ~1e4 ulps of
    them). Naive quadrature Σ_i w_i y_i φ_α(ξ_i) on the same nodes aliases."""
    grid = SparseGrid.smolyak(dists, level, rule, weights)
    coefficients, values = _random_expansion_values(grid, seed=level)
    expansion = project_sparse(grid, values)
    np.testing.assert_allclose(expansion.coefficients, coefficients, atol=1e-10)
    families = tuple(d.family for d in dists)
    basis = PolynomialBasis(families, grid.multi_index).evaluate(grid.nodes)
    naive = basis.T @ (grid.weights[:, None] * values)
    assert np.max(np.abs(naive - coefficients)) > 1e-3


def test_an_arbitrary_downward_closed_set_is_exact_and_checked():
    index = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [0, 1], [1, 1], [0, 2]])
    dists = [Uniform(-1.0, 1.0), Normal(0.0, 1.0)]
    rules = (nested_rule(Legendre(), "clenshaw-curtis"), nested_rule(Hermite(), "leja"))
    grid = SparseGrid(dists, index, rules)
    coefficients, values = _random_expansion_values(grid, seed=7)
    np.testing.assert_allclose(grid.project(values), coefficients, atol=1e-10)
    with pytest.raises(ValueError, match="not downward closed"):
        SparseGrid(dists, np.array([[0, 0], [0, 2]]), rules)


def test_combination_coefficients_match_the_smolyak_formula():
    """Isotropic level L in n inputs: c_i = (-1)^(L-|i|) C(n-1, L-|i|) for L-n+1 <= |i| <= L."""
    from math import comb

    n, level = 4, 5
    index = smolyak_index_set(n, level)
    gap = level - index.sum(axis=1)
    expected = np.where(gap <= n - 1, (-1) ** gap * np.array([comb(n - 1, g) for g in gap]), 0)
    np.testing.assert_array_equal(combination_coefficients(index), expected)


# -- 3. convergence on functions with closed-form statistics --------------------------------


def test_ishigami_statistics_converge():
    """Ishigami on U[-π, π]³. The Gauss–Patterson levels 2, 3, 4 resolve degrees 2, 5, 11 per
    axis; the Clenshaw–Curtis level 7 resolves x1 to degree 8 while x3 holds degree 4 (the
    interaction b x3⁴ sin x1). The Legendre coefficients of sin(πξ) fall like (π/2)^k / k!:
    ≈ 1e-4 at k = 9, so the error of the variance at level 7 is ~(1e-4)² relative: 1e-7."""
    reference = ishigami_moments()
    errors = []
    for level, rule in [(2, "auto"), (3, "auto"), (4, "auto"), (7, "clenshaw-curtis")]:
        grid = SparseGrid.smolyak([Uniform(-np.pi, np.pi)] * 3, level, rule)
        expansion = project_sparse(grid, ishigami(grid.params))
        errors.append(
            (
                abs(expansion.mean() - reference.mean),
                abs(expansion.variance() / reference.variance - 1.0),
                np.max(np.abs(expansion.sobol_first() - reference.first)),
            )
        )
    errors = np.array(errors)
    assert np.all(np.diff(errors[:, 1]) < 0) and np.all(np.diff(errors[:, 2]) < 0)
    # The mean needs sin² x2 only to degree 2 per factor: exact from level 3 on.
    assert np.all(errors[1:, 0] < 1e-12)
    assert errors[2, 1] < 1e-3 and errors[2, 2] < 1e-3
    assert errors[3, 1] < 1e-7 and errors[3, 2] < 1e-7


def test_anisotropic_exponential_converges():
    """y = exp(a·x), x1, x2 ~ U[-1, 1], x3, x4 ~ N(0, 1), a = (1, 0.5, 0.3, 0.1): mean Π m_k,
    E[y²] = Π s_k with m = sinh(a)/a, s = sinh(2a)/(2a) (uniform), m = e^{a²/2}, s = e^{2a²}
    (normal); V_k = (s_k - m_k²) Π_{j≠k} m_j². Weights (1, 1.25, 1.5, 2) give the weaker
    inputs fewer levels. Coefficients of exp(aξ) fall like a^k / k!: at level 6 the inputs
    reach degrees ≥ (23, 11, 15, 7), whose tails are below 1e-8 in every input, but the
    interactions are cut at lower degrees: 1e-5 on the variance is a safe bound, and each
    level must reduce the error."""
    a = np.array([1.0, 0.5, 0.3, 0.1])
    dists = [Uniform(-1.0, 1.0), Uniform(-1.0, 1.0), Normal(0.0, 1.0), Normal(0.0, 1.0)]
    m = np.array([*(np.sinh(a[:2]) / a[:2]), *np.exp(a[2:] ** 2 / 2)])
    s = np.array([*(np.sinh(2 * a[:2]) / (2 * a[:2])), *np.exp(2 * a[2:] ** 2)])
    mean, variance = m.prod(), s.prod() - m.prod() ** 2
    first = np.array([(s[k] - m[k] ** 2) * np.prod(np.delete(m, k) ** 2) for k in range(4)])
    errors = []
    for level in range(2, 7):
        grid = SparseGrid.smolyak(dists, level, weights=(1.0, 1.25, 1.5, 2.0))
        expansion = project_sparse(grid, np.exp(grid.params @ a))
        errors.append(
            (
                abs(expansion.mean() / mean - 1.0),
                abs(expansion.variance() / variance - 1.0),
                np.max(np.abs(expansion.sobol_first() - first / variance)),
            )
        )
    errors = np.array(errors)
    assert np.all(np.diff(errors, axis=0) < 0)
    assert errors[-1, 0] < 1e-6 and errors[-1, 1] < 1e-5 and errors[-1, 2] < 1e-5


# -- 4. node counts and weights -------------------------------------------------------------


@pytest.mark.parametrize(
    ("n", "level", "count"), [(2, 1, 5), (2, 2, 13), (2, 3, 29), (2, 4, 65), (10, 2, 221)]
)
def test_clenshaw_curtis_node_counts_are_the_known_ones(n, level, count):
    grid = SparseGrid.smolyak([Uniform(0.0, 1.0)] * n, level, "clenshaw-curtis")
    assert grid.size == count
    assert grid.nodes.shape == (count, n)
    assert np.unique(np.round(grid.nodes, 12), axis=0).shape[0] == count


def test_sparse_weights_sum_to_one_and_integrate_their_exact_space():
    """The combined rule integrates φ_α exactly when some tensor rule does (α_k <= e(i_k))."""
    dists = [Uniform(0.0, 1.0), Normal(0.0, 1.0), Gamma(3.0, 1.0)]
    grid = SparseGrid.smolyak(dists, 3)
    assert abs(grid.weights.sum() - 1.0) < 1e-13 and grid.weights.min() < 0
    exact = [
        np.indices(
            [rule.exactness(int(top)) + 1 for rule, top in zip(grid.rules, row, strict=True)]
        )
        .reshape(3, -1)
        .T
        for row in grid.index_set
    ]
    terms = np.unique(np.concatenate(exact), axis=0)
    basis = PolynomialBasis(tuple(d.family for d in dists), terms).evaluate(grid.nodes)
    expected = (~terms.any(axis=1)).astype(float)
    np.testing.assert_allclose(grid.weights @ basis, expected, atol=1e-11)


# -- 5. the design --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Settings(MethodSettings):
    """MethodSettings with the sparse-grid keys the config will add."""

    level: int | None = None
    rule: str = "auto"


INPUTS = {"a": Uniform(1.0, 3.0), "b": Normal(0.5, 0.2), "c": Gamma(2.0, 0.5)}


def test_the_design_follows_the_node_design_protocol():
    design = SparseCollocation(INPUTS, _Settings("smolyak", level=3))
    nodes = design.nodes()
    assert design.runs == nodes.size == nodes.nodes.shape[0]
    for k, dist in enumerate(INPUTS.values()):
        np.testing.assert_allclose(nodes.params[:, k], dist.to_physical(nodes.nodes[:, k]))
    weights = design.weights(nodes)
    assert weights.shape == (nodes.size,) and abs(weights.sum() - 1.0) < 1e-12
    record = design.record()
    assert (record.kind, record.grid, record.level, record.fit) == (
        "smolyak",
        "smolyak",
        3,
        "projection",
    )
    assert Design.from_description(record.describe()) == record

    times = np.linspace(0.0, 1.0, 4)
    a, b, c = nodes.params.T
    values = {
        "y": (2.0 + 3.0 * a - b + c)[:, None] * (1.0 + times),
        "flat": 0.0 * a[:, None] + times,
    }
    mean = 2.0 + 3.0 * 2.0 - 0.5 + 1.0
    std = np.sqrt(9.0 * 4.0 / 12.0 + 0.2**2 + 2.0 * 0.5**2)
    recovery = design.recover(nodes, values, np.ones(nodes.size, dtype=bool), times)
    np.testing.assert_allclose(recovery.expansions["y"].mean(), mean * (1.0 + times), rtol=1e-12)
    np.testing.assert_allclose(recovery.expansions["y"].std(), std * (1.0 + times), rtol=1e-10)
    assert [w.code for w in recovery.warnings] == ["sobol-undefined"]

    ok = np.ones(nodes.size, dtype=bool)
    ok[[1, 5]] = False
    refit = design.recover(nodes, values, ok, times)
    assert refit.warnings[0].code == "least-squares-fit"
    np.testing.assert_allclose(refit.expansions["y"].mean(), mean * (1.0 + times), rtol=1e-10)


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        (_Settings("smolyak"), "method.level"),
        (_Settings("smolyak", level=-1), "method.level"),
        (_Settings("smolyak", level=30, rule="leja"), "method.level"),
        (_Settings("smolyak", level=2, rule="simpson"), "method.rule"),
        (_Settings("smolyak", level=2, rule="genz-keister"), "method.rule"),
        (_Settings("smolyak", level=2, orders=(2, 2, 2)), "method.order"),
    ],
)
def test_unusable_settings_name_their_key(settings, key):
    with pytest.raises(ValueError, match=rf"^{key}:"):
        SparseCollocation(INPUTS, settings)


@pytest.mark.parametrize("dist", [Normal(0.0, 1.0), Uniform(-1.0, 1.0), Gamma(2.0, 1.0)])
def test_interpolatory_weights_on_gauss_nodes_are_the_gauss_weights(dist):
    # N Gauss nodes carry one interpolatory rule: Gauss's (exact to degree 2N - 1).
    grid = TensorGrid((dist,), (9,))
    found = interpolatory_weights(dist.family, grid.nodes[:, 0])
    np.testing.assert_allclose(found, grid.weights, rtol=1e-10, atol=1e-14)
