"""Benchmark of pcmb's chaos methods against chaospy and OpenTURNS: runs for a given accuracy.

Five functions, all with uniform inputs: Ishigami (3), Borehole (8; reference by an anisotropic
tensor Gauss-Legendre rule of ~1e6 nodes), exp(Σ 2^-k x_k) (8, closed form), the Sobol'
G-function (8, a = 0, 1, 4.5, 9, 99, 99, 99, 99; non-smooth, closed form) and the quarter car of
``configs/quarter_car.yaml`` (output x1 at t = 0.1, 0.2, ..., 3 s; reference: tensor Gauss
order 19, 8000 runs; order 13 with --quick). The error is max |std - std_ref| / max std_ref
(for one output: the relative error of the std).

pcmb (public API: ``pcmb.Study``, ``backend="inprocess"``, ``validation=0``): tensor Gauss
collocation, Smolyak (``rule="auto"``), adaptive sparse grid, LARS (hyperbolic, q = 0.75, Sobol').
Peers, if importable (``pip install -e ".[peers]"``): chaospy tensor Gauss quadrature, Smolyak
(Clenshaw-Curtis, nested) and point collocation (least squares on Sobol' points, 2 runs per
term); OpenTURNS LARS (same candidate count as pcmb's, corrected LOO, scrambled Sobol' points).

A sweep stops once the error is below 1e-7 or after BUDGET seconds. Prints the runs each
method needs for errors 1e-2, 1e-4 and 1e-6 and the recovery time at
1e-4 (pcmb: ``Study.run`` wall time minus the model runs; peers: the fit); draws the error
against the runs to ``docs/figures/bench_sparse.png``.

Run: ``OMP_NUM_THREADS=1 python scripts/bench_sparse.py [--quick] [--figure PATH]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import qmc

import pcmb
from pcmb import references
from pcmb.chaos.nested import CONTINUED_LEVELS, nested_rule
from pcmb.chaos.polynomials import Legendre
from pcmb.references import borehole_bounds, ishigami, ishigami_moments

ROOT = Path(__file__).resolve().parents[1]
TARGETS = (1e-2, 1e-4, 1e-6)
#: Seconds after which a method's sweep of one function stops (after the design running then).
BUDGET = 45.0
Q = 0.75


@dataclass
class Problem:
    """A benchmark function: uniform bounds, a batch evaluator (N, d) -> (N, K), the
    reference std (K,) and the scale the std error is divided by."""

    name: str
    bounds: list[tuple[float, float]]
    func: Callable[[np.ndarray], np.ndarray]
    reference: np.ndarray
    lars_order: int
    cap: int
    adaptive_cap: int
    study: Callable[..., pcmb.Study] | None = None
    scale: float = field(init=False)

    def __post_init__(self) -> None:
        self.scale = float(np.max(self.reference))

    @property
    def dim(self) -> int:
        return len(self.bounds)

    def error(self, std: np.ndarray) -> float:
        return float(np.max(np.abs(np.ravel(std) - self.reference)) / self.scale)

    def physical(self, unit: np.ndarray) -> np.ndarray:
        """Points of [0, 1]^d mapped to the input box."""
        low, high = np.array(self.bounds).T
        return low + unit * (high - low)


# ----------------------------------------------------------------------------- functions

BOREHOLE = list(borehole_bounds())
EXP_WEIGHTS = 2.0 ** -np.arange(8)
G_WEIGHTS = np.array([0.0, 1.0, 4.5, 9.0, 99.0, 99.0, 99.0, 99.0])


def borehole(x: np.ndarray) -> np.ndarray:
    """Water flow through a borehole (Harper & Gupta 1983), (N, 8) -> (N, 1)."""
    return references.borehole(x)[:, None]


def gauss_std(func: Callable, bounds, points: list[int], block: int = 3) -> np.ndarray:
    """Std of ``func`` by a tensor Gauss-Legendre rule, ``points[k]`` nodes in input k."""
    rules = [np.polynomial.legendre.leggauss(n) for n in points]
    nodes = [lo + (hi - lo) * (x + 1) / 2 for (lo, hi), (x, _) in zip(bounds, rules, strict=True)]
    weights = [w / 2 for _, w in rules]
    tail_x = np.stack(np.meshgrid(*nodes[block:], indexing="ij"), -1).reshape(
        -1, len(bounds) - block
    )
    tail_w = np.prod(np.meshgrid(*weights[block:], indexing="ij"), axis=0).ravel()
    first = second = 0.0
    for head in itertools.product(*[range(n) for n in points[:block]]):
        x = np.column_stack(
            [np.full(tail_w.size, nodes[k][h]) for k, h in enumerate(head)] + [tail_x]
        )
        w = tail_w * np.prod([weights[k][h] for k, h in enumerate(head)])
        y = func(x)
        first = first + w @ y
        second = second + w @ y**2
    return np.sqrt(second - first**2)


def exp_sum(x: np.ndarray) -> np.ndarray:
    """exp(Σ a_k x_k), a_k = 2^-k, x_k uniform on [-1, 1]: (N, 8) -> (N, 1)."""
    return np.exp(x @ EXP_WEIGHTS)[:, None]


def exp_sum_std() -> np.ndarray:
    a = EXP_WEIGHTS
    mean = np.prod(np.sinh(a) / a)
    square = np.prod(np.sinh(2 * a) / (2 * a))
    return np.array([np.sqrt(square - mean**2)])


def g_function(x: np.ndarray) -> np.ndarray:
    """Sobol' G-function, x_k uniform on [0, 1]: (N, 8) -> (N, 1)."""
    return np.prod((np.abs(4 * x - 2) + G_WEIGHTS) / (1 + G_WEIGHTS), axis=1)[:, None]


