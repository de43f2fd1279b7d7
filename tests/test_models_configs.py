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


@pytest.mark.slow
def test_the_ishigami_config_gives_its_closed_form_statistics(tmp_path):
    import h5py
    import numpy as np

    import pcmb
    from pcmb.cli import main
    from pcmb.references import ishigami_moments

    out = tmp_path / "ishigami.h5"
    assert main(["run", str(CONFIGS_DIR / "ishigami.yaml"), "-o", str(out), "--quiet"]) == 0
    result, exact = pcmb.load(out), ishigami_moments()
    with h5py.File(out) as file:
        assert file["outputs/y/values"].shape == (result.n_nodes,)  # one number per run
    # The adaptive grid's tolerance is 1e-4 of the std; the estimate is honest within 10x.
    scale = np.sqrt(exact.variance)
    assert abs(result.mean("y").item() - exact.mean) <= 1e-3 * scale
    assert abs(result.std("y").item() - scale) <= 1e-3 * scale
    np.testing.assert_allclose(np.ravel(result.sobol_total("y")), exact.total, atol=1e-3)


def test_the_borehole_model_is_the_reference_function():
    import numpy as np
    from model_loading import model_class

    from pcmb.references import borehole, borehole_bounds

    model = model_class("test_functions", "Borehole")()
    low, high = np.array(borehole_bounds()).T
    x = low + (high - low) * np.random.default_rng(3).random((5, 8))
    names = ("rw", "r", "Tu", "Hu", "Tl", "Hl", "L", "Kw")
    found = model.simulate({n: x[:, k] for k, n in enumerate(names)}, np.array([0.0, 1.0]))
    np.testing.assert_array_equal(found["y"], borehole(x))
    # Harper & Gupta's nominal flow at the middle of the ranges is about 73 m³/year.
    assert 60 < model.simulate({}, np.array([0.0]))["y"][0] < 90
