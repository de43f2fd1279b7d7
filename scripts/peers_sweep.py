"""Add chaospy and OpenTURNS to a ``pcmb sweep``: same model, same reference, same chart.

Usage (after ``pcmb sweep CONFIG -o DIR``; peers from ``pip install -e ".[peers]"``)::

    python scripts/peers_sweep.py CONFIG DIR [--max-runs N] [--peers NAME ...]

Each peer runs the config's model through pcmb's executor (the same model file and workers,
one call per chunk of nodes) at the peer's own nodes, at rising cost up to ``--max-runs``
(default: the most runs of any row already in the table, at most :data:`MAX_RUNS`):

- ``chaospy:quadrature``: tensor Gauss quadrature of order p, projected on the orthonormal
  expansion of order p (``generate_quadrature``, ``fit_quadrature``);
- ``chaospy:smolyak``: Smolyak grids of Clenshaw–Curtis rules with growth, level L, on the
  expansion of order L;
- ``chaospy:collocation``: point collocation (``fit_regression``), total order p on twice as
  many scrambled Sobol' points as terms;
- ``openturns:lars``: LARS with the corrected leave-one-out error on a hyperbolic (q = 0.75)
  candidate set of the degree of the sweep's own regression entry (else 8), 2^k scrambled
  Sobol' points.

Their rows (``seconds`` = model runs + fit; ``model_seconds`` the runs; ``pcmb_seconds`` the
peer's own fit time) are appended to ``DIR/sweep.csv`` and ``DIR/sweep.h5`` (replacing rows
of the same peers from an earlier call), and ``DIR/sweep.png`` is drawn again.
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from scipy.special import comb
from scipy.stats import qmc

import pcmb
from pcmb.config.schema import StudyConfig, load_config
from pcmb.run.executor import run_nodes
from pcmb.sweep.accuracy import errors
from pcmb.sweep.chart import draw_sweep
from pcmb.sweep.table import SweepRow, SweepTable, read_sweep, write_sweep

#: Exponent of OpenTURNS' hyperbolic candidate set (as in scripts/bench_sparse.py).
Q = 0.75
#: Largest design by default: OpenTURNS' LARS fits each time point of each output apart, and
#: on the quarter car (2 x 301 of them) 512 points already took minutes.
MAX_RUNS = 1024
#: OpenTURNS' candidate degree when the sweep has no regression entry to copy.
LARS_ORDER = 8


@dataclass(frozen=True)
class Fit:
    """A peer's statistics at one cost."""

    setting: str
    runs: int
    mean: dict[str, np.ndarray]
    std: dict[str, np.ndarray]
    model_seconds: float
    fit_seconds: float


class Model:
    """The config's model, run through pcmb's executor at given physical points."""

    def __init__(self, config: StudyConfig, outputs: tuple[str, ...]):
        self.config, self.outputs = config, outputs
        self.names = config.input_names
        self.distributions = [d.describe() for d in config.distributions]

    def germ(self, germ: np.ndarray) -> tuple[dict[str, np.ndarray], float]:
        """:meth:`__call__` at (N, n) points of the standardised germs."""
        return self(
            np.column_stack(
                [d.to_physical(germ[:, i]) for i, d in enumerate(self.config.distributions)]
            )
        )

    def __call__(self, points: np.ndarray) -> tuple[dict[str, np.ndarray], float]:
        """(N, n) physical points -> output -> (N, T) values, and the wall seconds."""
        execution = self.config.execution
        start = time.perf_counter()
        found = run_nodes(
            self.config.model_factory(),
            {name: points[:, i] for i, name in enumerate(self.names)},
            self.config.times,
            self.outputs,
            stop_on_failure=True,
            execution=execution,
        )
        seconds = time.perf_counter() - start
        if found.failures:
            raise RuntimeError(f"model failed: {found.failures[0]}")
        return found.values, seconds


def _unsupported(described: dict) -> RuntimeError:
    return RuntimeError(f"{described['dist']} inputs are not mapped to the peers by this script")


def _chaospy_joint(model: Model):
    """The inputs' standardised germs as a chaospy joint (U(-1, 1), N(0, 1), Beta on
    [-1, 1]): in physical units chaospy's expansions of order 9 and more give NaN when an
    input is of order 1e6, as the quarter car's stiffness is."""
    import chaospy

    marginals = []
    for d in model.distributions:
        if d["dist"] == "uniform":
            marginals.append(chaospy.Uniform(-1.0, 1.0))
        elif d["dist"] == "normal":
            marginals.append(chaospy.Normal(0.0, 1.0))
        elif d["dist"] == "beta":
            marginals.append(chaospy.Beta(d["alpha"], d["beta"], -1.0, 1.0))
        else:
            raise _unsupported(d)
    return chaospy.J(*marginals)


