"""Stochastic Galerkin (method kind galerkin): the products from 1-D integrals, convergence to
the collocation statistics on the quarter car with its cubic spring, the study end to end, and
the refusal of models without a polynomial form."""

from __future__ import annotations

import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import pcmb
from pcmb.chaos.basis import tensor_index_set, total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Normal, Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.config import validate_config
from pcmb.designs.galerkin import GalerkinSystem
from pcmb.designs.polynomial_form import PolynomialForm, PolynomialSpace
from pcmb.errors import ConfigError, PcmbWarning

MODELS = Path(__file__).resolve().parents[1] / "models"
sys.path.insert(0, str(MODELS))

from quarter_car import QuarterCar  # noqa: E402

QC_INPUTS = ("A", "kT", "c")
QC_DISTS = (Uniform(0.025, 0.075), Uniform(1.2e5, 1.8e5), Uniform(800.0, 1200.0))


def _orthonormal_1d(family: str, degree: int, x: np.ndarray) -> np.ndarray:
    """(len(x), degree + 1) orthonormal Legendre (uniform on [-1, 1]) or probabilists' Hermite
    polynomials from numpy's own classes: independent of pcmb's recurrences."""
    columns = []
    for k in range(degree + 1):
        if family == "legendre":
            p = np.polynomial.Legendre.basis(k)(x) * math.sqrt(2 * k + 1)
        else:
            p = np.polynomial.HermiteE.basis(k)(x) / math.sqrt(math.factorial(k))
        columns.append(p)
    return np.stack(columns, axis=1)


def _product_table_1d(family: str, degree: int, count: int) -> np.ndarray:
    """E[p_a1 ... p_a_count] for a_i <= degree, (degree + 1,) * count, by numpy's Gauss rules
    with enough points to be exact."""
    q = (count * degree) // 2 + 1
    if family == "legendre":
        x, w = np.polynomial.legendre.leggauss(q)
        w = w / 2
    else:
        x, w = np.polynomial.hermite_e.hermegauss(q)
        w = w / math.sqrt(2 * math.pi)
    values = _orthonormal_1d(family, degree, x)
    letters = "abcdefgh"[:count]
    return np.einsum(",".join(f"q{c}" for c in letters) + ",q->" + letters, *[values] * count, w)


def test_hermite_triple_products_match_their_closed_form():
    # E[He_a He_b He_c] = a! b! c! / ((s-a)! (s-b)! (s-c)!), s = (a+b+c)/2 (a+b+c even,
    # triangle inequality), divided by sqrt(a! b! c!) for the orthonormal family.
    table = _product_table_1d("hermite", 4, 3)
    for a, b, c in itertools.product(range(5), repeat=3):
        s2 = a + b + c
        s = s2 // 2
        exact = 0.0
        if s2 % 2 == 0 and s >= max(a, b, c):
            f = math.factorial
            exact = f(a) * f(b) * f(c) / (f(s - a) * f(s - b) * f(s - c))
            exact /= math.sqrt(f(a) * f(b) * f(c))
        assert table[a, b, c] == pytest.approx(exact, abs=1e-10)


class _Toy:
    """x' = -θ1 x³ + θ2 x y,  y' = -y + θ1 θ2 sin(t) + x²: cubic and quartic products."""

    outputs = ("x", "y")

    def polynomial_form(self, inputs):
        space = PolynomialSpace(("x", "y"), inputs, ("sine",))
        t1, t2 = space.inputs["t1"], space.inputs["t2"]
        x, y = space.states
        (sine,) = space.forcing
        return PolynomialForm(
            space,
            rhs=(-t1 * x**3 + t2 * x * y, -y + t1 * t2 * sine + x**2),
            initial=(1.0 + 0.1 * t2, 0.0),
            outputs={"x": x, "y": y},
            forcing=lambda t: np.array([np.sin(t)]),
        )


