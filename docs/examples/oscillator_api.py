"""The study of python_oscillator.yaml built in Python, for every form in damped_oscillator.py.

    python docs/examples/oscillator_api.py

prints the mean and standard deviation of x at t = 5 s by each form: the same numbers (the
stacked ODE to its integration tolerance).
"""

import numpy as np
from damped_oscillator import FACTORY, Oscillator, OscillatorODE, oscillator_batch, oscillator_point

import pcmb

INPUTS = {"k": pcmb.Uniform(3.5, 4.5), "c": pcmb.Uniform(0.2, 0.6)}  # ordered: the germ order
TIMES = np.linspace(0.0, 5.0, 101)
PARAMS = {"k": 4.0, "c": 0.4, "x0": 1.0}  # nominal values; k and c change per node


def main(jobs=None):  # jobs None: as many workers as cores, when workers pay
    forms = {
        "class": (Oscillator, PARAMS),
        "per-point function": (oscillator_point, PARAMS),
        "batch function": (oscillator_batch, PARAMS),
        "stacked ODE": (OscillatorODE, PARAMS),
        "factory": (FACTORY, None),  # a factory takes no params
    }
    results = {}
    for label, (model, params) in forms.items():
        study = pcmb.Study(model, INPUTS, TIMES, order=4, params=params, jobs=jobs)
        results[label] = study.run()  # study.run("results/oscillator.h5") also writes a file
        mean, std = results[label].mean("x")[-1], results[label].std("x")[-1]
        print(f"{label:>18}: x(5) mean {mean:+.10f}, std {std:.10f}")
    return results


if __name__ == "__main__":
    main()