def _chaospy_statistics(values: dict, fit: Callable) -> tuple[dict, dict, float]:
    """Mean and std per output from the coefficients ``fit(values[name], retall=True)``
    returns on chaospy's orthonormal expansion (its first term the constant), and the seconds
    it all took. chaospy.E and chaospy.Std on the fitted polynomial of 301 time points ran out
    of memory at order 5 on the quarter car."""
    mean, std = {}, {}
    start = time.perf_counter()
    for name in values:
        _, coefficients = fit(values[name], retall=True)
        coefficients = np.asarray(coefficients, dtype=float)
        mean[name] = coefficients[0]
        std[name] = np.sqrt(np.sum(coefficients[1:] ** 2, axis=0))
    return mean, std, time.perf_counter() - start


def chaospy_quadrature(model: Model, cap: int) -> Iterator[Fit]:
    import chaospy

    joint, n = _chaospy_joint(model), len(model.names)
    for order in range(1, 40):
        if (order + 1) ** n > cap:
            return
        nodes, weights = chaospy.generate_quadrature(order, joint, rule="gaussian")
        values, seconds = model.germ(nodes.T)
        expansion = chaospy.generate_expansion(order, joint, normed=True)
        mean, std, fit = _chaospy_statistics(
            values, partial(chaospy.fit_quadrature, expansion, nodes, weights)
        )
        yield Fit(f"order={order}", nodes.shape[1], mean, std, seconds, fit)


def chaospy_smolyak(model: Model, cap: int) -> Iterator[Fit]:
    import chaospy

    joint = _chaospy_joint(model)
    for level in range(1, 20):
        start = time.perf_counter()
        nodes, weights = chaospy.generate_quadrature(
            level, joint, rule="clenshaw_curtis", sparse=True, growth=True
        )
        build = time.perf_counter() - start
        if nodes.shape[1] > cap:
            return
        values, seconds = model.germ(nodes.T)
        expansion = chaospy.generate_expansion(level, joint, normed=True)
        mean, std, fit = _chaospy_statistics(
            values, partial(chaospy.fit_quadrature, expansion, nodes, weights)
        )
        yield Fit(f"level={level}", nodes.shape[1], mean, std, seconds, fit + build)


def _sobol_points(model: Model, samples: int) -> np.ndarray:
    """(samples, n) scrambled Sobol' points mapped through the inputs' inverse CDFs."""
    unit = qmc.Sobol(len(model.names), scramble=True, seed=1).random(samples)
    distributions = model.config.distributions
    return np.column_stack([d.physical.ppf(unit[:, i]) for i, d in enumerate(distributions)])


def chaospy_collocation(model: Model, cap: int) -> Iterator[Fit]:
    import chaospy

    joint, n = _chaospy_joint(model), len(model.names)
    for order in range(1, 30):
        samples = 2 ** int(np.ceil(np.log2(2 * comb(n + order, order))))  # >= 2 per term
        if samples > cap:
            return
        points = _sobol_points(model, samples)
        values, seconds = model(points)
        germ = np.column_stack(
            [d.to_germ(points[:, i]) for i, d in enumerate(model.config.distributions)]
        )
        expansion = chaospy.generate_expansion(order, joint, normed=True)
        mean, std, fit = _chaospy_statistics(
            values, partial(chaospy.fit_regression, expansion, germ.T)
        )
        yield Fit(f"order={order}", samples, mean, std, seconds, fit)


def _openturns_joint(model: Model):
    import openturns as ot

    marginals, families = [], []
    for d in model.distributions:
        if d["dist"] == "uniform":
            marginals.append(ot.Uniform(d["low"], d["high"]))
        elif d["dist"] == "normal":
            marginals.append(ot.Normal(d["mean"], d["std"]))
        elif d["dist"] == "beta":
            marginals.append(ot.Beta(d["alpha"], d["beta"], d["low"], d["high"]))
        else:
            raise _unsupported(d)
        families.append(ot.StandardDistributionPolynomialFactory(marginals[-1]))
    joint = (getattr(ot, "JointDistribution", None) or ot.ComposedDistribution)(marginals)
    return joint, families


def _lars_order(config: StudyConfig) -> int:
    """The candidate degree of pcmb's own LARS in the sweep (its first regression entry with
    an integer order), so that both select from the same set; else :data:`LARS_ORDER`."""
    for entry in config.sweep.methods if config.sweep is not None else ():
        if entry.get("kind") == "regression" and isinstance(entry.get("order"), int):
            return entry["order"]
    return LARS_ORDER