def g_function_std() -> np.ndarray:
    return np.array([np.sqrt(np.prod(1 + 1 / (3 * (1 + G_WEIGHTS) ** 2)) - 1)])


# ----------------------------------------------------------------------------- quarter car

QC_TIMES = np.round(np.linspace(0.1, 3.0, 30), 10)
QC_INPUTS = ("A", "kT", "c")


def _quarter_car_config():
    return pcmb.load_config(ROOT / "configs" / "quarter_car.yaml")


def quarter_car_function() -> Callable[[np.ndarray], np.ndarray]:
    """The config's QuarterCar model as a batch function (N, 3) -> (N, 30), output x1."""
    sys.path.insert(0, str(ROOT / "models"))
    from quarter_car import QuarterCar

    params = _quarter_car_config().model.params
    model = QuarterCar(**params)

    def run(x: np.ndarray) -> np.ndarray:
        values = {name: x[:, k] for k, name in enumerate(QC_INPUTS)}
        return model.simulate(values, QC_TIMES)["x1"]

    return run


def quarter_car_study(**method) -> pcmb.Study:
    """The study of ``configs/quarter_car.yaml`` on x1 at QC_TIMES, in-process, no validation
    (the config's ``basis: tensor`` dropped unless given: with kind adaptive it would ask for
    the tensor variant)."""
    base = pcmb.Study.from_config(_quarter_car_config())
    method = {"basis": None, **method}
    return base.replace(
        times=QC_TIMES,
        outputs=("x1",),
        backend="inprocess",
        validation=0,
        analysis=pcmb.AnalysisSettings(psd=()),
        **method,
    )


def problems(quick: bool) -> list[Problem]:
    """The benchmark functions with their references (computed here)."""
    cap = 1024 if quick else 4096
    adaptive = min(cap, 2048)
    qc = quarter_car_function()
    qc_bounds = [(0.025, 0.075), (1.2e5, 1.8e5), (800.0, 1200.0)]
    qc_points = 14 if quick else 20
    return [
        Problem(
            "Ishigami",
            [(-np.pi, np.pi)] * 3,
            lambda x: ishigami(x)[:, None],
            np.array([np.sqrt(ishigami_moments().variance)]),
            14,
            cap,
            adaptive,
        ),
        Problem(
            "Borehole",
            BOREHOLE,
            borehole,
            gauss_std(borehole, BOREHOLE, [12, 40, 6, 3, 8, 3, 5, 6]),
            6,
            cap,
            adaptive,
        ),
        Problem("exp(Σ 2^-k x_k)", [(-1.0, 1.0)] * 8, exp_sum, exp_sum_std(), 6, cap, adaptive),
        Problem("G-function", [(0.0, 1.0)] * 8, g_function, g_function_std(), 6, cap, 600),
        Problem(
            "quarter car",
            qc_bounds,
            qc,
            gauss_std(qc, qc_bounds, [qc_points] * 3, block=1),
            12,
            cap,
            adaptive,
            study=quarter_car_study,
        ),
    ]


# ----------------------------------------------------------------------------- pcmb


def _pcmb_study(problem: Problem, **method) -> pcmb.Study:
    if problem.study is not None:
        return problem.study(**method)
    names = [f"x{k}" for k in range(problem.dim)]

    @pcmb.batched(outputs=("y",))
    def model(params, times):
        return {"y": problem.func(np.column_stack([params[n] for n in names]))}

    inputs = {n: pcmb.Uniform(lo, hi) for n, (lo, hi) in zip(names, problem.bounds, strict=True)}
    return pcmb.Study(model, inputs, np.array([0.0]), backend="inprocess", validation=0, **method)


def _pcmb_run(problem: Problem, method: dict, full: bool = False):
    """(runs, error, recovery seconds) of one pcmb study, None if it exceeds the cap (with
    ``full``: also the result)."""
    study = _pcmb_study(problem, **method)
    if study.node_set().size > problem.cap and method.get("method") != "adaptive":
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        result = study.run()
        seconds = time.perf_counter() - start - result.seconds
    row = result.n_nodes, problem.error(result.std(result.outputs[0])), seconds
    return (row, result) if full else row


