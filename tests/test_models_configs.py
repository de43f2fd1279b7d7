"""The paper-case configs of issue 3 pass pcmb's validator and say what the issue asks."""

from __future__ import annotations

import pytest
from model_loading import CONFIGS_DIR

from pcmb.config.schema import load_config

GERMS = ("xi11", "xi12", "xi21", "xi22")

# file -> (entry, inputs in germ order, order, basis, (start, stop))
EXPECTED = {
    "quarter_car": ("QuarterCar", ("A", "kT", "c"), 5, "tensor", (0.0, 3.0)),
    "quarter_car_beta": ("QuarterCar", ("A",), 5, "tensor", (0.0, 3.0)),
    "mr_damper": ("QuarterCar", ("I",), 3, "tensor", (0.0, 6.0)),
    "terrain_kl": ("QuarterCar", GERMS, 3, "tensor", (0.0, 10.0)),
    "oscillator_kl": ("CubicOscillator", GERMS, 3, "tensor", (0.0, 200.0)),
    "pendulum_ode": ("PendulumODE", ("L",), 12, "tensor", (0.0, 15.0)),
    "pendulum_dae": ("PendulumDAE", ("L",), 12, "tensor", (0.0, 15.0)),
    "double_well": ("DoubleWell", ("x0",), 7, "tensor", (0.0, 4.0)),
    "lorenz_stable": ("Lorenz", ("x0", "y0", "z0"), 5, "total", (0.0, 15.0)),
    "lorenz_chaotic": ("Lorenz", ("x0", "y0", "z0"), 5, "total", (0.0, 15.0)),
}


@pytest.mark.parametrize("stem", sorted(EXPECTED))
def test_config_is_valid_and_matches_the_issue(stem):
    config = load_config(CONFIGS_DIR / f"{stem}.yaml")  # builds the model, checks every key
    entry, inputs, order, basis, (start, stop) = EXPECTED[stem]
    assert config.model.kind == "python"
    assert config.model.entry.startswith("../models/") and config.model.entry.endswith(entry)
    assert config.input_names == inputs
    assert config.method.kind == "collocation"
    assert config.method.order == order and config.method.basis == basis
    assert (config.time.start, config.time.stop) == (start, stop)
    assert config.output == f"results/{stem}.h5"
    if inputs == GERMS:
        for spec in config.inputs.values():
            assert (spec.dist, spec.mean, spec.std) == ("normal", 0.0, 1.0)


def test_default_job_keeps_the_requested_outputs():
    config = load_config(CONFIGS_DIR / "quarter_car.yaml")
    assert config.model.outputs == ["x1", "x2"]
    assert config.times.size == 301
