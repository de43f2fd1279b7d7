"""Config sections of random process inputs: ``inputs.<name>: {process: kl, ...}``.

A process input is expanded (Karhunen–Loève, :mod:`pcmb.chaos.process`) while the config is
validated, so a bad setting or a covariance without enough eigenvalues is reported at its
key before anything runs, and ``pcmb validate`` can say how many germs it got.
"""

from __future__ import annotations

import functools
import itertools
import json
import re
import typing
from typing import Annotated, Literal, Self

from pydantic import AfterValidator, Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError

from pcmb.chaos import process as kl
from pcmb.config.messages import SETTING_ERROR
from pcmb.config.types import (
    NonNegativeReal,
    PositiveInt,
    PositiveReal,
    Real,
    Section,
    Stop,
    count,
)

__all__ = ["CovarianceSpec", "GridSpec", "ProcessSpec"]


class _CovarianceSpec(Section):
    """A stationary covariance: ``kind`` names its :data:`pcmb.chaos.process.COVARIANCES`
    constructor, whose
    arguments are the other keys."""


class ExponentialSpec(_CovarianceSpec):
    """``{kind: exponential, sigma, length}``: R(τ) = σ² exp(-|τ|/ℓ)."""

    kind: Literal["exponential"]
    sigma: PositiveReal = Field(description="standard deviation σ of the process")
    length: PositiveReal = Field(description="correlation length ℓ (units of the grid)")


class SquaredExponentialSpec(_CovarianceSpec):
    """``{kind: squared-exponential, sigma, length}``: R(τ) = σ² exp(-τ²/(2ℓ²))."""

    kind: Literal["squared-exponential"]
    sigma: PositiveReal = Field(description="standard deviation σ of the process")
    length: PositiveReal = Field(description="correlation length ℓ (units of the grid)")


class MaternSpec(_CovarianceSpec):
    """``{kind: matern, sigma, length, nu}``: Matérn covariance of smoothness ν."""

    kind: Literal["matern"]
    sigma: PositiveReal = Field(description="standard deviation σ of the process")
    length: PositiveReal = Field(description="correlation length ℓ (units of the grid)")
    nu: PositiveReal = Field(description="smoothness ν (1/2: exponential; large: smooth)")


def _one_each(values: list[float], info: ValidationInfo) -> list[float]:
    """An after-validator of the list paired with ``omega``: one value per frequency."""
    omega = info.data.get("omega")
    if omega is not None and len(values) != len(omega):
        raise ValueError(f"expected {len(omega)} values (one per omega), found {len(values)}")
    return values


class LinesSpec(_CovarianceSpec):
    """``{kind: lines, omega, variance}``: R(τ) = Σ σ_i² cos(ω_i τ), a line spectrum."""

    kind: Literal["lines"]
    omega: Annotated[list[NonNegativeReal], Field(min_length=1)] = Field(
        description="angular frequencies ω_i of the lines (radians per unit of the grid)"
    )
    variance: Annotated[list[NonNegativeReal], Field(min_length=1), AfterValidator(_one_each)] = (
        Field(description="variance σ_i² of each line")
    )


def _increasing(values: list[float]) -> list[float]:
    if any(b <= a for a, b in itertools.pairwise(values)):
        raise ValueError("expected increasing frequencies")
    return values


class PsdSpec(_CovarianceSpec):
    """``{kind: psd, omega, density}``: a tabulated one-sided power spectral density."""

    kind: Literal["psd"]
    omega: Annotated[list[NonNegativeReal], Field(min_length=2), AfterValidator(_increasing)] = (
        Field(description="increasing angular frequencies ω (radians per unit of the grid)")
    )
    density: Annotated[list[NonNegativeReal], Field(min_length=2), AfterValidator(_one_each)] = (
        Field(description="one-sided PSD S(ω) at each frequency, so that the variance is ∫ S dω")
    )


CovarianceSpec = Annotated[
    typing.Union[  # noqa: UP007 (one member per covariance kind)
        ExponentialSpec, SquaredExponentialSpec, MaternSpec, LinesSpec, PsdSpec
    ],
    Field(discriminator="kind"),
]


class GridSpec(Section):
    """The points where the model receives the field: ``numpy.linspace(start, stop, points)``."""

    start: Real = Field(default=0.0, description="first point")
    stop: Stop = Field(description="last point (> start)")
    points: count(ge=2, le=kl.MAX_GRID_POINTS) = Field(
        description="number of points m: the model receives (B, m) values"
    )


@functools.lru_cache(maxsize=16)
def _expansion(settings: str) -> kl.RandomProcess:
    """The expansion of a process section's settings (JSON), computed once per settings."""
    data = json.loads(settings)
    grid = data["grid"]
    return kl.RandomProcess.karhunen_loeve(
        kl.covariance_from_description(data["covariance"]),
        grid["start"],
        grid["stop"],
        grid["points"],
        energy=data["energy"],
        terms=data["terms"],
    )


def _settings(
    covariance: _CovarianceSpec, grid: GridSpec, energy: float | None, terms: int | None
) -> str:
    return json.dumps(
        {
            "covariance": covariance.model_dump(mode="json"),
            "grid": grid.model_dump(mode="json"),
            "energy": energy,
            "terms": terms,
        }
    )


class ProcessSpec(Section):
    """``{process: kl, covariance, grid, energy | terms}``: a zero-mean Gaussian random
    process, expanded into the fewest standard normal germs that keep ``energy``.

    Its germs are inputs ``<name>[0]``, ``<name>[1]``, ... in its place in the germ order
    (``method.order`` may give the process one order for all of them); the model receives
    the field at the grid's points, (B, m), under ``<name>``. See ``docs/processes.md``.
    """

    process: Literal["kl"] = Field(description="the expansion: Karhunen–Loève")
    covariance: CovarianceSpec = Field(description="the stationary covariance")
    grid: GridSpec
    energy: Annotated[float, Field(gt=0, le=1)] | None = Field(
        default=None,
        description=f"share of the variance kept (default {kl.DEFAULT_ENERGY} when "
        "terms is not set either)",
    )
    terms: PositiveInt | None = Field(
        default=None,
        validate_default=True,
        description="keep exactly this many germs instead of energy",
    )

    @field_validator("terms")
    @classmethod
    def _one_truncation(cls, terms: int | None, info: ValidationInfo) -> int | None:
        if terms is not None and info.data.get("energy") is not None:
            raise ValueError("give energy or terms, not both")
        return terms

    @model_validator(mode="after")
    def _expandable(self) -> Self:
        """Make the expansion now; its objections name their key of this section
        (``covariance.length: ...``, see :meth:`RandomProcess.karhunen_loeve
        <pcmb.chaos.process.RandomProcess.karhunen_loeve>`), else the section itself."""
        try:
            self.expansion  # noqa: B018 - made for its errors (and cached)
        except ValueError as error:
            key, _, message = str(error).partition(": ")
            if message and re.fullmatch(r"[a-z]+(\.[a-z]+)*", key):
                raise PydanticCustomError(
                    SETTING_ERROR, "{message}", {"key": key, "message": message}
                ) from None
            raise
        return self

    @property
    def expansion(self) -> kl.RandomProcess:
        """The truncated expansion (computed once, while the config is validated)."""
        return _expansion(_settings(self.covariance, self.grid, self.energy, self.terms))
