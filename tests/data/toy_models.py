"""Small closed-form models for the config and adapter tests (no integration).

``Decay`` is y(t) = y0 exp(-k t), dy = -k y: batch-capable, declares its parameters.
``decay_point`` is the same law as a per-point function, ``decay_batch`` as a batch function;
``plain_point`` is the per-point law without a marker (which pcmb refuses).
"""

import numpy as np

from pcmb.adapters.python import batched, pointwise


class Decay:
    """Exponential decay, vectorised over the batch."""

    outputs = ("y", "dy")

    def __init__(self, k=1.0, y0=1.0):
        if not k > 0:
            raise ValueError(f"k must be > 0, got {k}")
        self.parameters = {"k": float(k), "y0": float(y0)}

    def simulate(self, params, times):
        unknown = set(params) - set(self.parameters)
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}")
        values = {
            name: np.asarray(params.get(name, nominal), dtype=float)
            for name, nominal in self.parameters.items()
        }
        batch = max((v.size for v in values.values()), default=1)
        k = np.broadcast_to(values["k"], (batch,))[:, None]
        y0 = np.broadcast_to(values["y0"], (batch,))[:, None]
        y = y0 * np.exp(-k * np.asarray(times)[None, :])
        return {"y": y, "dy": -k * y}


class Silent:
    """A model that does not declare its parameters."""

    outputs = ("y",)

    def simulate(self, params, times):
        batch = len(next(iter(params.values()))) if params else 1
        return {"y": np.zeros((batch, len(times)))}


class NotAModel:
    """Constructs fine but has no simulate."""

    def __init__(self, **params):
        self.params = params


@pointwise(outputs=("y", "dy"))
def decay_point(params, times):
    """One node of the decay law."""
    y = params["y0"] * np.exp(-params["k"] * times)
    if params.get("fail", 0.0) > 0.5:
        raise RuntimeError("asked to fail")
    return {"y": y, "dy": -params["k"] * y}


@batched(outputs=("y", "dy"))
def decay_batch(params, times):
    """The decay law for a batch: every parameter is a (B,) array."""
    k, y0 = params["k"][:, None], params["y0"][:, None]
    y = y0 * np.exp(-k * times)
    return {"y": y, "dy": -k * y}


@pointwise
def undeclared_point(params, times):
    """A per-point function that does not declare its outputs."""
    return {"y": np.zeros_like(times)}


def plain_point(params, times):
    """A per-point function without a marker."""
    return {"y": params["y0"] * np.exp(-params["k"] * times)}


plain_point.outputs = ("y",)


@pointwise(outputs=("y",))
def scalar_point(params, times):
    """Returns a number where a (T,) array is due."""
    return {"y": params["k"]}


DECAY = Decay(k=2.0)
NUMBER = 3
