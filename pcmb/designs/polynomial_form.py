"""The optional polynomial-form protocol: a model whose right-hand side is polynomial in its
states and uncertain inputs says so, for the intrusive methods (stochastic Galerkin,
statistical linearization).

A model offers ``polynomial_form(inputs) -> PolynomialForm``: its ODE right-hand side, initial
state and outputs as polynomials in the variables (states, uncertain inputs, forcing), where a
*forcing* variable is a function of time only (``forcing(t) -> (F,)``, e.g. sin(2π f t)),
evaluated by the model. It raises ``ValueError`` saying why when the chosen inputs do not enter
polynomially (a mass in a denominator, a frequency inside a sine). Models build the polynomials
with ordinary arithmetic on the variables of a :class:`PolynomialSpace` (``docs/models.md``).
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["CompiledPolynomials", "Polynomial", "PolynomialForm", "PolynomialSpace"]

Exponents = tuple[int, ...]


class Polynomial:
    """A polynomial with float coefficients in named variables; ``+ - * **`` (int powers) and
    division by a number build new ones. Dividing by a non-constant polynomial raises
    ``ValueError`` (the model is not polynomial in that variable).

    Parameters
    ----------
    terms:
        Exponents (one per variable) -> coefficient.
    names:
        The variables' names (shared by every polynomial of one space).
    """

    __slots__ = ("names", "terms")
    __array_ufunc__ = None  # numpy scalars defer to our operators: np.float64(2) * p works

    def __init__(self, terms: Mapping[Exponents, float], names: tuple[str, ...]):
        self.terms = {e: float(c) for e, c in terms.items() if c != 0.0}
        self.names = names

    def _lift(self, other: object) -> Polynomial:
        if isinstance(other, Polynomial):
            if other.names != self.names:
                raise ValueError("polynomials of different spaces cannot be combined")
            return other
        if isinstance(other, numbers.Real):
            return Polynomial({(0,) * len(self.names): float(other)}, self.names)
        return NotImplemented

    def __add__(self, other: object) -> Polynomial:
        other = self._lift(other)
        if other is NotImplemented:
            return NotImplemented
        terms = dict(self.terms)
        for exponents, coefficient in other.terms.items():
            terms[exponents] = terms.get(exponents, 0.0) + coefficient
        return Polynomial(terms, self.names)

    __radd__ = __add__

    def __neg__(self) -> Polynomial:
        return Polynomial({e: -c for e, c in self.terms.items()}, self.names)

    def __sub__(self, other: object) -> Polynomial:
        other = self._lift(other)
        return NotImplemented if other is NotImplemented else self + (-other)

    def __rsub__(self, other: object) -> Polynomial:
        return -self + other

    def __mul__(self, other: object) -> Polynomial:
        other = self._lift(other)
        if other is NotImplemented:
            return NotImplemented
        terms: dict[Exponents, float] = {}
        for e1, c1 in self.terms.items():
            for e2, c2 in other.terms.items():
                e = tuple(a + b for a, b in zip(e1, e2, strict=True))
                terms[e] = terms.get(e, 0.0) + c1 * c2
        return Polynomial(terms, self.names)

    __rmul__ = __mul__

    def __pow__(self, power: int) -> Polynomial:
        if not isinstance(power, numbers.Integral) or power < 0:
            raise ValueError(f"a polynomial power must be a non-negative integer, got {power!r}")
        out = self._lift(1.0)
        for _ in range(int(power)):
            out = out * self
        return out

    def constant(self) -> float | None:
        """The value of a constant polynomial, else ``None``."""
        if not self.terms:
            return 0.0
        zero = (0,) * len(self.names)
        return self.terms[zero] if set(self.terms) == {zero} else None

    def __truediv__(self, other: object) -> Polynomial:
        other = self._lift(other)
        if other is NotImplemented:
            return NotImplemented
        value = other.constant()
        if value is None:
            raise ValueError(f"division by {other}: not polynomial in {other.variables()}")
        return self * (1.0 / value)

    def __rtruediv__(self, other: object) -> Polynomial:
        lifted = self._lift(other)
        return NotImplemented if lifted is NotImplemented else lifted / self

    def variables(self) -> list[str]:
        """Names of the variables that occur."""
        used = np.any(np.array(list(self.terms) or [(0,) * len(self.names)]) > 0, axis=0)
        return [name for name, u in zip(self.names, used, strict=True) if u]

    def __repr__(self) -> str:
        parts = []
        for exponents, coefficient in self.terms.items():
            factors = [
                name if e == 1 else f"{name}^{e}"
                for name, e in zip(self.names, exponents, strict=True)
                if e
            ]
            parts.append("*".join([f"{coefficient:g}", *factors]))
        return " + ".join(parts) or "0"


class PolynomialSpace:
    """The variables a model writes its polynomial form in: states, inputs, forcing.

    Parameters
    ----------
    states:
        The d state names (the ODE's unknowns).
    inputs:
        The n uncertain inputs, germ order.
    forcing:
        Names of the F functions of time only.
    """

    def __init__(
        self, states: Sequence[str], inputs: Sequence[str], forcing: Sequence[str] = ()
    ) -> None:
        self.state_names, self.input_names = tuple(states), tuple(inputs)
        self.forcing_names = tuple(forcing)
        names = (*self.state_names, *self.input_names, *self.forcing_names)
        if len(set(names)) != len(names):
            raise ValueError(f"state, input and forcing names must differ, got {names}")
        self.names = names
        variables = [
            Polynomial({tuple(int(j == k) for j in range(len(names))): 1.0}, names)
            for k in range(len(names))
        ]
        d, n = len(self.state_names), len(self.input_names)
        self.states = tuple(variables[:d])
        self.inputs = dict(zip(self.input_names, variables[d : d + n], strict=True))
        self.forcing = tuple(variables[d + n :])

    def parameters(
        self, nominal: Mapping[str, float], fixed: Sequence[str] = ()
    ) -> dict[str, float | Polynomial]:
        """Every parameter: its nominal value, or its variable when it is an uncertain input.

        Parameters
        ----------
        nominal:
            Parameter name -> nominal value.
        fixed:
            Parameters the model is not polynomial in (a frequency inside a sine, a mass it
            divides by): they must not be uncertain.

        Raises
        ------
        ValueError
            An input that is not a parameter, or one of ``fixed``.
        """
        unknown = [name for name in self.input_names if name not in nominal]
        if unknown:
            raise ValueError(f"input(s) {unknown} name no parameter (parameters: {list(nominal)})")
        bad = [name for name in self.input_names if name in fixed]
        if bad:
            raise ValueError(f"the right-hand side is not polynomial in {bad}: keep them certain")
        return {name: self.inputs.get(name, float(value)) for name, value in nominal.items()}

    def polynomial(self, value: Polynomial | float) -> Polynomial:
        """``value`` as a polynomial of this space (a number becomes a constant)."""
        if isinstance(value, Polynomial):
            return value
        return Polynomial({(0,) * len(self.names): float(value)}, self.names)


class CompiledPolynomials:
    """R polynomials as arrays: term k adds ``coefficients[k] * prod(variables**exponents[k])``
    to row ``rows[k]``; the variables are (states, inputs, forcing), V of them.

    Attributes
    ----------
    rows:
        (K,) the row of every term.
    exponents:
        (K, V) its exponents.
    coefficients:
        (K,) its coefficient.
    size:
        R.
    """

    def __init__(
        self,
        rows: NDArray[np.intp],
        exponents: NDArray[np.int64],
        coefficients: NDArray[np.float64],
        size: int,
    ) -> None:
        self.rows, self.exponents, self.coefficients, self.size = (
            rows,
            exponents,
            coefficients,
            size,
        )
        # Per term, its (variable, power) factors; the powers every term needs are made once.
        self._factors = [tuple((int(v), int(e[v])) for v in np.flatnonzero(e)) for e in exponents]
        self._powers = sorted({factor for factors in self._factors for factor in factors})

    @classmethod
    def of(cls, polynomials: Sequence[Polynomial], n_variables: int) -> CompiledPolynomials:
        rows, exponents, coefficients = [], [], []
        for row, polynomial in enumerate(polynomials):
            for e, c in polynomial.terms.items():
                rows.append(row)
                exponents.append(e)
                coefficients.append(c)
        return cls(
            np.array(rows, dtype=np.intp),
            np.array(exponents, dtype=np.int64).reshape(-1, n_variables),
            np.array(coefficients, dtype=float),
            len(polynomials),
        )

    def evaluate(self, variables: NDArray[np.float64]) -> NDArray[np.float64]:
        """(R, ...) values at points, from the (V, ...) variables there."""
        powers = {}
        for v, e in self._powers:  # by products: a complex ** goes through exp and log
            powers[v, e] = (
                variables[v]
                if e == 1
                else powers.get((v, e - 1), variables[v] ** (e - 1)) * variables[v]
            )
        out = np.zeros((self.size, *variables.shape[1:]), dtype=variables.dtype)
        for row, factors, coefficient in zip(
            self.rows, self._factors, self.coefficients, strict=True
        ):
            if not factors:
                out[row] += coefficient
                continue
            term = coefficient * powers[factors[0]]
            for factor in factors[1:]:
                term = term * powers[factor]
            out[row] += term
        return out


@dataclass(frozen=True)
class PolynomialForm:
    """A model's dynamics as polynomials in (states, inputs, forcing).

    Attributes
    ----------
    space:
        The variables (:class:`PolynomialSpace`).
    rhs:
        d polynomials: dx/dt.
    initial:
        d polynomials in the inputs (and forcing, taken at ``t0``): the state at ``t0``.
    outputs:
        Output name -> polynomial.
    forcing:
        ``forcing(t) -> (F,)`` the time functions at time t (model code).
    t0:
        Initial time.
    rtol, atol, method:
        Integration settings of the intrusive systems (:func:`pcmb.integrate.stacked_ode.
        solve_stacked`): ``atol`` scalar or one value per state.
    """

    space: PolynomialSpace
    rhs: tuple[Polynomial | float, ...]
    initial: tuple[Polynomial | float, ...]
    outputs: Mapping[str, Polynomial | float]
    forcing: Callable[[float], ArrayLike] = field(default=lambda t: np.zeros(0))
    t0: float = 0.0
    rtol: float = 1e-9
    atol: float | ArrayLike = 1e-12
    method: str = "DOP853"

    def __post_init__(self) -> None:
        d = len(self.space.state_names)
        if len(self.rhs) != d or len(self.initial) != d:
            raise ValueError(
                f"need one right-hand side and one initial value per state ({d}), got "
                f"{len(self.rhs)} and {len(self.initial)}"
            )
        for value in self.initial:
            used = set(self.space.polynomial(value).variables())
            if used & set(self.space.state_names):
                raise ValueError(f"an initial value depends on the states: {value}")

    @property
    def n_variables(self) -> int:
        return len(self.space.names)

    def compiled(self, part: str, outputs: Sequence[str] = ()) -> CompiledPolynomials:
        """``"rhs"``, ``"initial"`` or ``"outputs"`` (those named) as arrays."""
        if part == "outputs":
            polynomials = [self.outputs[name] for name in outputs]
        else:
            polynomials = list(getattr(self, part))
        return CompiledPolynomials.of(
            [self.space.polynomial(p) for p in polynomials], self.n_variables
        )

    def forcing_at(self, t: float) -> NDArray[np.float64]:
        """(F,) the forcing functions at time ``t``."""
        values = np.asarray(self.forcing(t), dtype=float).reshape(-1)
        if values.size != len(self.space.forcing_names):
            raise ValueError(
                f"forcing({t:g}) returned {values.size} values for "
                f"{len(self.space.forcing_names)} forcing names"
            )
        return values
