"""Nested one-dimensional quadrature rules in the germ space, for Smolyak sparse grids.

A nested rule is a sequence of rules indexed by a level l = 0, 1, 2, ... whose nodes are
nested: the m_l nodes of level l are the first m_l points of one sequence, and every level
adds points to the previous one. Each level carries its *growth* (m_l points) and its
*exactness* e_l: the rule integrates every polynomial of degree <= e_l exactly under the
germ's probability measure. Weights are probability weights (they sum to one) and may be
negative for Leja rules.

| rule                  | family   | points m_l                    | exactness e_l             |
|-----------------------|----------|-------------------------------|---------------------------|
| ``clenshaw-curtis``   | Legendre | 1, 3, 5, 9, ..., 2^l + 1      | m_l (odd m, by symmetry)  |
| ``gauss-patterson``   | Legendre | 1, 3, 7, ..., 2^(l+1) - 1     | 1, 5, 11, ..., 3·2^l - 1  |
| ``genz-keister``      | Hermite  | 1, 3, 9, 19, 35               | 1, 5, 15, 29, 51          |
| ``leja``              | any      | 2l + 1                        | 2l                        |
| ``auto``, l > 4       | Leg./Her.| 2 m_(l-1) + 1                 | m_l - 1                   |

Gauss–Patterson (Patterson, Math. Comp. 22, 1968) and Genz–Keister (Genz & Keister,
J. Comput. Appl. Math. 71, 1996) rules are computed rather than tabulated: both are
Kronrod–Patterson extensions. Given the m nodes of the previous level, with node polynomial
K(x) = Π (x - x_i), the k added nodes are the roots of the degree-k polynomial orthogonal to
all lower degrees under the signed measure K(x) dμ(x); the interpolatory rule on the m + k
nodes is then exact to degree m + 2k - 1, and to m + 2k for the symmetric measures here.
Gauss–Patterson adds k = m + 1 nodes per level from the 1-point rule; Genz–Keister adds 2, 6,
10, 16 (the sequence 1, 3, 9, 19, 35 of Genz & Keister's Table 3, the one in Burkardt's and
chaospy's ``genz_keister_18`` tables; the paper's further rules of 37, 41 and 43 points
trade degree for positivity and are not of this form, so this rule stops at level 4).
Both are computed in double precision from the previous level's nodes; Gauss–Patterson
stops at level 4 (31 points, degree 47), where the extension is still exact to ~1e-14 (at
63 points its linear system loses digits: 5e-12).

``auto`` continues Gauss–Patterson past level 4 and Genz–Keister past level 4 with weighted
Leja points grown from their nodes (the Leja search starts from the rule's last level, so the
sequence stays nested), doubling the points per level like Gauss–Patterson, for
:data:`CONTINUED_LEVELS` levels (127 and 143 points); the continued levels are interpolatory,
exact to degree m_l - 1. Higher levels take ``rule: clenshaw-curtis`` or ``leja``.
Switching the whole sequence to another rule instead (Clenshaw–Curtis or Leja from the start)
would make every level of that input less exact: a level-5 grid was then less accurate than
the level-4 one.

Weighted Leja sequences (Narayan & Jakeman, SIAM J. Sci. Comput. 36, 2014) serve any
family: x_0 is the germ's mean, then x_n maximises √w(x) Π_{j<n} |x - x_j| over the support,
w the germ density. Level l takes the first 2l + 1 points, so the projection degree grows by
one per level. Every rule's weights are interpolatory: the solution of Σ_i w_i p_j(x_i) =
δ_j0 for the orthonormal p_0..p_{m-1} (Clenshaw–Curtis: its closed form).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.polynomials import Hermite, Legendre, OrthonormalFamily

__all__ = [
    "RULES",
    "ClenshawCurtis",
    "KronrodPatterson",
    "Leja",
    "LejaContinued",
    "NestedRule",
    "gauss_patterson",
    "genz_keister",
    "leja_sequence",
    "nested_rule",
]

#: Names accepted by :func:`nested_rule` (``method.rule``).
RULES = ("auto", "clenshaw-curtis", "gauss-patterson", "genz-keister", "leja")
#: Highest Gauss–Patterson level computed (511 points): its extension stays accurate to
#: round-off up to here (checked by the tests).
PATTERSON_LEVELS = 4
#: Points added per Genz–Keister level: 1, 3, 9, 19, 35 points.
GENZ_KEISTER_ADDED = (2, 6, 10, 16)
#: Length of every Leja sequence (its levels are its prefixes): level <= 20.
LEJA_POINTS = 41
#: Levels ``auto`` adds by Leja points after the last Gauss–Patterson / Genz–Keister level.
CONTINUED_LEVELS = 2
#: Candidate points of the Leja search before local refinement.
_LEJA_CANDIDATES = 4001


class NestedRule(ABC):
    """A nested sequence of 1-D quadrature rules for one germ's probability measure.

    Level l has :meth:`size` points, the first ones of :attr:`sequence`, and integrates
    polynomials of degree <= :meth:`exactness` exactly.
    """

    family: OrthonormalFamily
    #: Name of the rule (one of :data:`RULES`).
    name: str

    @property
    @abstractmethod
    def max_level(self) -> int | None:
        """Highest level available (``None``: unbounded)."""

    @abstractmethod
    def size(self, level: int) -> int:
        """Number of points m_l of level l."""

    @abstractmethod
    def exactness(self, level: int) -> int:
        """Highest polynomial degree e_l integrated exactly by level l."""

    @abstractmethod
    def _sequence(self, count: int) -> NDArray[np.float64]:
        """The first ``count`` points of the nested sequence."""

    def projection_degree(self, level: int) -> int:
        """Highest degree p_l whose products p_i p_j (i, j <= p_l) level l integrates exactly."""
        return self.exactness(level) // 2

    def nodes(self, level: int) -> NDArray[np.float64]:
        """(m_l,) nodes of level l, in the order the levels introduce them."""
        self._check(level)
        return self._sequence(self.size(level))

    def weights(self, level: int) -> NDArray[np.float64]:
        """(m_l,) probability weights of level l, aligned with :meth:`nodes` (read-only)."""
        return _weights(self, level)

    def projector(self, level: int) -> NDArray[np.float64]:
        """(p_l + 1, m_l) the 1-D pseudo-spectral projection of level l, Vᵀ W: it maps values
        at :meth:`nodes` to the coefficients of p_0..p_l (read-only)."""
        return _projector(self, level)

    def difference(self, level: int) -> NDArray[np.float64]:
        """(p_l + 1, m_l) the 1-D surplus operator P_l - P_{l-1} (P_{-1} = 0): the projection
        of level l minus that of level l - 1, which reads the first m_{l-1} nodes and yields
        the first p_{l-1} + 1 degrees (read-only)."""
        return _difference(self, level)

    def _weights(self, level: int) -> NDArray[np.float64]:
        """Interpolatory weights of a level (:func:`interpolatory_weights`)."""
        return interpolatory_weights(self.family, self.nodes(level))

    def _check(self, level: int) -> None:
        if level < 0:
            raise ValueError(f"levels start at 0, got {level}")
        if self.max_level is not None and level > self.max_level:
            raise ValueError(f"the {self.name} rule has levels 0..{self.max_level}, asked {level}")


@dataclass(frozen=True)
class ClenshawCurtis(NestedRule):
    """Clenshaw–Curtis rules for the uniform germ: m_l = 2^l + 1 Chebyshev extrema (m_0 = 1).

    The nodes are sin(π i / 2^l), i = -2^(l-1)..2^(l-1), computed so that every level
    reproduces the previous level's nodes bit for bit.
    """

    family: OrthonormalFamily = field(default_factory=Legendre)
    name: str = "clenshaw-curtis"

    def __post_init__(self) -> None:
        _require_family(self.family, Legendre, self.name)

    @property
    def max_level(self) -> None:
        return None

    def size(self, level: int) -> int:
        return 1 if level == 0 else 2**level + 1

    def exactness(self, level: int) -> int:
        return self.size(level)

    def _sequence(self, count: int) -> NDArray[np.float64]:
        points = [0.0]
        level = 0
        while len(points) < count:
            level += 1
            half = 2 ** (level - 1)
            new = np.arange(-half, half + 1)
            new = new[new % 2 != 0]
            points.extend(np.sin(np.pi * new / 2**level))
        return np.array(points[:count])

    def _weights(self, level: int) -> NDArray[np.float64]:
        """The closed form (Waldvogel, BIT 46, 2006) in O(m²), halved for the probability
        measure: w(θ) = c/n (1 - Σ_{k=1}^{n/2} b_k cos(2kθ) / (4k² - 1)), x = cos θ, n = m - 1,
        c = 1 at the ends and 2 inside, b_k = 2 except b_{n/2} = 1."""
        nodes = self.nodes(level)
        if nodes.size == 1:
            return np.ones(1)
        n = nodes.size - 1
        k = np.arange(1, n // 2 + 1)
        b = np.where(k == n // 2, 1.0, 2.0)
        theta = np.arccos(np.clip(nodes, -1.0, 1.0))
        series = np.cos(2.0 * np.outer(theta, k)) @ (b / (4.0 * k**2 - 1.0))
        ends = np.isclose(np.abs(nodes), 1.0, rtol=0.0, atol=1e-15)
        return np.where(ends, 1.0, 2.0) / n * (1.0 - series) / 2.0


@dataclass(frozen=True)
class KronrodPatterson(NestedRule):
    """Nested rules grown from the 1-point rule by Kronrod–Patterson extensions.

    Level l adds ``added[l - 1]`` nodes to level l - 1 (see the module notes); build the
    named rules with :func:`gauss_patterson` and :func:`genz_keister`.
    """

    family: OrthonormalFamily
    name: str
    added: tuple[int, ...]

    @property
    def max_level(self) -> int:
        return len(self.added)

    def size(self, level: int) -> int:
        return 1 + sum(self.added[:level])

    def exactness(self, level: int) -> int:
        return 1 if level == 0 else self.size(level - 1) + 2 * self.added[level - 1]

    def _sequence(self, count: int) -> NDArray[np.float64]:
        return _extensions(self.family, self.added)[:count]


def gauss_patterson(levels: int = PATTERSON_LEVELS) -> KronrodPatterson:
    """Gauss–Patterson rules (uniform germ): 1, 3, 7, ..., 2^(levels+1) - 1 points."""
    return KronrodPatterson(
        Legendre(), "gauss-patterson", tuple(2**level for level in range(1, levels + 1))
    )


def genz_keister() -> KronrodPatterson:
    """Genz–Keister rules (standard normal germ): 1, 3, 9, 19, 35 points."""
    return KronrodPatterson(Hermite(), "genz-keister", GENZ_KEISTER_ADDED)


@dataclass(frozen=True)
class LejaContinued(NestedRule):
    """A Kronrod–Patterson rule continued past its last level by weighted Leja points.

    Levels up to ``base.max_level`` are the base rule's; each further level doubles the points
    plus one (as Gauss–Patterson does), with the Leja points that extend the previous ones.
    Those levels are interpolatory, exact to degree m_l - 1.
    """

    base: KronrodPatterson
    name: str = "auto"

    @property
    def family(self) -> OrthonormalFamily:  # type: ignore[override]
        return self.base.family

    @property
    def max_level(self) -> int:
        return self.base.max_level + CONTINUED_LEVELS

    def size(self, level: int) -> int:
        if level <= self.base.max_level:
            return self.base.size(level)
        return 2 * self.size(level - 1) + 1

    def exactness(self, level: int) -> int:
        if level <= self.base.max_level:
            return self.base.exactness(level)
        return self.size(level) - 1

    def _sequence(self, count: int) -> NDArray[np.float64]:
        base = self.base.nodes(self.base.max_level)
        if count <= base.size:
            return base[:count]
        total = self.size(self.max_level)
        return leja_sequence(self.family, tuple(base), total)[:count]


@dataclass(frozen=True)
class Leja(NestedRule):
    """Weighted Leja rules for any family: level l has the first 2l + 1 Leja points.

    The rule is interpolatory on its own points only, exact to degree 2l; its weights can be
    negative.
    """

    family: OrthonormalFamily
    name: str = "leja"

    @property
    def max_level(self) -> int:
        return (LEJA_POINTS - 1) // 2

    def size(self, level: int) -> int:
        return 2 * level + 1

    def exactness(self, level: int) -> int:
        return 2 * level

    def _sequence(self, count: int) -> NDArray[np.float64]:
        return leja_sequence(self.family, (), LEJA_POINTS)[:count]


def nested_rule(family: OrthonormalFamily, rule: str = "auto", level: int = 0) -> NestedRule:
    """The nested rule named ``rule`` for a germ family, with at least ``level`` levels.

    ``auto`` picks Gauss–Patterson for the uniform germ and Genz–Keister for the normal germ,
    each continued by Leja points past its level 4 (:class:`LejaContinued`), and Leja for
    every other family.

    Raises
    ------
    ValueError
        An unknown rule, a rule that does not fit the family, or a level the rule lacks.
    """
    if rule == "auto":
        if isinstance(family, Legendre | Hermite):
            base = gauss_patterson() if isinstance(family, Legendre) else genz_keister()
            made: NestedRule = base if level <= base.max_level else LejaContinued(base)
            made._check(level)
            return made
        rule = "leja"
    if rule == "clenshaw-curtis":
        made = ClenshawCurtis(family)
    elif rule == "gauss-patterson":
        _require_family(family, Legendre, rule)
        made = gauss_patterson()
    elif rule == "genz-keister":
        _require_family(family, Hermite, rule)
        made = genz_keister()
    elif rule == "leja":
        made = Leja(family)
    else:
        raise ValueError(f"unknown rule {rule!r}: expected one of {', '.join(RULES)}")
    made._check(level)
    return made


def _require_family(family: OrthonormalFamily, kind: type, rule: str) -> None:
    if not isinstance(family, kind):
        germ = "uniform" if kind is Legendre else "normal"
        raise ValueError(f"the {rule} rule is for {germ} inputs, not {type(family).__name__}")


def interpolatory_weights(family: OrthonormalFamily, nodes: ArrayLike) -> NDArray[np.float64]:
    """(m,) probability weights of the interpolatory rule on m germ ``nodes``: they integrate
    p_0..p_{m-1} exactly, Vᵀ w = e_0. Solved for w / √(germ density), as the weighted Leja
    points are chosen: the same weights, but well conditioned."""
    nodes = np.asarray(nodes, dtype=float)
    root = np.sqrt(family.germ.pdf(nodes))
    basis = root[:, None] * family.evaluate(nodes, nodes.size - 1)
    return root * np.linalg.solve(basis.T, np.eye(nodes.size)[0])


@cache
def _weights(rule: NestedRule, level: int) -> NDArray[np.float64]:
    weights = rule._weights(level)
    weights.setflags(write=False)
    return weights


@cache
def _projector(rule: NestedRule, level: int) -> NDArray[np.float64]:
    basis = rule.family.evaluate(rule.nodes(level), rule.projection_degree(level))
    projector = (basis * rule.weights(level)[:, None]).T
    projector.setflags(write=False)
    return projector


@cache
@cache
def _difference(rule: NestedRule, level: int) -> NDArray[np.float64]:
    difference = rule.projector(level).copy()
    if level > 0:
        coarse = rule.projector(level - 1)
        difference[: coarse.shape[0], : coarse.shape[1]] -= coarse
    difference.setflags(write=False)
    return difference


@cache
def _extensions(family: OrthonormalFamily, added: tuple[int, ...]) -> NDArray[np.float64]:
    """The point sequence 0-level node (the mean), then each extension's nodes in turn
    (read-only: computed once per family, shared by every design)."""
    points = np.array([family.recurrence(1)[0][0]])
    for count in added:
        points = np.concatenate([points, _extend(family, points, count)])
    points.setflags(write=False)
    return points


def _extend(
    family: OrthonormalFamily, nodes: NDArray[np.float64], count: int
) -> NDArray[np.float64]:
    """The ``count`` Kronrod–Patterson nodes that extend ``nodes`` (sorted, real).

    q = p_k + Σ_{i<k} c_i p_i with ∫ q p_j K dμ = 0 for j < k (K the node polynomial, the
    integrals by a Gauss rule exact for them); its roots are the eigenvalues of the Jacobi
    matrix whose last row is corrected by q's coefficients (the comrade matrix).

    Raises
    ------
    ValueError
        If the extension has complex nodes (it does not exist).
    """
    k = count
    gauss = family.gauss_rule((2 * k + nodes.size) // 2 + 1)
    node_poly = np.prod(gauss.nodes[:, None] - nodes[None, :], axis=1)
    measure = gauss.weights * node_poly / np.max(np.abs(node_poly))
    basis = family.evaluate(gauss.nodes, k)
    gram = (basis[:, :k] * measure[:, None]).T @ basis
    coef = np.linalg.solve(gram[:, :k], -gram[:, k])
    a, b = family.recurrence(k + 1)
    root_b = np.sqrt(b)
    comrade = np.diag(a[:k]) + np.diag(root_b[1:k], 1) + np.diag(root_b[1:k], -1)
    comrade[k - 1] -= root_b[k] * coef
    roots = np.linalg.eigvals(comrade)
    if np.max(np.abs(roots.imag), initial=0.0) > 1e-8:
        raise ValueError(f"no real extension of {nodes.size} nodes by {k}")
    return _polish(family, np.sort(roots.real), coef)


def _polish(
    family: OrthonormalFamily, roots: NDArray[np.float64], coef: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Two Newton steps on q = p_k + Σ c_i p_i (derivative by the recurrence)."""
    k = coef.size
    weights = np.append(coef, 1.0)
    a, b = family.recurrence(k + 1)
    root_b = np.sqrt(b)
    for _ in range(2):
        value = family.evaluate(roots, k)
        slope = np.zeros_like(value)
        # d/dx of √b_{j+1} p_{j+1} = (x - a_j) p_j - √b_j p_{j-1}
        for j in range(k):
            previous = slope[:, j - 1] if j else 0.0
            slope[:, j + 1] = (
                value[:, j] + (roots - a[j]) * slope[:, j] - root_b[j] * previous
            ) / root_b[j + 1]
        roots = roots - (value @ weights) / (slope @ weights)
    return roots