def test_galerkin_right_hand_side_is_the_contraction_with_products_from_1d_integrals():
    # Inputs t1 = 1 + 0.2 ξ1 (Legendre) and t2 = 0.5 + 0.1 ξ2 (Hermite), total order 2.
    dists = (Uniform(0.8, 1.2), Normal(0.5, 0.1))
    index = total_index_set(2, 2)
    system = GalerkinSystem(_Toy().polynomial_form(("t1", "t2")), dists, index, ["x", "y"])
    rng = np.random.default_rng(4)
    coefficients = rng.normal(size=(2, index.shape[0])) * 0.5
    t = 0.7
    derivative = system.derivative(t, coefficients)

    # Explicit Galerkin tensors E[φ_a φ_b ...] = Π_k (1-D tables), with the inputs as
    # expansions: t1 = 1 φ_0 + 0.2/√3 φ_(1,0), t2 = 0.5 φ_0 + 0.1 φ_(0,1).
    def tensor(count):
        legendre = _product_table_1d("legendre", 2, count)
        hermite = _product_table_1d("hermite", 2, count)
        grids = np.ix_(*[np.arange(index.shape[0])] * count)
        first = legendre[tuple(index[g, 0] for g in grids)]
        return first * hermite[tuple(index[g, 1] for g in grids)]

    def position(alpha):
        return int(np.flatnonzero((index == alpha).all(axis=1))[0])

    t1 = np.zeros(index.shape[0])
    t1[position((0, 0))], t1[position((1, 0))] = 1.0, 0.2 / math.sqrt(3)
    t2 = np.zeros(index.shape[0])
    t2[position((0, 0))], t2[position((0, 1))] = 0.5, 0.1
    x, y = coefficients
    c3, c4, c5 = tensor(3), tensor(4), tensor(5)
    expected_x = -np.einsum("abcde,b,c,d,e->a", c5, t1, x, x, x) + np.einsum(
        "abcd,b,c,d->a", c4, t2, x, y
    )
    expected_y = (
        -y + np.einsum("abc,b,c->a", c3, t1, t2) * np.sin(t) + np.einsum("abc,b,c->a", c3, x, x)
    )
    np.testing.assert_allclose(derivative[0], expected_x, atol=1e-13)
    np.testing.assert_allclose(derivative[1], expected_y, atol=1e-13)


def _collocation(model, orders, times):
    grid = TensorGrid(QC_DISTS, orders)
    values = model.simulate(dict(zip(QC_INPUTS, grid.params.T, strict=True)), times)["x1"]
    index = grid.multi_index
    return ChaosExpansion(project_tensor(grid, values, index), index, QC_DISTS, QC_INPUTS)


def _error(expansion, reference):
    scale = reference.std().max()
    return (
        max(
            np.abs(expansion.mean() - reference.mean()).max(),
            np.abs(expansion.std() - reference.std()).max(),
        )
        / scale
    )


@pytest.mark.slow
def test_galerkin_converges_geometrically_to_the_collocation_statistics_of_the_quarter_car():
    # Both methods are spectral in the order for this smooth response: their errors fall
    # geometrically with P towards the same limit. The reference is collocation of order 8,
    # whose own error (bounded by its distance to order 7, measured 3e-5) must be far below
    # the Galerkin errors it measures.
    model = QuarterCar()
    times = np.linspace(0.0, 1.5, 151)
    reference = _collocation(model, (8, 8, 8), times)
    resolution = _error(_collocation(model, (7, 7, 7), times), reference)
    assert resolution < 1e-4
    form = model.polynomial_form(QC_INPUTS)
    orders = np.array([1, 2, 3, 4])
    errors = []
    for order in orders:
        index = tensor_index_set((int(order),) * 3)
        system = GalerkinSystem(form, QC_DISTS, index, ["x1"])
        coefficients = system.output_coefficients(system.solve(times), times)[0]
        errors.append(_error(ChaosExpansion(coefficients, index, QC_DISTS, QC_INPUTS), reference))
    errors = np.array(errors)
    assert errors[-1] > 3 * resolution  # the reference resolves every Galerkin error
    # Both are spectral projections onto the same space at order P, so their errors track
    # each other up to an O(1) factor (quasi-optimality); the check is against collocation of
    # the same order, not against numbers this test printed. Every error is also below the
    # one two orders lower (uniform inputs make odd and even orders gain unevenly).
    collocation = np.array(
        [_error(_collocation(model, (int(p),) * 3, times), reference) for p in orders]
    )
    assert np.all(errors < 3 * collocation), (errors, collocation)
    assert np.all(errors[2:] < errors[:-2] / 5), errors


