"""Benchmark of sparse chaos regression (LARS, OMP) against plain least squares.

1. Runs (Sobol' points, 2^m) needed for a relative variance error of 1e-2 and 1e-4 on
   Ishigami (3 inputs, closed form) and Borehole (8 uniform inputs, reference from a 7^8
   Gauss-Legendre rule), for LARS and OMP over a hyperbolic candidate set (q = 0.75) and for
   least squares on the largest total-degree set with 2 runs per term.
2. Fit time at N = 512 Borehole runs for T = 1 and T = 500 time points, against
   scikit-learn's ``lars_path`` and OpenTURNS' LARS when importable (optional peers).

Run: ``OMP_NUM_THREADS=1 python scripts/bench_sparse_regression.py [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from bench_timing import median_seconds

from pcmb import PolynomialBasis, Uniform, hyperbolic_index_set, total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.nodes import random_nodes
from pcmb.chaos.sparse_regression import fit_sparse, minimum_samples
from pcmb.references import ishigami, ishigami_moments

BOREHOLE = [
    Uniform(0.05, 0.15),  # rw
    Uniform(100.0, 50_000.0),  # r
    Uniform(63_070.0, 115_600.0),  # Tu
    Uniform(990.0, 1110.0),  # Hu
    Uniform(63.1, 116.0),  # Tl
    Uniform(700.0, 820.0),  # Hl
    Uniform(1120.0, 1680.0),  # L
    Uniform(9855.0, 12_045.0),  # Kw
]
ISHIGAMI = [Uniform(-np.pi, np.pi)] * 3
SIZES = [2**m for m in range(4, 13)]


def borehole(x: np.ndarray) -> np.ndarray:
    """Water flow through a borehole (Harper & Gupta 1983), (N, 8) -> (N,)."""
    rw, r, tu, hu, tl, hl, length, kw = x.T
    log = np.log(r / rw)
    return 2 * np.pi * tu * (hu - hl) / (log * (1 + 2 * length * tu / (log * rw**2 * kw) + tu / tl))


def borehole_variance(points: int = 7) -> float:
    """Var of :func:`borehole` by a tensor Gauss-Legendre rule (points^8 nodes, in blocks)."""
    nodes, weights = np.polynomial.legendre.leggauss(points)
    weights = weights / 2
    first = second = 0.0
    for head in itertools.product(range(points), repeat=3):
        grid = np.meshgrid(*[nodes] * 5, indexing="ij")
        germ = np.column_stack(
            [np.full(grid[0].size, nodes[h]) for h in head] + [g.ravel() for g in grid]
        )
        weight = (
            np.prod(weights[list(head)])
            * np.prod(np.meshgrid(*[weights] * 5, indexing="ij"), axis=0).ravel()
        )
        y = borehole(np.column_stack([d.to_physical(germ[:, k]) for k, d in enumerate(BOREHOLE)]))
        first += weight @ y
        second += weight @ y**2
    return second - first**2


def _fit(distributions, selection, order, samples, values_of):
    """Variance and fit of one design: LARS/OMP over the hyperbolic set, or least squares on the
    largest total set with two runs per term (None if even order 1 does not fit)."""
    n = len(distributions)
    families = tuple(d.family for d in distributions)
    if selection == "none":
        fitting = [p for p in range(1, order + 1) if total_index_set(n, p).shape[0] * 2 <= samples]
        if not fitting:
            return None
        index = total_index_set(n, max(fitting))
    else:
        index = hyperbolic_index_set(n, order, 0.75)
        if samples < minimum_samples(index.shape[0], selection):
            return None
    nodes = random_nodes(distributions, samples, "sobol", seed=1)
    fit = fit_sparse(
        PolynomialBasis(families, index), nodes.nodes, values_of(nodes.params), selection
    )
    return float(ChaosExpansion(fit.coefficients, fit.multi_index, distributions).variance())


def runs_needed(name, distributions, function, order, variance):
    """First 2^m whose relative variance error is at most 1e-2 and 1e-4, per method."""
    rows = []
    for selection in ("lars", "omp", "none"):
        needed = {1e-2: None, 1e-4: None}
        for samples in SIZES:
            estimate = _fit(distributions, selection, order, samples, function)
            if estimate is None:
                continue
            error = abs(estimate / variance - 1)
            for target in needed:
                if needed[target] is None and error <= target:
                    needed[target] = samples
            if needed[1e-4] is not None:
                break
        rows.append((name, selection, needed[1e-2], needed[1e-4]))
    return rows


def fit_times(repeat):
    """Seconds to fit 512 Borehole runs for T = 1 and T = 500, with the optional peer."""
    nodes = random_nodes(BOREHOLE, 512, "sobol", seed=1)
    times = np.linspace(0.0, 5.0, 500)
    # A non-separable response over time: the flow decays at a rate set by the first input.
    values = borehole(nodes.params)[:, None] * np.exp(-np.outer(1 + nodes.nodes[:, 0], times) / 4)
    families = tuple(d.family for d in BOREHOLE)
    candidates = PolynomialBasis(families, hyperbolic_index_set(8, 5, 0.75))
    ols = PolynomialBasis(families, total_index_set(8, 3))
    rows = []
    for label, basis, selection in [
        ("lars", candidates, "lars"),
        ("omp", candidates, "omp"),
        ("none", ols, "none"),
    ]:
        for width in (1, 500):
            y = values[:, :width]
            seconds = median_seconds(
                lambda b=basis, s=selection, y=y: fit_sparse(b, nodes.nodes, y, s), repeat
            )
            rows.append((f"pcmb {label} ({basis.size} terms)", width, seconds))
    matrix = candidates.evaluate(nodes.nodes)
    try:
        from sklearn.linear_model import lars_path
    except ImportError:
        rows.append(("scikit-learn lars_path", 1, None))
    else:
        rows.append(
            (
                "scikit-learn lars_path",
                1,
                median_seconds(lambda: lars_path(matrix, values[:, 0], method="lar"), repeat),
            )
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows = runs_needed("Ishigami", ISHIGAMI, ishigami, 14, ishigami_moments().variance)
    rows += runs_needed("Borehole", BOREHOLE, borehole, 6, borehole_variance())
    print(f"{'function':10s} {'method':6s} {'runs for 1e-2':>14s} {'runs for 1e-4':>14s}")
    for name, selection, low, high in rows:
        print(f"{name:10s} {selection:6s} {low or '> 4096':>14} {high or '> 4096':>14}")
    print(f"\n{'fit (N = 512 Borehole runs)':36s} {'T':>4s} {'seconds':>9s}")
    for label, width, seconds in fit_times(args.repeat):
        shown = "not installed" if seconds is None else f"{seconds:9.3f}"
        print(f"{label:36s} {width:4d} {shown:>9s}")


if __name__ == "__main__":
    main()
