"""Statistical (equivalent) linearization (``method: {kind: linearization}``): mean and std over
time from the moment equations of a polynomial model closed by a Gaussian assumption (Part II
Eq. 17–24). See ``docs/methods.md``.

The states x and inputs θ are taken jointly Gaussian, z = (x, θ) ~ N(m, Σ). Then

    dm_x/dt = E[f(z, t)],    dΣ_xz/dt = E[f(z, t) (z - m)ᵀ] (+ its transpose in the xx block),

and by Stein's lemma E[f (z - m)ᵀ] = E[∂f/∂z] Σ: the equivalent linear system's gain is the
expected Jacobian (k_eq = 3h E[x²] for h x³ at zero mean), re-evaluated as the moments move.
For a polynomial f both expectations are Gaussian moments, computed exactly by a tensor
Gauss–Hermite rule in the d + n dimensions of z. A model linear in (x, θ) with Gaussian inputs
is Gaussian, and then the method is exact.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.inputs import Distribution, Normal
from pcmb.chaos.nodes import TensorGrid
from pcmb.designs.base import MethodSection, MethodSettings, Recovery
from pcmb.designs.intrusive import WithoutNodes, form_problems, polynomial_form
from pcmb.designs.polynomial_form import CompiledPolynomials, PolynomialForm
from pcmb.result import Design, WarningRecord

__all__ = ["GaussianMoments", "Linearization", "LinearizationSettings"]

#: Points of the 1-D rule that gives an input's mean and variance (exact for affine maps).
_MOMENT_POINTS = 16


def input_moments(distribution: Distribution) -> tuple[float, float]:
    """Mean and variance of an input, by Gauss quadrature over its germ."""
    rule = distribution.family.gauss_rule(_MOMENT_POINTS)
    theta = distribution.to_physical(rule.nodes)
    mean = float(rule.weights @ theta)
    return mean, float(rule.weights @ (theta - mean) ** 2)


def _total_degree(part: CompiledPolynomials, variables: int) -> int:
    """Largest total degree of a part's terms in its first ``variables`` variables."""
    if part.exponents.shape[0] == 0:
        return 0
    return int(part.exponents[:, :variables].sum(axis=1).max())


