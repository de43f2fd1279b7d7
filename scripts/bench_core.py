"""Benchmark of the chaos core (issue 2): recovery and statistics at scale.

1. Recovery + mean/std/Sobol' for 7 inputs × order 4 tensor grid (78,125 nodes) × 100
   time points: seconds and peak traced memory (the dense S×S matrix would need ~49 GB),
   plus, on a size where the dense route fits (5 inputs, 3,125 nodes), the ratio of a dense
   ``numpy.linalg.solve`` to the Kronecker projection.
2. Sobol' first + total indices for 4 inputs, order 4 (625 terms), 2,000 time points:
   pcmb vs chaospy's ``Sens_m``/``Sens_t`` on the same expansion (if chaospy is installed).

Run: ``python scripts/bench_core.py [--repeat 5] [--skip-chaospy]``. Medians are printed.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np
from bench_timing import median_seconds

from pcmb import (
    ChaosExpansion,
    PolynomialBasis,
    TensorGrid,
    Uniform,
    project_tensor,
    total_index_set,
)


def _response(theta, n_times):
    """A smooth nonlinear response over time: y(t) = Σ_k sin(θ_k t) + Π_k θ_k, (N, n) -> (N, T)."""
    t = np.linspace(0.0, 1.0, n_times)
    return np.sin(np.einsum("nk,t->nt", theta, t)) + np.prod(theta, axis=1)[:, None]


def recovery_and_statistics(grid, values):
    coef = project_tensor(grid, values)
    expansion = ChaosExpansion(coef, grid.multi_index, grid.distributions)
    return expansion.mean(), expansion.std(), expansion.sobol_first(), expansion.sobol_total()


def bench_large_recovery(repeat):
    grid = TensorGrid([Uniform(0.5, 1.5)] * 7, [4] * 7)
    values = _response(grid.params, 100)
    _ = grid.rules  # Gauss rules are built once per grid, not per recovery
    seconds = median_seconds(lambda: recovery_and_statistics(grid, values), repeat)
    tracemalloc.start()
    recovery_and_statistics(grid, values)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    dense_gb = grid.size**2 * 8 / 1e9
    print(
        f"[1] 7 inputs x order 4 = {grid.size} nodes x 100 times: recovery + mean/std/Sobol' "
        f"{seconds:.3f} s (median of {repeat}), peak extra memory {peak / 1e6:.0f} MB "
        f"(values alone {values.nbytes / 1e6:.0f} MB; dense A would be {dense_gb:.0f} GB)"
    )

    small = TensorGrid([Uniform(0.5, 1.5)] * 5, [4] * 5)
    small_values = _response(small.params, 100)
    basis = PolynomialBasis(tuple(d.family for d in small.distributions), small.multi_index)
    matrix = basis.evaluate(small.nodes)
    dense = median_seconds(lambda: np.linalg.solve(matrix, small_values), repeat)
    kron = median_seconds(lambda: project_tensor(small, small_values), repeat)
    error = np.abs(np.linalg.solve(matrix, small_values) - project_tensor(small, small_values))
    print(
        f"    5 inputs x order 4 = {small.size} nodes: dense solve {dense * 1e3:.1f} ms "
        f"(matrix already built) vs Kronecker {kron * 1e3:.2f} ms -> ratio {dense / kron:.0f}x, "
        f"max |difference| {error.max():.1e}"
    )


def bench_sobol(repeat, with_chaospy):
    dists = [Uniform(0.5, 1.5)] * 4
    grid = TensorGrid(dists, [4] * 4)
    values = _response(grid.params, 2000)
    tensor = ChaosExpansion(project_tensor(grid, values), grid.multi_index, dists)
    index = total_index_set(4, 4)
    total = ChaosExpansion(project_tensor(grid, values, index), index, dists)
    for label, expansion in [("tensor", tensor), ("total-degree", total)]:
        ours = median_seconds(lambda e=expansion: (e.sobol_first(), e.sobol_total()), repeat)
        print(
            f"[2] Sobol' first + total, 4 inputs, {label} order 4 "
            f"({expansion.multi_index.shape[0]} terms) x 2000 times, {grid.size} nodes: "
            f"pcmb {ours * 1e3:.2f} ms (median of {repeat})"
        )
    if not with_chaospy:
        return
    try:
        import chaospy
    except ImportError:
        print("    chaospy not installed: no comparison")
        return
    joint = chaospy.J(*[chaospy.Uniform(0.5, 1.5) for _ in range(4)])
    polys = chaospy.generate_expansion(4, joint, normed=True)
    nodes, weights = chaospy.generate_quadrature(4, joint, rule="gaussian")
    surrogate = chaospy.fit_quadrature(polys, nodes, weights, _response(nodes.T, 2000))
    start = time.perf_counter()
    first = chaospy.Sens_m(surrogate, joint)
    chaospy.Sens_t(surrogate, joint)
    theirs = time.perf_counter() - start
    difference = np.nanmax(np.abs(total.sobol_first()[:, 1:] - first[:, 1:]))
    print(
        f"    chaospy Sens_m + Sens_t on the same total-degree expansion ({len(polys)} terms): "
        f"{theirs:.2f} s (one run) -> ratio chaospy/pcmb "
        f"{theirs / ours:.0f}x; max |S_first difference| {difference:.1e}"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--skip-chaospy", action="store_true")
    args = parser.parse_args()
    bench_large_recovery(args.repeat)
    bench_sobol(args.repeat, not args.skip_chaospy)


if __name__ == "__main__":
    main()
