"""One simulator in every form the python door (``model.kind: python``) accepts.

The free damped oscillator x'' + c x' + k x = 0 from x(0) = x0 at rest, with outputs ``x`` and
``v`` = x'. Each form below gives pcmb the same numbers (the stacked ODE to its tolerance):
pick the one that matches how your simulator computes. docs/models.md walks through them;
python_oscillator.yaml and oscillator_api.py run them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import pcmb


def closed_form(k, c, x0, times):
    """x(t) and v(t) of the underdamped oscillator (c² < 4k); k, c, x0 broadcast together.

    Floats give (T,) arrays; (B,) arrays give (B, T) arrays.
    """
    k, c, x0 = (np.asarray(value, dtype=float)[..., None] for value in (k, c, x0))
    a, w = c / 2, np.sqrt(k - c**2 / 4)
    decay, cos, sin = np.exp(-a * times), np.cos(w * times), np.sin(w * times)
    x = x0 * decay * (cos + a / w * sin)
    v = -x0 * decay * k / w * sin
    return x, v


# 1. A per-point function: one node per call, params[name] are floats, outputs (T,).
@pcmb.pointwise(outputs=("x", "v"))
def oscillator_point(params, times):
    x, v = closed_form(params["k"], params["c"], params["x0"], times)
    return {"x": x, "v": v}


# 2. A batch function: one call per batch of B nodes, params[name] are (B,) arrays,
#    outputs (B, T).
@pcmb.batched(outputs=("x", "v"))
def oscillator_batch(params, times):
    x, v = closed_form(params["k"], params["c"], params["x0"], times)
    return {"x": x, "v": v}


# 3. A class: pcmb constructs it with model.params as keywords and calls simulate on batches.
class Oscillator:
    """The model protocol written out: ``outputs`` and ``simulate``, plus optional hints."""

    outputs = ("x", "v")

    def __init__(self, k=4.0, c=0.4, x0=1.0):
        # Optional: the nominal value of every parameter. pcmb then checks that each
        # uncertain input names one of them.
        self.parameters = {"k": k, "c": c, "x0": x0}

    def check_times(self, times):
        # Optional: refuse a grid before anything runs (pcmb validate calls it too).
        if times[0] < 0:
            raise pcmb.ConfigError("the oscillator starts at t = 0: the grid cannot start before")

    def simulate(self, params, times):
        # params holds the uncertain inputs only, each (B,) and read-only; every other
        # parameter keeps its nominal value.
        batch = len(next(iter(params.values()))) if params else 1
        p = {
            name: np.broadcast_to(params.get(name, value), (batch,))
            for name, value in self.parameters.items()
        }
        ok = p["c"] ** 2 < 4 * p["k"]  # the closed form holds for underdamped nodes only
        x, v = closed_form(np.where(ok, p["k"], 1.0), np.where(ok, p["c"], 0.0), p["x0"], times)
        # A row that is not finite is a failed run of that node; the other rows are kept.
        # (Raising fails the whole batch: pcmb then re-runs its nodes one at a time.)
        x[~ok] = v[~ok] = np.nan
        return {"x": x, "v": v}


# 4. A stacked ODE: the same physics integrated numerically, the whole batch as one system.
class OscillatorODE(pcmb.StackedODEModel):
    """x' = v, v' = -c v - k x; states (2, B), integrated by DOP853 to rtol 1e-10 per node."""

    outputs = ("x", "v")

    def __init__(self, *, rtol=1e-10, atol=1e-12, **params):
        super().__init__({"k": 4.0, "c": 0.4, "x0": 1.0}, params, rtol=rtol, atol=atol)

    def _initial_state(self, p):
        return np.stack([p["x0"], np.zeros_like(p["x0"])])

    def _rhs(self, t, y, p):
        return np.stack([y[1], -p["c"] * y[1] - p["k"] * y[0]])

    def _observe(self, times, states, p):
        return {"x": states[0], "v": states[1]}


# 5. A model factory: a small picklable object that builds the model. Each worker calls it
#    once, so expensive set-up (reading tables, compiling) happens once per process.
@dataclass(frozen=True)
class OscillatorFactory(pcmb.ModelFactory):
    k: float = 4.0
    c: float = 0.4
    x0: float = 1.0

    def __call__(self):
        return Oscillator(k=self.k, c=self.c, x0=self.x0)


FACTORY = OscillatorFactory()