class GaussianMoments:
    """The Gaussian-closure moment equations of a polynomial form.

    Parameters
    ----------
    form:
        The model's polynomial form.
    distributions:
        The n inputs, germ order; the closure uses their mean and variance.
    outputs:
        The outputs whose mean and std are computed.
    """

    def __init__(
        self, form: PolynomialForm, distributions: Sequence[Distribution], outputs: Sequence[str]
    ) -> None:
        self.form = form
        self.rhs, self.initial = form.compiled("rhs"), form.compiled("initial")
        self.outputs = form.compiled("outputs", outputs)
        self.d, self.n = len(form.space.state_names), len(distributions)
        moments = np.array([input_moments(dist) for dist in distributions]).reshape(-1, 2)
        self.input_mean, self.input_covariance = moments[:, 0], np.diag(moments[:, 1])
        dims = self.d + self.n
        # q Gauss–Hermite points integrate degree 2q - 1: f (z - m) for the dynamics, the
        # squared output for its variance.
        self._rule = self._grid(dims, (_total_degree(self.rhs, dims) + 1) // 2 + 1)
        self._output_rule = self._grid(dims, _total_degree(self.outputs, dims) + 1)

    @staticmethod
    def _grid(dims: int, q: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(dims, Q) standard normal points and (Q,) weights of the tensor Gauss rule."""
        grid = TensorGrid((Normal(0.0, 1.0),) * dims, (q - 1,) * dims)
        return grid.nodes.T, grid.weights

    def _points(
        self,
        mean_x: NDArray[np.float64],
        covariance: NDArray[np.float64],
        rule: tuple[NDArray[np.float64], NDArray[np.float64]],
        t: float,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Variables (V, Q) at the rule's points of N(m, Σ), the (D, Q) deviations z - m and the
        weights.

        The rule is exact for the polynomials it integrates, so what it returns is a polynomial
        in m and R Rᵀ for any factor R with R Rᵀ = Σ: the moments are smooth in Σ, also where
        an integration stage makes Σ slightly indefinite (near t0, where the states are
        certain). R = S U √Λ from the eigenvalues Λ of S⁻¹ Σ S⁻¹ (S: √|diag Σ|, so that
        variances of very different sizes keep their relative accuracy), with complex roots
        of negative eigenvalues; the imaginary parts cancel, and callers keep the real part."""
        eta, weights = rule
        scale = np.sqrt(np.abs(np.diag(covariance)))
        scale[scale == 0.0] = 1.0  # a certain state (at t0): its row of Σ is 0
        values, vectors = np.linalg.eigh(covariance / np.outer(scale, scale))
        root = scale[:, None] * vectors * np.sqrt(values.astype(complex))
        deviations = root.real @ eta + 1j * (root.imag @ eta)  # numpy's mixed matmul is slow
        mean = np.concatenate([mean_x, self.input_mean])
        variables = np.empty(
            (mean.size + len(self.form.space.forcing_names), eta.shape[1]), dtype=complex
        )
        variables[: mean.size] = mean[:, None] + deviations
        variables[mean.size :] = self.form.forcing_at(t)[:, None]
        return variables, deviations, weights

    def _covariance(self, xx: NDArray[np.float64], xt: NDArray[np.float64]) -> NDArray[np.float64]:
        d = self.d
        out = np.empty((d + self.n, d + self.n))
        out[:d, :d], out[:d, d:], out[d:, :d], out[d:, d:] = xx, xt, xt.T, self.input_covariance
        return out

    def _unpack(
        self, y: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        d, n = self.d, self.n
        return y[:d], y[d : d + d * d].reshape(d, d), y[d + d * d :].reshape(d, n)

    def initial_state(self) -> NDArray[np.float64]:
        """(d + d² + d·n,) mean, covariance and state-input covariance at ``t0``."""
        zero = np.zeros((self.d, self.d))
        covariance = self._covariance(zero, np.zeros((self.d, self.n)))
        variables, deviations, weights = self._points(
            np.zeros(self.d), covariance, self._rule, self.form.t0
        )
        x0 = self.initial.evaluate(variables)  # (d, Q)
        mean = x0 @ weights
        centred = (x0 - mean[:, None]) * weights
        xx = centred @ (x0 - mean[:, None]).T
        xt = centred @ deviations[self.d :].T
        return np.concatenate([mean, xx.ravel(), xt.ravel()]).real

    def derivative(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """d/dt of the packed moments ``y``."""
        mean_x, xx, xt = self._unpack(y)
        covariance = self._covariance(xx, xt)
        variables, deviations, weights = self._points(mean_x, covariance, self._rule, t)
        f = self.rhs.evaluate(variables)  # (d, Q)
        gain = ((f * weights) @ deviations.T).real  # (d, D) = E[f (z - m)ᵀ] = E[∂f/∂z] Σ
        d = self.d
        return np.concatenate(
            [(f @ weights).real, (gain[:, :d] + gain[:, :d].T).ravel(), gain[:, d:].ravel()]
        )

    def solve(self, times: NDArray[np.float64]) -> NDArray[np.float64]:
        """(R, 2, T) mean and std of every output at ``times``."""
        from pcmb.integrate.stacked_ode import solve_stacked  # scipy.integrate: when solving

        y0 = self.initial_state()
        atol = np.broadcast_to(np.asarray(self.form.atol, dtype=float), (self.d,))
        # Covariances in squared units: absolute tolerance atol_i atol_j / rtol, so that stds
        # above atol / rtol are held to rtol and smaller ones to an error far below atol.
        rtol = self.form.rtol
        spread = np.sqrt(np.diag(self.input_covariance))
        tolerance = np.concatenate(
            [atol, np.outer(atol, atol).ravel() / rtol, np.outer(atol, spread).ravel()]
        )
        states = solve_stacked(
            lambda t, y: self.derivative(t, y[:, 0])[:, None],
            y0[:, None],
            times,
            t0=self.form.t0,
            method=self.form.method,
            rtol=self.form.rtol,
            atol=tolerance,
        )[:, 0, :]
        out = np.empty((self.outputs.size, 2, times.size))
        for k, t in enumerate(times):
            mean_x, xx, xt = self._unpack(states[:, k])
            variables, _, weights = self._points(
                mean_x, self._covariance(xx, xt), self._output_rule, t
            )
            values = self.outputs.evaluate(variables)
            mean = values @ weights
            out[:, 0, k] = mean.real
            variance = (((values - mean[:, None]) ** 2) @ weights).real
            out[:, 1, k] = np.sqrt(np.clip(variance, 0.0, None))
        return out


class LinearizationSettings(MethodSection):
    """``method: {kind: linearization}``: no keys of its own."""

    kind: Literal["linearization"] = Field(description="how nodes are made (a registered design)")


class Linearization(WithoutNodes):
    """``method: {kind: linearization}``: statistical linearization with Gaussian closure;
    needs the model's polynomial form. Non-Gaussian inputs enter by their mean and variance
    only (a warning record says so)."""

    Settings = LinearizationSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())

    def record(self) -> Design:
        return Design(kind="linearization", grid="none", label="linearization")

    def check(self, model: object, outputs: Sequence[str] | None) -> list[tuple[str, str]]:
        return form_problems(model, self.names, outputs, "linearization")

    def solve(self, model: object, times: NDArray[np.float64], outputs: Sequence[str]) -> Recovery:
        form = polynomial_form(model, self.names, outputs, "linearization")
        statistics = GaussianMoments(form, self.distributions, outputs).solve(
            np.asarray(times, dtype=float)
        )
        moments = {name: statistics[k] for k, name in enumerate(outputs)}
        others = [
            name
            for name, dist in zip(self.names, self.distributions, strict=True)
            if not isinstance(dist, Normal)
        ]
        warnings = ()
        if others:
            warnings = (
                WarningRecord(
                    "gaussian-closure",
                    f"input(s) {others} are not normal: statistical linearization treats them as "
                    "Gaussian with the same mean and variance",
                ),
            )
        return Recovery(warnings=warnings, moments=moments)
