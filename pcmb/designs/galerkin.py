"""Stochastic Galerkin (``method: {kind: galerkin, order, basis}``): the coupled ODE of the
chaos coefficients of a model whose right-hand side is polynomial (Part I Eq. 31–34, Part II
Eq. 7–9), solved as one task in a worker. See ``docs/methods.md``.

Every state is an expansion x_i(t, ξ) = Σ_b X_ib(t) φ_b(ξ); projecting the right-hand side on
each φ_a gives dX_ia/dt = E[f_i(x(ξ), θ(ξ), g(t)) φ_a]. For a term c·x_j x_k x_l that is
c Σ X_jb X_kc X_ld E[φ_a φ_b φ_c φ_d]: the quadruple products, each a product over the inputs
of 1-D integrals E[p_a p_b p_c p_d]. They are applied in factored form: on the tensor Gauss
grid that integrates the term's degree exactly, E[φ_a φ_b φ_c φ_d] = Σ_q w_q φ_a φ_b φ_c φ_d
(μ_q), so the contraction is states at the points (X Vᵀ), the polynomial there, and a weighted
projection back — O(S·Q) per evaluation instead of the S⁴ entries of the dense tensor, and
the same numbers up to round-off (tests/test_galerkin.py builds the tensors from 1-D integrals
and checks it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.basis import PolynomialBasis, tensor_index_set, total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import TensorGrid
from pcmb.config.types import OrderSpec
from pcmb.designs.base import (
    MethodSection,
    MethodSettings,
    Recovery,
    order_words,
    statistics_warnings,
)
from pcmb.designs.intrusive import WithoutNodes, form_problems, polynomial_form
from pcmb.designs.polynomial_form import CompiledPolynomials, PolynomialForm
from pcmb.result import Design

__all__ = ["Galerkin", "GalerkinSettings", "GalerkinSystem"]

BASES = ("tensor", "total")


class GalerkinSystem:
    """The coefficient ODE of a polynomial form in a chaos basis, with its exact quadrature.

    Parameters
    ----------
    form:
        The model's polynomial form.
    distributions:
        The n inputs, germ order (those of ``form.space.input_names``).
    index:
        (S, n) the basis's multi-indices (must contain the zero index).
    outputs:
        The outputs to expand.

    Attributes
    ----------
    points:
        The tensor Gauss grid: per input, enough points to integrate every term times a basis
        function exactly (inputs affine in their germ, as every Askey-scheme input is).
    """

    def __init__(
        self,
        form: PolynomialForm,
        distributions: Sequence[Distribution],
        index: NDArray[np.int64],
        outputs: Sequence[str],
    ) -> None:
        self.form = form
        self.index = np.asarray(index)
        self.rhs, self.initial = form.compiled("rhs"), form.compiled("initial")
        self.outputs = form.compiled("outputs", outputs)
        self.d, self.size = len(form.space.state_names), self.index.shape[0]
        orders = self.index.max(axis=0)
        degree = np.zeros_like(orders)
        for part in (self.rhs, self.initial, self.outputs):
            degree = np.maximum(degree, _germ_degrees(part, self.d, orders))
        # q Gauss points integrate degree 2q - 1: the term's degree plus φ_a's.
        self.points = TensorGrid(
            tuple(distributions), tuple(int(p) for p in (degree + orders) // 2)
        )
        basis = PolynomialBasis(tuple(d.family for d in distributions), self.index)
        self._values = basis.evaluate(self.points.nodes)  # (Q, S): φ_b(μ_q)
        self._project = self._values * self.points.weights[:, None]  # (Q, S): w_q φ_a(μ_q)
        self._inputs = self.points.params.T  # (n, Q)

    def _variables(self, states: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """(V, Q) variables at the points: states (d, Q), inputs, forcing at ``t``."""
        forcing = self.form.forcing_at(t)
        width = self._inputs.shape[1]
        return np.vstack([states, self._inputs, np.repeat(forcing[:, None], width, axis=1)])

    def initial_coefficients(self) -> NDArray[np.float64]:
        """(d, S) coefficients of the initial state."""
        zero = np.zeros((self.d, self._inputs.shape[1]))
        return self.initial.evaluate(self._variables(zero, self.form.t0)) @ self._project

    def derivative(self, t: float, coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
        """(d, S) dX/dt: the Galerkin projection of the right-hand side at ``t``."""
        states = coefficients @ self._values.T
        return self.rhs.evaluate(self._variables(states, t)) @ self._project

    def solve(self, times: NDArray[np.float64]) -> NDArray[np.float64]:
        """(d, S, T) state coefficients at ``times`` (one stacked solve of d·S unknowns)."""
        from pcmb.integrate.stacked_ode import solve_stacked  # scipy.integrate: when solving

        shape = (self.d, self.size)
        atol = np.broadcast_to(np.asarray(self.form.atol, dtype=float), (self.d,))
        states = solve_stacked(
            lambda t, y: self.derivative(t, y.reshape(shape)).reshape(-1, 1),
            self.initial_coefficients().reshape(-1, 1),
            times,
            t0=self.form.t0,
            method=self.form.method,
            rtol=self.form.rtol,
            atol=np.repeat(atol, self.size),
        )
        return states.reshape(self.d, self.size, -1)

    def output_coefficients(
        self, states: NDArray[np.float64], times: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """(R, S, T) coefficients of the outputs from the (d, S, T) state coefficients."""
        out = np.empty((self.outputs.size, self.size, times.size))
        for k, t in enumerate(times):
            values = self.outputs.evaluate(self._variables(states[:, :, k] @ self._values.T, t))
            out[:, :, k] = values @ self._project
        return out


def _germ_degrees(
    part: CompiledPolynomials, d: int, orders: NDArray[np.int64]
) -> NDArray[np.int64]:
    """(n,) the largest degree in each germ of a part's terms: a state of degree P_k in ξ_k
    raised to its total power, times the input's own power (affine in its germ)."""
    if part.exponents.shape[0] == 0:
        return np.zeros_like(orders)
    n = orders.size
    state_power = part.exponents[:, :d].sum(axis=1)  # (K,)
    input_power = part.exponents[:, d : d + n]  # (K, n)
    return (state_power[:, None] * orders[None, :] + input_power).max(axis=0)


