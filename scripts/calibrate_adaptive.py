"""How honest kind adaptive's error estimate is: its estimate against the true error of the
mean and std, on functions whose moments are known in closed form.

For each function and tolerance 1e-2 .. 1e-6 the adaptive design runs in this process (no
workers, no held-out check) to ``--max-runs``; the true error is max(|Δmean|, |Δstd|) / std
against the closed form, the quantity ``method.tolerance`` names. ``estimate/true`` > 1 is a
careful estimate, < 1 an over-confident one; ``true/tolerance`` is what the tolerance
delivered; ``nonsmooth`` whether an ``adaptive-nonsmooth`` warning came.

The estimate's form (see :mod:`pcmb.designs.adaptive`) was chosen on exp8 and
genz_oscillatory; lognormal6, ishigami3 and genz_gaussian validate it (g_function is not
smooth: the estimate cannot see its kink, the warning must).

    python scripts/calibrate_adaptive.py [exp8,genz_oscillatory,...] [--max-runs 6000]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
from scipy.special import erf

import pcmb
from pcmb.chaos.nodes import NodeSet
from pcmb.designs import MethodSettings, make_design
from pcmb.references import ishigami, ishigami_moments

Case = tuple[dict, Callable[[np.ndarray], np.ndarray], float, float]


def _unit(n: int) -> dict:
    return {f"x{k}": pcmb.Uniform(0.0, 1.0) for k in range(n)}


def exp8() -> Case:
    """exp(Σ c_k x_k), 8 uniform inputs of falling weight."""
    c = np.array([1.0, 0.8, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1])
    mean = np.prod(np.expm1(c) / c)
    second = np.prod(np.expm1(2 * c) / (2 * c))
    return _unit(8), lambda x: np.exp(x @ c), mean, np.sqrt(second - mean**2)


def genz_gaussian() -> Case:
    """Genz's Gaussian peak exp(-Σ a_k² (x_k - w_k)²) in 10 uniform inputs."""
    a, w = np.linspace(1.0, 3.0, 10), np.linspace(0.3, 0.7, 10)

    def integral(b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.pi) / (2 * b) * (erf(b * (1 - w)) + erf(b * w))

    mean, second = np.prod(integral(a)), np.prod(integral(np.sqrt(2) * a))
    return (
        _unit(10),
        lambda x: np.exp(-(((x - w) * a) ** 2).sum(axis=1)),
        mean,
        np.sqrt(second - mean**2),
    )


def genz_oscillatory() -> Case:
    """Genz's oscillatory cos(2π w + Σ a_k x_k) in 6 uniform inputs."""
    a, w = np.array([1.5, 1.2, 1.0, 0.8, 0.6, 0.4]), 0.3

    def phi(b: np.ndarray) -> complex:
        return np.prod((np.exp(1j * b) - 1) / (1j * b))

    mean = float(np.real(np.exp(2j * np.pi * w) * phi(a)))
    second = 0.5 + 0.5 * float(np.real(np.exp(4j * np.pi * w) * phi(2 * a)))
    return _unit(6), lambda x: np.cos(2 * np.pi * w + x @ a), mean, np.sqrt(second - mean**2)


def g_function() -> Case:
    """Sobol's G-function Π (|4 x_k - 2| + a_k) / (1 + a_k), 8 inputs: a kink at 1/2."""
    a = np.array([0.0, 1.0, 4.5, 9.0, 99.0, 99.0, 99.0, 99.0])
    second = np.prod(1 + 1 / (3 * (1 + a) ** 2))
    return (
        _unit(8),
        lambda x: np.prod((np.abs(4 * x - 2) + a) / (1 + a), axis=1),
        1.0,
        np.sqrt(second - 1),
    )


def lognormal6() -> Case:
    """exp(Σ b_k z_k), 6 standard normal inputs (Hermite chaos, heavy right tail)."""
    b = np.array([0.4, 0.3, 0.25, 0.2, 0.1, 0.05])
    inputs = {f"z{k}": pcmb.Normal(0.0, 1.0) for k in range(6)}
    s = float((b**2).sum())
    return inputs, lambda x: np.exp(x @ b), np.exp(s / 2), np.sqrt(np.exp(2 * s) - np.exp(s))


def ishigami3() -> Case:
    """Ishigami's sin x1 + 7 sin² x2 + 0.1 x3⁴ sin x1 on [-π, π]³."""
    inputs = {name: pcmb.Uniform(-np.pi, np.pi) for name in ("x1", "x2", "x3")}
    moments = ishigami_moments()
    return inputs, ishigami, moments.mean, np.sqrt(moments.variance)


CASES = {
    f.__name__: f
    for f in (exp8, genz_gaussian, genz_oscillatory, g_function, lognormal6, ishigami3)
}


def run(case: str, tolerance: float, max_runs: int) -> tuple[int, float, float, str]:
    """(runs, the design's final estimate, the true error, whether an
    ``adaptive-nonsmooth`` warning came) of one adaptive study."""
    inputs, function, mean, std = CASES[case]()
    design = make_design(inputs, MethodSettings("adaptive", tolerance=tolerance, max_runs=max_runs))
    first = design.nodes()
    germ, params = first.nodes, first.params
    values = function(params)[:, None]
    while True:
        nodes = NodeSet(first.distributions, germ, params)
        more = design.more(nodes, {"y": values}, np.ones(len(germ), bool))
        if more is None:
            break
        germ, params = np.vstack([germ, more.nodes]), np.vstack([params, more.params])
        values = np.concatenate([values, function(more.params)[:, None]])
    recovery = design.recover(nodes, {"y": values}, np.ones(len(germ), bool), np.zeros(1))
    expansion = recovery.expansions["y"]
    error = max(abs(expansion.mean()[0] - mean), abs(expansion.std()[0] - std)) / std
    nonsmooth = [w.message for w in recovery.warnings if w.code == "adaptive-nonsmooth"]
    return len(germ), recovery.adaptive.estimate, float(error), "yes" if nonsmooth else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="?", default=",".join(CASES))
    parser.add_argument("--max-runs", type=int, default=6000)
    args = parser.parse_args()
    print(
        "| function | tolerance | runs | estimate | true error | estimate/true | true/tolerance |"
        " nonsmooth |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---|")
    for case in args.cases.split(","):
        for tolerance in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6):
            runs, estimate, error, nonsmooth = run(case, tolerance, args.max_runs)
            print(
                f"| {case} | {tolerance:.0e} | {runs} | {estimate:.2e} | {error:.2e} | "
                f"{estimate / error:.2g} | {error / tolerance:.2g} | {nonsmooth} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