def openturns_lars(model: Model, cap: int) -> Iterator[Fit]:
    import openturns as ot

    order = _lars_order(model.config)

    ot.Log.Show(ot.Log.NONE)
    joint, families = _openturns_joint(model)
    n = len(model.names)
    enumerate_ = ot.HyperbolicAnisotropicEnumerateFunction(n, Q)
    basis = ot.OrthogonalProductPolynomialFactory(families, enumerate_)
    size = enumerate_.getBasisSizeFromTotalDegree(order)
    for power in range(4, 20):
        samples = 2**power
        if samples > cap:
            return
        points = _sobol_points(model, samples)
        values, seconds = model(points)
        mean, std = {}, {}
        start = time.perf_counter()
        for name in model.outputs:
            selection = ot.LeastSquaresMetaModelSelectionFactory(
                ot.LARS(), ot.CorrectedLeaveOneOut()
            )
            algorithm = ot.FunctionalChaosAlgorithm(
                ot.Sample(points),
                ot.Sample(values[name]),
                joint,
                ot.FixedStrategy(basis, size),
                ot.LeastSquaresStrategy(selection),
            )
            algorithm.run()
            vector = ot.FunctionalChaosRandomVector(algorithm.getResult())
            mean[name] = np.array(vector.getMean())
            variance = np.array(vector.getCovariance())
            std[name] = np.sqrt(np.maximum(np.diag(variance), 0.0))
        fit = time.perf_counter() - start
        yield Fit(f"samples={samples}", samples, mean, std, seconds, fit)


PEERS: dict[str, tuple[str, Callable[[Model, int], Iterator[Fit]]]] = {
    "chaospy:quadrature": ("chaospy", chaospy_quadrature),
    "chaospy:smolyak": ("chaospy", chaospy_smolyak),
    "chaospy:collocation": ("chaospy", chaospy_collocation),
    "openturns:lars": ("openturns", openturns_lars),
}


def _rows(method: str, found: Fit, reference, outputs) -> tuple[list, list, list]:
    rows, means, stds = [], [], []
    seconds = found.model_seconds + found.fit_seconds
    for name in outputs:
        error = errors(found.mean[name], found.std[name], reference.mean(name), reference.std(name))
        rows.append(
            SweepRow.measured(
                error,
                method=method,
                setting=found.setting,
                runs=found.runs,
                seconds=seconds,
                output=name,
                model_seconds=found.model_seconds,
                pcmb_seconds=found.fit_seconds,
            )
        )
        # Curves over time only; an output off the time grid keeps its errors in its rows.
        blank = np.full(reference.times.size, np.nan)
        means.append(error.mean_curve if reference.on_time(name) else blank)
        stds.append(error.std_curve if reference.on_time(name) else blank)
    return rows, means, stds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", type=Path)
    parser.add_argument("folder", type=Path, help="the folder of a finished pcmb sweep")
    parser.add_argument("--max-runs", type=int, help="largest design of a peer")
    parser.add_argument("--peers", nargs="+", choices=list(PEERS), default=list(PEERS))
    args = parser.parse_args()
    config = load_config(args.config)
    table = read_sweep(args.folder / "sweep.h5")
    reference = pcmb.load(table.reference_file)
    outputs = tuple(dict.fromkeys(row.output for row in table.rows))
    cap = args.max_runs or min(max(row.runs for row in table.rows), MAX_RUNS)
    model = Model(config, outputs)
    keep = [i for i, row in enumerate(table.rows) if row.method not in args.peers]
    table = SweepTable(
        tuple(table.rows[i] for i in keep),
        table.times,
        table.mean_curves[keep],
        table.std_curves[keep],
        table.reference,
        table.reference_file,
        table.floors,
    )
    for method in args.peers:
        module, peer = PEERS[method]
        if importlib.util.find_spec(module) is None:
            print(f"skipping {method}: {module} is not installed (pip install -e '.[peers]')")
            continue
        for found in peer(model, cap):
            rows, means, stds = _rows(method, found, reference, outputs)
            table = table.extended(rows, np.array(means), np.array(stds))
            worst = max(row.err_std for row in rows)
            print(f"{method:<22} {found.setting:<14} {found.runs:>6} runs  std error {worst:.3g}")
    write_sweep(table, args.folder)
    draw_sweep(table, args.folder / "sweep.png")
    print(f"wrote {args.folder / 'sweep.csv'}, sweep.h5 and sweep.png")


if __name__ == "__main__":
    main()