class GalerkinSettings(MethodSection):
    """``method: {kind: galerkin, order, basis}``."""

    kind: Literal["galerkin"] = Field(description="how nodes are made (a registered design)")
    order: OrderSpec | None = Field(
        default=None, description="chaos order: int or a mapping input -> int"
    )
    basis: Literal[BASES] | None = Field(
        default=None, description="chaos terms: tensor (default) or total degree"
    )

    @property
    def size_key(self) -> str:
        return "order"

    cost_key = size_key  # a sweep raises what sets the size


class Galerkin(WithoutNodes):
    """``method: {kind: galerkin, order, basis}``: stochastic Galerkin on a tensor or total
    basis of order P (per input for ``tensor``); needs the model's polynomial form."""

    Settings = GalerkinSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        if settings.orders is None or settings.orders == "auto":
            raise ValueError(
                "method.order: an integer order (or one per input) is required by kind galerkin"
            )
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.orders = tuple(int(p) for p in settings.orders)
        self.basis = settings.basis or "tensor"

    def record(self) -> Design:
        return Design(
            kind="galerkin",
            grid="none",
            basis=self.basis,
            orders=self.orders,
            fit="galerkin",
            label=f"Galerkin, {order_words(self.orders, self.basis)}",
        )

    def index(self) -> NDArray[np.int64]:
        """(S, n) the basis's multi-indices."""
        if self.basis == "tensor":
            return tensor_index_set(self.orders)
        index = total_index_set(len(self.orders), max(self.orders))
        return index[np.all(index <= np.array(self.orders), axis=1)]

    def check(self, model: object, outputs: Sequence[str] | None) -> list[tuple[str, str]]:
        return form_problems(model, self.names, outputs, "galerkin")

    def solve(self, model: object, times: NDArray[np.float64], outputs: Sequence[str]) -> Recovery:
        form = polynomial_form(model, self.names, outputs, "galerkin")
        system = GalerkinSystem(form, self.distributions, self.index(), outputs)
        times = np.asarray(times, dtype=float)
        coefficients = system.output_coefficients(system.solve(times), times)
        expansions = {
            name: ChaosExpansion(coefficients[k], system.index, self.distributions, self.names)
            for k, name in enumerate(outputs)
        }
        empty = {name: np.zeros((0, times.size)) for name in outputs}
        ok = np.zeros(0, dtype=bool)
        return Recovery(expansions, statistics_warnings(expansions, empty, ok, times))