def pcmb_tensor(problem: Problem):
    for order in range(1, 40):
        row = _pcmb_run(problem, {"order": order})
        if row is None:
            return
        yield row


def pcmb_smolyak(problem: Problem):
    top = nested_rule(Legendre(), "auto").max_level + CONTINUED_LEVELS  # rule auto's last
    for level in range(1, top + 1):
        row = _pcmb_run(problem, {"grid": "smolyak", "level": level})
        if row is None:
            return
        yield row


def pcmb_adaptive(problem: Problem):
    last = 0
    for exponent in range(1, 12):
        tolerance = 10.0**-exponent
        method = {"method": "adaptive", "tolerance": tolerance, "max_runs": problem.adaptive_cap}
        row, result = _pcmb_run(problem, method, full=True)
        if row[0] != last:
            yield row
        last = row[0]
        if result.adaptive.estimate > tolerance:  # the budget stopped it
            return


def pcmb_lars(problem: Problem):
    for samples in _powers(problem.cap):
        try:
            row = _pcmb_run(
                problem,
                {
                    "method": "regression",
                    "samples": samples,
                    "selection": "lars",
                    "basis": "hyperbolic",
                    "q": Q,
                    "order": problem.lars_order,
                },
            )
        except pcmb.PcmbError:  # too few samples for the candidates
            continue
        yield row


def _powers(cap: int) -> list[int]:
    return [2**m for m in range(4, 14) if 2**m <= cap]


# ----------------------------------------------------------------------------- peers


def _chaospy_joint(problem: Problem):
    import chaospy

    return chaospy.J(*[chaospy.Uniform(lo, hi) for lo, hi in problem.bounds])


def _chaospy_projection(problem: Problem, order: int, nodes, weights):
    import chaospy

    joint = _chaospy_joint(problem)
    values = problem.func(nodes.T)
    start = time.perf_counter()
    expansion = chaospy.generate_expansion(order, joint, normed=True)
    approx = chaospy.fit_quadrature(expansion, nodes, weights, values)
    std = chaospy.Std(approx, joint)
    return nodes.shape[1], problem.error(std), time.perf_counter() - start


def chaospy_tensor(problem: Problem):
    import chaospy

    for order in range(1, 40):
        if (order + 1) ** problem.dim > problem.cap:
            return
        nodes, weights = chaospy.generate_quadrature(
            order, _chaospy_joint(problem), rule="gaussian"
        )
        yield _chaospy_projection(problem, order, nodes, weights)


def chaospy_smolyak(problem: Problem):
    import chaospy

    for level in range(1, 20):
        start = time.perf_counter()
        nodes, weights = chaospy.generate_quadrature(
            level, _chaospy_joint(problem), rule="clenshaw_curtis", sparse=True, growth=True
        )
        build = time.perf_counter() - start
        if nodes.shape[1] > problem.cap:
            return
        runs, error, seconds = _chaospy_projection(problem, level, nodes, weights)
        yield runs, error, seconds + build
        if build > 10:  # the next level would take minutes to build
            return


def chaospy_ols(problem: Problem):
    import chaospy
    from scipy.special import comb

    if problem.dim > 3:  # chaospy's polynomial evaluation takes minutes in 8 inputs
        return
    joint = _chaospy_joint(problem)
    for samples in _powers(min(problem.cap, 1024)):
        fitting = [p for p in range(1, 30) if 2 * comb(problem.dim + p, p) <= samples]
        if not fitting:
            continue
        nodes = problem.physical(_sobol(problem.dim, samples)).T
        values = problem.func(nodes.T)
        start = time.perf_counter()
        expansion = chaospy.generate_expansion(max(fitting), joint, normed=True)
        approx = chaospy.fit_regression(expansion, nodes, values)
        std = chaospy.Std(approx, joint)
        yield samples, problem.error(std), time.perf_counter() - start


def _sobol(dim: int, samples: int) -> np.ndarray:
    return qmc.Sobol(dim, scramble=True, seed=1).random(samples)


