"""Two free damped oscillators x[i]'' + c x[i]' + k[i] x[i] = 0 from x[i] = 1 at rest, as a
co-simulation FMU (FMI 2.0) with array variables, for tests/test_fmu_adapter.py.

The state is advanced by the exact solution over each step. It misbehaves on purpose when
k[0] exceeds a threshold: ``discard_above`` (do_step returns False: fmi2Discard),
``raise_above`` (do_step raises: the FMU reports an error) or ``crash_above`` (the process
gets SIGSEGV). ``instances`` counts the slave objects made in this process.
"""

import math
import os
import signal

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

MADE = [0]


def exact_step(x, v, k, c, h):
    """(x, v) after h seconds of x'' + c x' + k x = 0 (underdamped)."""
    a = c / 2
    w = math.sqrt(k - a * a)
    b = (v + a * x) / w
    decay, cos, sin = math.exp(-a * h), math.cos(w * h), math.sin(w * h)
    return decay * (x * cos + b * sin), decay * (v * cos - (a * b + w * x) * sin)


class Springs(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        MADE[0] += 1
        self.k, self.x, self.v = [4.0, 9.0], [1.0, 1.0], [0.0, 0.0]
        self.c = 0.4
        self.discard_above = self.raise_above = self.crash_above = 1e300
        self.instances = float(MADE[0])
        parameter = {"causality": Fmi2Causality.parameter, "variability": Fmi2Variability.tunable}
        for i in range(2):
            self.register_variable(
                Real(
                    f"k[{i}]",
                    getter=lambda i=i: self.k[i],
                    setter=lambda value, i=i: self.k.__setitem__(i, value),
                    **parameter,
                )
            )
        for name in ("c", "discard_above", "raise_above", "crash_above"):
            self.register_variable(Real(name, **parameter))
        for i in range(2):
            self.register_variable(
                Real(f"x[{i}]", causality=Fmi2Causality.output, getter=lambda i=i: self.x[i])
            )
        self.register_variable(Real("instances", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.x, self.v = [1.0, 1.0], [0.0, 0.0]

    def do_step(self, current_time, step_size):
        if current_time > 0.5 and self.k[0] > self.crash_above:
            os.kill(os.getpid(), signal.SIGSEGV)
        if current_time > 0.5 and self.k[0] > self.raise_above:
            raise RuntimeError(f"k[0] = {self.k[0]} is too stiff")
        if current_time > 0.5 and self.k[0] > self.discard_above:
            return False
        for i in range(2):
            self.x[i], self.v[i] = exact_step(self.x[i], self.v[i], self.k[i], self.c, step_size)
        return True
