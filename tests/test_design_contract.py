"""Every registered design honours its contract (pcmb.designs): node designs NodeDesign,
intrusive ones IntrusiveDesign."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

import pcmb
from pcmb.designs import DESIGNS, METHOD_KINDS, MethodSettings, make_design, method_section
from pcmb.designs.polynomial_form import PolynomialForm, PolynomialSpace
from pcmb.result import Design

INPUTS = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.5, 0.2)}

#: The smallest sensible settings per method kind; a new design adds its own here.
EXAMPLES = {
    "collocation": MethodSettings("collocation", orders=(2, 3)),
    "montecarlo": MethodSettings("montecarlo", samples=64, seed=3),
    "lhs": MethodSettings("lhs", samples=64, seed=3, fit="regression", orders=(2, 2)),
    "sobol": MethodSettings("sobol", samples=64, seed=3),
    "halton": MethodSettings("halton", samples=50, seed=3, fit="regression", orders=(2, 2)),
    "collocation:smolyak": MethodSettings("collocation", grid="smolyak", level=2),
    "collocation:elements": MethodSettings("collocation", orders=(2, 2), elements={"a": [2.0]}),
    "regression": MethodSettings(
        "regression", orders=(3, 3), samples=32, seed=3, q=0.75, selection="lars"
    ),
    "adaptive": MethodSettings("adaptive", tolerance=1e-3, max_runs=200),
    "adaptive:tensor": MethodSettings("adaptive", tolerance=1e-3, max_runs=200, basis="tensor"),
    "collocation:refine": MethodSettings(
        "collocation", orders="auto", diagnostics_tolerance=0.05, max_runs=100
    ),
    "galerkin": MethodSettings("galerkin", orders=(1, 2), basis="total"),
    "linearization": MethodSettings("linearization"),
}
#: ``Design.fit`` of the designs that recover an expansion.
EXPANSION_FITS = ("projection", "regression", "lars", "omp", "ols")


def test_every_registered_kind_has_an_example():
    assert set(EXAMPLES) == set(DESIGNS)


@pytest.fixture(params=sorted(DESIGNS))
def design(request):
    return make_design(INPUTS, EXAMPLES[request.param])


def test_nodes_are_germs_mapped_to_physical_values(design):
    nodes = design.nodes()
    n = len(INPUTS)
    assert nodes.nodes.shape == nodes.params.shape and nodes.nodes.shape[1] == n
    for k, dist in enumerate(INPUTS.values()):
        np.testing.assert_allclose(nodes.params[:, k], dist.to_physical(nodes.nodes[:, k]))
    weights = design.weights(nodes)
    if weights is not None:  # a sparse grid's weights sum to one, some are negative
        assert weights.shape == (nodes.size,) and np.all(np.isfinite(weights))
        assert abs(weights.sum() - 1.0) < 1e-12


def test_the_record_says_how_the_nodes_were_made_and_round_trips(design):
    record = design.record()
    nodes = design.nodes()
    assert isinstance(record, Design) and record.kind in METHOD_KINDS
    assert record.label  # the design labels itself: nothing downstream branches on its kind
    assert Design.from_description(record.describe()) == record
    if record.samples is not None:
        assert record.samples == nodes.size
    if record.grid == "tensor-gauss":
        assert nodes.size == int(np.prod(np.add(record.orders, 1)))


def test_recovery_reproduces_an_affine_response(design):
    """y = 2 + 3 a - b, linear in the physical inputs: every expansion of order >= 1 holds
    it exactly, so its mean and std are the exact ones to round-off. An intrusive design
    solves y' = 2 + 3 a - b from y(0) = 2 + 3 a - b, whose solution is the same response;
    linear in the inputs, its mean and std depend on their first two moments only, so
    linearization is exact too."""
    nodes = design.nodes()
    times = np.linspace(0.0, 1.0, 3)
    a, b = INPUTS.values()
    mean = 2.0 + 3.0 * a.expectation() - b.expectation()
    std = np.sqrt(9.0 * (2.0**2 / 12.0) + 0.2**2)
    if not hasattr(design, "recover"):
        assert design.runs == 0 and nodes.size == 0
        assert design.check(_Affine(), None) == []
        recovery = design.solve(_Affine(), times, ["y"])
        for name, (found_mean, found_std) in recovery.moments.items():
            assert name == "y"
            np.testing.assert_allclose(found_mean, mean * (1.0 + times), rtol=1e-9)
            np.testing.assert_allclose(found_std, std * (1.0 + times), rtol=1e-9)
    else:
        response = 2.0 + 3.0 * nodes.params[:, 0] - nodes.params[:, 1]
        values = {"y": response[:, None] * (1.0 + times)}
        recovery = design.recover(nodes, values, np.ones(nodes.size, dtype=bool))
    for expansion in recovery.expansions.values():
        np.testing.assert_allclose(expansion.mean(), mean * (1.0 + times), rtol=1e-12)
        np.testing.assert_allclose(expansion.std(), std * (1.0 + times), rtol=1e-10)
    expected_fit = design.record().fit in (*EXPANSION_FITS, "galerkin")
    assert bool(recovery.expansions) == expected_fit
    assert bool(recovery.expansions) or bool(recovery.moments) or design.record().fit == "none"


class _Affine:
    """y' = 2 + 3 a - b, y(0) = 2 + 3 a - b: y = (2 + 3 a - b)(1 + t)."""

    outputs = ("y",)

    def polynomial_form(self, inputs):
        space = PolynomialSpace(("y",), inputs)
        a, b = space.inputs["a"], space.inputs["b"]
        response = 2.0 + 3.0 * a - b
        (y,) = space.states
        return PolynomialForm(space, rhs=(response,), initial=(response,), outputs={"y": y})


def test_unusable_settings_name_their_key():
    with pytest.raises(ValueError, match=r"^method\.order:"):
        make_design(INPUTS, MethodSettings("collocation"))
    with pytest.raises(ValueError, match=r"^method\.samples:"):
        make_design(INPUTS, MethodSettings("lhs", samples=1))
    with pytest.raises(ValidationError, match="kriging"):  # refused by the method: union
        method_section({"kind": "kriging"})
