"""The free damped oscillator x'' + c x' + k x = 0 as an FMI 3.0 FMU with both interfaces
and units, for tests/test_fmu_adapter.py: as model exchange FMPy's CVode integrates it; as
co-simulation each step advances the state by the exact solution. Its derivatives are NaN
once the time passes ``fail_after``, which CVode cannot integrate (a failing run; raising
there would crash pythonfmu3's FMU)."""

import math

from pythonfmu3 import (
    CoSimulation,
    Float64,
    Fmi3Causality,
    Fmi3Initial,
    Fmi3SlaveBase,
    Fmi3Variability,
    ModelExchange,
    Unit,
)


class Oscillator3(Fmi3SlaveBase, ModelExchange, CoSimulation):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.x, self.v, self.der_x, self.der_v = 1.0, 0.0, 0.0, 0.0
        self.k, self.c, self.fail_after = 4.0, 0.4, 1e300
        self.register_units([Unit("m"), Unit("m/s"), Unit("m/s2"), Unit("1/s"), Unit("1/s2")])
        continuous = Fmi3Variability.continuous
        self.register_variable(
            Float64("time", causality=Fmi3Causality.independent, variability=continuous)
        )
        states = (("x", "m", "m/s", 1), ("v", "m/s", "m/s2", 3))  # reference: x's, v's
        for name, unit, derivative_unit, reference in states:
            self.register_variable(
                Float64(
                    name,
                    causality=Fmi3Causality.output,
                    start=getattr(self, name),
                    variability=continuous,
                    initial=Fmi3Initial.exact,
                    unit=unit,
                )
            )
            self.register_variable(
                Float64(
                    f"der_{name}",
                    causality=Fmi3Causality.local,
                    variability=continuous,
                    derivative=reference,
                    unit=derivative_unit,
                )
            )
        for name, unit in (("k", "1/s2"), ("c", "1/s")):
            self.register_variable(
                Float64(
                    name,
                    causality=Fmi3Causality.parameter,
                    variability=Fmi3Variability.tunable,
                    start=getattr(self, name),
                    unit=unit,
                )
            )
        self.register_variable(
            Float64(
                "fail_after",
                causality=Fmi3Causality.parameter,
                variability=Fmi3Variability.tunable,
                start=self.fail_after,
            )
        )

    def get_continuous_state_derivatives(self):
        if self.time > self.fail_after:
            return [math.nan, math.nan]
        self.der_x = self.v
        self.der_v = -self.k * self.x - self.c * self.v
        return [self.der_x, self.der_v]

    def do_step(self, current_time, step_size):
        a = self.c / 2
        w = math.sqrt(self.k - a * a)
        b = (self.v + a * self.x) / w
        decay, cos, sin = math.exp(-a * step_size), math.cos(w * step_size), math.sin(w * step_size)
        self.x, self.v = (
            decay * (self.x * cos + b * sin),
            decay * (self.v * cos - (a * b + w * self.x) * sin),
        )
        self.time = current_time + step_size
        return True