@cache
def leja_sequence(
    family: OrthonormalFamily, start: tuple[float, ...], count: int
) -> NDArray[np.float64]:
    """``count`` weighted Leja points of a family (see the module notes): ``start``, then the
    points that extend it (from the germ's mean when ``start`` is empty)."""
    from scipy.optimize import minimize_scalar  # deferred: only Leja rules need it

    germ = family.germ
    low, high = family.support
    reach = 2.0 * np.max(np.abs(family.gauss_rule(2 * count).nodes))
    low, high = max(low, -reach), min(high, reach)
    candidates = np.unique(
        np.concatenate(
            [
                np.linspace(low, high, _LEJA_CANDIDATES),
                family.gauss_rule(4 * count).nodes,
            ]
        )
    )

    def objective(x: NDArray[np.float64], points: list[float]) -> NDArray[np.float64]:
        x = np.asarray(x, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = 0.5 * germ.logpdf(x) + np.sum(
                np.log(np.abs(x[..., None] - np.array(points))), axis=-1
            )
        return np.where(np.isnan(value), -np.inf, value)

    points = list(start) or [float(family.recurrence(1)[0][0])]
    while len(points) < count:
        scores = objective(candidates, points)
        best = int(np.argmax(scores))
        left = candidates[max(best - 1, 0)]
        right = candidates[min(best + 1, candidates.size - 1)]
        refined = minimize_scalar(
            lambda x: -float(objective(x, points)),
            bounds=(left, right),
            method="bounded",
            options={"xatol": 1e-14 * max(1.0, abs(candidates[best]))},
        )
        better = refined.success and -refined.fun > scores[best]
        points.append(float(refined.x) if better else float(candidates[best]))
    return np.array(points)