def test_galerkin_study_end_to_end_stores_and_loads_like_collocation(tmp_path):
    times = np.linspace(0.0, 1.0, 51)
    study = pcmb.Study(
        QuarterCar,
        dict(zip(QC_INPUTS, QC_DISTS, strict=True)),
        times,
        method="galerkin",
        order=2,
        basis="total",
        outputs=["x1", "z"],
        jobs=1,
        validation=4,
    )
    # The held-out runs check the expansion as they check collocation's: order 2 is too low
    # for x1 by the end of the second (4 runs find it or say they cannot tell).
    with pytest.warns(PcmbWarning, match="x1: .*(chaos unreliable|cannot tell whether)"):
        result = study.run(tmp_path / "g.h5", progress=False)
    loaded = pcmb.load(tmp_path / "g.h5")
    assert loaded.design.kind == "galerkin" and loaded.n_nodes == 0
    assert loaded.multi_index.shape == (10, 3)
    for name in ("x1", "z"):
        np.testing.assert_array_equal(loaded.mean(name), result.mean(name))
        np.testing.assert_array_equal(loaded.std(name), result.std(name))
        assert loaded.sobol_total(name).shape == (3, times.size)
    # The terrain z = A sin(2π t) is linear in A: its expansion is exact at any order.
    a = QC_DISTS[0]
    np.testing.assert_allclose(
        loaded.std("z"),
        (a.high - a.low) / math.sqrt(12) * np.abs(np.sin(2 * np.pi * times)),
        atol=1e-15,
    )
    assert loaded.held_out is not None and loaded.held_out.ok.all()


def _config(**model_params):
    return {
        "name": "galerkin-check",
        "model": {
            "kind": "python",
            "entry": str(MODELS / "quarter_car.py") + ":QuarterCar",
            "params": {"Ms": 250.0, "kT": 1.5e5, **model_params},
        },
        "time": {"start": 0.0, "stop": 1.0, "points": 11},
        "inputs": {"kT": {"dist": "uniform", "low": 1.2e5, "high": 1.8e5}},
        "method": {"kind": "galerkin", "order": 2},
    }


def test_validate_refuses_a_model_that_is_not_polynomial_naming_method_kind():
    with pytest.raises(ConfigError) as caught:
        validate_config(_config(damper="mr"))
    (problem,) = caught.value.problems
    assert problem.path == "method.kind"
    assert "not polynomial" in problem.message


def test_validate_refuses_an_uncertain_mass_and_a_model_without_the_protocol():
    data = _config()
    data["inputs"] = {"Ms": {"dist": "uniform", "low": 200.0, "high": 300.0}}
    with pytest.raises(ConfigError, match=r"method\.kind: galerkin.*\['Ms'\]"):
        validate_config(data)
    data = {
        **_config(),
        "model": {
            "kind": "python",
            "entry": str(MODELS / "double_well.py") + ":DoubleWell",
            "params": {"x0": 0.0},
        },
        "inputs": {"x0": {"dist": "uniform", "low": -0.5, "high": 0.5}},
    }
    with pytest.raises(ConfigError, match=r"method\.kind: galerkin needs a model that declares"):
        validate_config(data)


def test_validate_accepts_the_quarter_car():
    config = validate_config(_config())
    assert config.method.kind == "galerkin"
