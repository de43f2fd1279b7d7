"""Error of the quantile bands' draws against a 10^6-draw Monte Carlo reference.

For the quarter car (a result file of ``pcmb run configs/quarter_car.yaml``) and a skewed case,
exp(t (z1/2 + 3 z2/10)) + t u/5 (z normal, u uniform, order 7): max |band - reference band| /
max std over times and outputs, RMS and worst over 10 seeds, for Monte Carlo, Latin hypercube
and scrambled Sobol' draws of several sizes, with the CPU seconds of the bands
(docs/benchmarks.md, "Quantile bands from fewer draws").

    python scripts/bench_quantile_bands.py results/quarter_car.h5
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Iterator

import numpy as np

import pcmb
from pcmb.analysis.statistics import _quantile_bands
from pcmb.chaos.nodes import draw_germs, random_nodes

LEVELS = (0.05, 0.95)
REFERENCE_DRAWS = 1_000_000
SCHEMES = [
    ("montecarlo", 20_000),
    ("montecarlo", 4096),
    ("lhs", 2048),
    ("lhs", 4096),
    ("lhs", 8192),
    ("sobol", 4096),
]


@pcmb.batched(outputs=("x",))
def skewed(params, times):
    """Lognormal in time, plus a uniform part."""
    z = 0.5 * params["z1"] + 0.3 * params["z2"]
    return {"x": np.exp(np.outer(z, times)) + 0.2 * np.outer(params["u"], times)}


def _cases(quarter_car: str) -> Iterator[tuple[str, pcmb.StudyResult]]:
    yield "quarter car", pcmb.load(quarter_car)
    inputs = {"z1": pcmb.Normal(0.0, 1.0), "z2": pcmb.Normal(0.0, 1.0), "u": pcmb.Uniform(0, 1)}
    times = np.linspace(0.0, 2.0, 41)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        method, execution = {"kind": "collocation", "order": 7}, {"backend": "inprocess"}
        yield "skewed", pcmb.Study(skewed, inputs, times, method=method, execution=execution).run()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("quarter_car", help="result file of configs/quarter_car.yaml")
    args = parser.parse_args()
    for label, result in _cases(args.quarter_car):
        germs = result.distributions
        reference = _quantile_bands(
            result, draw_germs(germs, REFERENCE_DRAWS, np.random.default_rng(12345)), LEVELS
        )
        scale = {name: np.max(result.std(name)) for name in result.outputs}
        print(f"{label}: max |band - band of 1e6 draws| / max std, over 10 seeds")
        for scheme, size in SCHEMES:
            errors, seconds = [], []
            for seed in range(10):
                xi = random_nodes(germs, size, scheme, seed).nodes
                start = time.process_time()
                bands = _quantile_bands(result, xi, LEVELS)
                seconds.append(time.process_time() - start)
                errors.append(
                    max(np.max(np.abs(bands[n] - reference[n])) / scale[n] for n in bands)
                )
            rms = float(np.sqrt(np.mean(np.square(errors))))
            print(
                f"  {scheme:<10} {size:>6}: RMS {rms:.2e}, worst {max(errors):.2e}, "
                f"bands {np.median(seconds):.3f} s CPU"
            )


if __name__ == "__main__":
    main()