def openturns_lars(problem: Problem):
    import openturns as ot

    ot.Log.Show(ot.Log.NONE)
    marginals = [ot.Uniform(lo, hi) for lo, hi in problem.bounds]
    joint = (getattr(ot, "JointDistribution", None) or ot.ComposedDistribution)(marginals)
    enumerate_ = ot.HyperbolicAnisotropicEnumerateFunction(problem.dim, Q)
    basis = ot.OrthogonalProductPolynomialFactory([ot.LegendreFactory()] * problem.dim, enumerate_)
    size = pcmb.hyperbolic_index_set(problem.dim, problem.lars_order, Q).shape[0]
    for samples in _powers(problem.cap):
        x = problem.physical(_sobol(problem.dim, samples))
        y = problem.func(x)
        start = time.perf_counter()
        selection = ot.LeastSquaresMetaModelSelectionFactory(ot.LARS(), ot.CorrectedLeaveOneOut())
        algo = ot.FunctionalChaosAlgorithm(
            ot.Sample(x),
            ot.Sample(y),
            joint,
            ot.FixedStrategy(basis, size),
            ot.LeastSquaresStrategy(selection),
        )
        algo.run()
        result = algo.getResult()
        variance = np.array(ot.FunctionalChaosRandomVector(result).getCovariance())
        std = np.sqrt(np.maximum(np.diag(variance), 0.0))
        yield samples, problem.error(std), time.perf_counter() - start


# ----------------------------------------------------------------------------- driver

METHODS: list[tuple[str, str | None, Callable]] = [
    ("pcmb tensor", None, pcmb_tensor),
    ("pcmb Smolyak", None, pcmb_smolyak),
    ("pcmb adaptive", None, pcmb_adaptive),
    ("pcmb LARS", None, pcmb_lars),
    ("chaospy tensor", "chaospy", chaospy_tensor),
    ("chaospy Smolyak", "chaospy", chaospy_smolyak),
    ("chaospy OLS", "chaospy", chaospy_ols),
    ("OpenTURNS LARS", "openturns", openturns_lars),
]


def first_reaching(rows, target):
    """First (runs, seconds) whose error meets ``target``, in order of runs."""
    for runs, error, seconds in sorted(rows):
        if error <= target:
            return runs, seconds
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="at most 1024 runs per design (default 4096)"
    )
    parser.add_argument("--figure", type=Path, default=ROOT / "docs/figures/bench_sparse.png")
    args = parser.parse_args()
    methods = []
    for label, module, func in METHODS:
        if module is not None and importlib.util.find_spec(module) is None:
            print(f"skipping {label}: {module} is not installed (pip install -e '.[peers]')")
        else:
            methods.append((label, func))
    start = time.perf_counter()
    cases = problems(args.quick)
    print(f"references computed in {time.perf_counter() - start:.1f} s")
    curves: dict[str, dict[str, list]] = {}
    header = (
        "| function | method | runs for 1e-2 | runs for 1e-4 | runs for 1e-6 "
        "| best error (runs) | fit s at 1e-4 |"
    )
    lines = [header, "|---|---|---:|---:|---:|---:|---:|"]
    for problem in cases:
        curves[problem.name] = {}
        for label, func in methods:
            clock = time.perf_counter()
            rows = []
            for row in func(problem):
                rows.append(row)
                if row[1] <= TARGETS[-1] / 10 or time.perf_counter() - clock > BUDGET:
                    break
            rows.sort()
            if not rows:
                continue
            curves[problem.name][label] = rows
            cells = []
            for target in TARGETS:
                hit = first_reaching(rows, target)
                cells.append(f"{hit[0]}" if hit else f"> {max(r[0] for r in rows)}")
            hit = first_reaching(rows, 1e-4)
            best = min(rows, key=lambda r: r[1])
            lines.append(
                f"| {problem.name} (d={problem.dim}) | {label} | "
                + " | ".join(cells)
                + f" | {best[1]:.1e} ({best[0]}) | "
                + (f"{hit[1]:.3f}" if hit else "–")
                + " |"
            )
            print(lines[-1], f"  [{time.perf_counter() - clock:.1f} s]", flush=True)
    print(f"\ntotal {time.perf_counter() - start:.0f} s\n")
    print("\n".join(lines))
    draw(curves, args.figure)


def draw(curves: dict[str, dict[str, list]], path: Path) -> None:
    """Error against runs, one panel per function, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [label for label, _, _ in METHODS]
    colors = dict(zip(labels, plt.get_cmap("tab10").colors, strict=False))
    figure, axes = plt.subplots(2, 3, figsize=(14, 8.5))
    for ax, (name, methods) in zip(axes.flat, curves.items(), strict=False):
        for label, rows in methods.items():
            runs = [r[0] for r in rows]
            errors = [max(r[1], 1e-16) for r in rows]
            style = "-" if label.startswith("pcmb") else "--"
            ax.loglog(runs, errors, style, marker="o", ms=3, color=colors[label], label=label)
        for target in TARGETS:
            ax.axhline(target, color="0.8", lw=0.8, zorder=0)
        ax.set_title(name)
        ax.set_xlabel("runs")
        ax.set_ylabel("std error")
        ax.grid(True, which="major", alpha=0.3)
    handles, names = axes.flat[0].get_legend_handles_labels()
    axes.flat[-1].axis("off")
    axes.flat[-1].legend(handles, names, loc="center", frameon=False)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
