"""The free damped oscillator x'' + c x' + k x = 0 as a co-simulation FMU (FMI 2.0).

Built into ``DampedOscillator.fmu`` by ``python scripts/build_fmus.py`` (pythonfmu; see
docs/models.md) and run by configs/fmu_oscillator.yaml. Each communication step advances the
state (x, v) by the exact solution over the step, so the FMU's outputs at the communication
points are the closed form (pcmb.references.damped_oscillator) to rounding: whatever the
step, the only error left is where the steps land.

Parameters (tunable): k, c (per unit mass; c² < 4k), x0, v0 (the state at the start time).
Outputs: x, v.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class DampedOscillator(Fmi2Slave):
    author = "pcmb"
    description = "free damped oscillator x'' + c x' + k x = 0, stepped exactly"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k, self.c, self.x0, self.v0 = 4.0, 0.4, 1.0, 0.0
        self.x, self.v = self.x0, self.v0
        for name in ("k", "c", "x0", "v0"):
            self.register_variable(
                Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
            )
        for name in ("x", "v"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.x, self.v = self.x0, self.v0

    def do_step(self, current_time, step_size):
        a = self.c / 2
        if self.k <= a * a:
            return False  # the exact step below is for underdamped oscillators only
        w = math.sqrt(self.k - a * a)
        b = (self.v + a * self.x) / w
        decay, cos, sin = math.exp(-a * step_size), math.cos(w * step_size), math.sin(w * step_size)
        self.x, self.v = (
            decay * (self.x * cos + b * sin),
            decay * (self.v * cos - (a * b + w * self.x) * sin),
        )
        return True
