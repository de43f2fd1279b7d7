"""Small models and configs written to a temporary folder for pipeline tests."""

import textwrap
from pathlib import Path

LINEAR_MODEL = '''
import os
import time

import numpy as np


class Linear:
    """y = a t + b², z = a b: closed-form statistics; optional failure and slowness."""

    outputs = ("y", "z")

    def __init__(self, a=1.0, b=0.0, fail_above=None, delay=0.0):
        self.parameters = {"a": a, "b": b}
        self.fail_above = fail_above
        self.delay = delay

    def simulate(self, params, times):
        a = np.asarray(params.get("a", self.parameters["a"]), float)
        b = np.asarray(params.get("b", self.parameters["b"]), float)
        a, b = np.broadcast_arrays(a, b)
        if self.delay:
            time.sleep(self.delay * a.size)
        y = a[:, None] * times + b[:, None] ** 2
        if self.fail_above is not None:
            if a.size == 1 and a[0] > self.fail_above:
                raise RuntimeError(f"blew up at a={a[0]}")
            y[a > self.fail_above] = np.nan
        return {"y": y, "z": np.repeat((a * b)[:, None], times.size, axis=1)}
'''


def write_study(folder: Path, *, order=3, extra_params="", execution="jobs: 1", name="linear"):
    """A model file and a config for it; returns the config path."""
    (folder / "linear_model.py").write_text(LINEAR_MODEL)
    config = folder / f"{name}.yaml"
    config.write_text(
        textwrap.dedent(
            f"""\
            name: {name}
            model:
              kind: python
              entry: linear_model.py:Linear
              params: {{a: 1.0, b: 0.0{extra_params}}}
              outputs: [y, z]
            time: {{start: 0.0, stop: 2.0, points: 5}}
            inputs:
              a: {{dist: uniform, low: 1.0, high: 3.0}}
              b: {{dist: normal, mean: 0.0, std: 1.0}}
            method: {{kind: collocation, order: {order}}}
            execution: {{{execution}}}
            output: {folder / "out.h5"}
            """
        )
    )
    return config
