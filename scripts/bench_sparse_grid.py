"""Benchmark of Smolyak sparse grids: node counts, build and recovery times.

For 2 to 20 uniform inputs and Clenshaw–Curtis levels up to about 1e5 nodes: the node count,
the seconds to build the grid (nodes, weights, exact set) and to recover the coefficients of
T = 100 time points by sparse pseudo-spectral projection, and, if chaospy is installed,
chaospy's node count for the same Smolyak grid (``sparse=True``, ``growth=True``; only where
chaospy builds it in reasonable time).

Run: ``python scripts/bench_sparse_grid.py [--max-nodes 100000] [--skip-chaospy]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np
from bench_timing import median_seconds

from pcmb.chaos.inputs import Uniform
from pcmb.chaos.sparse import SparseGrid

TIMES = 100
#: chaospy's sparse grid is slow to build beyond this many nodes.
CHAOSPY_LIMIT = 5_000


def _build(n: int, level: int) -> SparseGrid:
    grid = SparseGrid.smolyak([Uniform(0.5, 1.5)] * n, level, "clenshaw-curtis")
    _ = grid.nodes, grid.weights, grid.multi_index
    return grid


def _chaospy_count(n: int, level: int) -> int:
    import chaospy

    nodes, _ = chaospy.generate_quadrature(
        level, chaospy.Iid(chaospy.Uniform(0.5, 1.5), n), rule="clenshaw_curtis", sparse=True
    )
    return nodes.shape[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-nodes", type=int, default=100_000)
    parser.add_argument("--skip-chaospy", action="store_true")
    args = parser.parse_args()
    peer = not args.skip_chaospy and importlib.util.find_spec("chaospy") is not None
    t = np.linspace(0.0, 1.0, TIMES)
    print(
        f"{'inputs':>6} {'level':>5} {'nodes':>8} {'terms':>8} {'build s':>8} "
        f"{'recover s':>9} {'chaospy':>8}"
    )
    for n in (2, 3, 5, 10, 15, 20):
        level = 1
        while SparseGrid.smolyak([Uniform(0.0, 1.0)] * n, level, "clenshaw-curtis").size <= (
            args.max_nodes
        ):
            start = time.perf_counter()
            grid = _build(n, level)
            build = time.perf_counter() - start
            values = (
                np.sin(np.einsum("nk,t->nt", grid.params, t))
                + np.prod(grid.params, axis=1)[:, None]
            )
            recover = median_seconds(lambda grid=grid, values=values: grid.project(values), 3)
            count = _chaospy_count(n, level) if peer and grid.size <= CHAOSPY_LIMIT else None
            shown = "-" if count is None else str(count)
            print(
                f"{n:>6} {level:>5} {grid.size:>8} {grid.multi_index.shape[0]:>8} "
                f"{build:>8.3f} {recover:>9.3f} {shown:>8}"
            )
            level += 1


if __name__ == "__main__":
    main()
