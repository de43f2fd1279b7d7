"""Sparse regression design: sampled nodes, a chaos basis selected by LARS or OMP."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from pcmb.chaos.basis import PolynomialBasis, hyperbolic_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, random_nodes
from pcmb.chaos.sparse_regression import (
    SELECTIONS,
    SparseFit,
    fit_sparse,
    minimum_samples,
    next_batch,
)
from pcmb.config.types import OrderSpec, PositiveInt, PositiveReal
from pcmb.designs.base import (
    MethodSection,
    MethodSettings,
    Recovery,
    missing_keys,
    refuse,
    statistics_warnings,
)
from pcmb.result import (
    ATTRIBUTE,
    POINTS,
    Design,
    Placement,
    RecordReport,
    RegressionFit,
    StudyResult,
    WarningRecord,
)

__all__ = [
    "RegressionReport",
    "RegressionSettings",
    "SparseRegression",
    "estimated_error",
    "loo_statistics_error",
]

#: ``method.sampling`` -> the :func:`pcmb.chaos.nodes.random_nodes` method.
SAMPLINGS = {"sobol": "sobol", "lhs": "lhs", "random": "montecarlo"}
BASES = ("total", "hyperbolic")
#: ``method.selection`` -> the ``fit`` recorded in :class:`pcmb.result.Design`.
FITS = {"lars": "lars", "omp": "omp", "none": "ols"}


class RegressionSettings(MethodSection):
    """``method: {kind: regression, samples, sampling, selection, basis, q, order, seed,
    tolerance, max_samples}``."""

    budget_key: ClassVar[str] = "max_samples"

    kind: Literal["regression"] = Field(description="how nodes are made (a registered design)")
    order: OrderSpec | None = Field(
        default=None, description="highest order of the candidate terms (int or input -> int)"
    )
    basis: Literal[BASES] | None = Field(
        default=None, description="candidate terms: hyperbolic (default) or total degree"
    )
    samples: PositiveInt | None = Field(default=None, description="runs of the first round")
    selection: Literal[tuple(SELECTIONS)] = Field(
        default="lars", description="term selection of kind regression"
    )
    sampling: Literal[tuple(SAMPLINGS)] = Field(
        default="sobol", description="how kind regression samples its nodes"
    )
    q: Annotated[float, Field(gt=0, le=1)] = Field(
        default=1.0, description="hyperbolic-set exponent of kind regression (1: total degree)"
    )
    tolerance: PositiveReal | None = Field(
        default=None,
        description="add samples until the error of the mean and std estimated from the "
        "corrected LOO error, relative to the largest std, meets it",
    )
    max_samples: PositiveInt | None = Field(
        default=None, description="with tolerance: most samples in all"
    )

    @property
    def size_key(self) -> str:
        return self.budget_key if self.tolerance is not None else "samples"

    @property
    def cost_key(self) -> str:
        return "samples"


#: Corrected LOO error above which a ``regression-loo`` record is made.
LOO_WARNING = 1e-2
#: Default largest total samples, as a multiple of ``method.samples``, with a tolerance.
MAX_GROWTH = 16


def output_errors(fits: Mapping[str, SparseFit], runs: Mapping[str, float]) -> dict[str, float]:
    """Each output's :func:`loo_statistics_error`, fitted to the ``runs`` it counts as."""
    return {
        name: loo_statistics_error(
            fit.loo_error, np.sqrt(np.sum(fit.coefficients[1:] ** 2, axis=0)), runs[name]
        )
        for name, fit in fits.items()
    }


def estimated_error(fits: Mapping[str, SparseFit], runs: Mapping[str, float]) -> float:
    """The largest :func:`output_errors` (0 without an output)."""
    return max(output_errors(fits, runs).values(), default=0.0)


def loo_statistics_error(loo: ArrayLike, std: ArrayLike, runs: float) -> float:
    """The estimated error of the mean and std of a least-squares fit, relative to the largest
    std, the largest over times, from its corrected LOO error ε and std σ per time.

    ε estimates the surrogate's mean squared error over the variance, so e = √ε σ is its RMS
    error. The coefficients then err by about e/√N each (N runs): the mean by e/√N, the std by
    e/√N (their projection on the coefficients' direction) plus e²/(2σ) (the variance the
    unselected terms carry).
    """
    std = np.asarray(std, dtype=float)
    scale = float(np.max(std, initial=0.0))
    if scale <= 0:
        return 0.0
    relative = np.sqrt(np.nan_to_num(np.asarray(loo, dtype=float)))
    return float(np.max(std * relative * (1.0 / np.sqrt(runs) + relative / 2.0))) / scale


class SparseRegression:
    """``method: {kind: regression, samples, sampling, selection, basis, q, order, seed,
    tolerance, max_samples}``.

    The candidate terms are the hyperbolic set (Σ α_k^q)^(1/q) <= order (``basis: total``:
    q = 1), capped per input by its order; every output gets the terms its LARS or OMP path
    selects (:func:`pcmb.chaos.sparse_regression.fit_sparse`), shared by all its times; the
    expansions hold the union of the selected terms (zero where an output did not select one).

    With a ``tolerance`` the design is adaptive (:class:`~pcmb.designs.base.AdaptiveDesign`):
    after each round :meth:`more` adds samples until the error of the mean and std estimated
    from the corrected LOO error (:func:`estimated_error`) meets it or the runs reach
    ``max_samples`` (default :data:`MAX_GROWTH` × ``samples``).
    """

    Settings = RegressionSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        selection, sampling, q = settings.selection, settings.sampling, settings.q
        tolerance, max_samples = settings.tolerance, settings.max_samples
        problems = missing_keys("kind regression", samples=settings.samples, order=settings.orders)
        if max_samples is not None and tolerance is None:
            problems.append(
                (
                    "method.max_samples",
                    "only used with method.tolerance (the budget of the rounds that add samples "
                    "until the estimated error meets it)",
                )
            )
        refuse(problems)
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.orders = tuple(settings.orders)
        self.samples, self.seed = settings.samples, settings.seed
        self.basis = settings.basis or "hyperbolic"
        self.q = q if self.basis == "hyperbolic" else 1.0
        self.selection, self.sampling, self.tolerance = selection, sampling, tolerance
        caps = np.asarray(self.orders)
        index = hyperbolic_index_set(len(caps), max(self.orders), self.q)
        self.candidates = PolynomialBasis(
            tuple(d.family for d in self.distributions), index[np.all(index <= caps, axis=1)]
        )
        least = minimum_samples(self.candidates.size, selection)
        if self.samples < least:
            raise ValueError(
                f"method.samples: selection {selection} over the {self.candidates.size} candidate "
                f"terms needs at least {least} samples, got {self.samples}"
            )
        self.max_samples = max_samples or MAX_GROWTH * self.samples
        if tolerance is not None and self.max_samples <= self.samples:
            raise ValueError(
                f"method.max_samples: a budget of {self.max_samples} runs leaves none for a "
                f"round after the first {self.samples} (method.samples): give more"
            )
        # (runs, worst corrected LOO) of the rounds so far, and the runs of the last recovery.
        self._history: list[tuple[int, float]] = []
        self._made = self.samples

    @property
    def runs(self) -> int:
        """Runs of the first round."""
        return self.samples

    @property
    def budget(self) -> int:
        """Most runs of all rounds together."""
        return self.samples if self.tolerance is None else self.max_samples

    def nodes(self) -> NodeSet:
        return random_nodes(self.distributions, self.samples, SAMPLINGS[self.sampling], self.seed)

    def weights(self, nodes: NodeSet) -> None:
        return None

    def record(self) -> Design:
        return Design(
            kind="regression",
            grid=self.sampling,
            basis=self.basis,
            orders=self.orders,
            samples=self._made,
            seed=self.seed,
            fit=FITS[self.selection],
            q=self.q,
            tolerance=self.tolerance,
            max_samples=None if self.tolerance is None else self.max_samples,
            label=self._label(),
        )

    def _label(self) -> str:
        """``LARS on hyperbolic order 5, q=0.75, 256 samples (to 0.05, at most 2048)``."""
        shape = f", q={self.q:g}" if self.basis == "hyperbolic" else ""
        label = (
            f"{FITS[self.selection].upper()} on {self.basis} order {max(self.orders)}{shape}, "
            f"{self._made} samples"
        )
        if self.tolerance is not None:
            label += f" (to {self.tolerance:g}, at most {self.max_samples})"
        return label

    def next_nodes(self, done: int, history: Sequence[tuple[int, float]]) -> NodeSet | None:
        """The next batch of nodes while the tolerance is not met, else ``None``.

        Parameters
        ----------
        done:
            Nodes made so far (the batch continues them: the Sobol' sequence is extended; LHS
            and random batches are drawn afresh with a seed derived from ``seed`` and ``done``).
        history:
            (samples, estimated error of the mean and std) of every fit so far.
        """
        if self.tolerance is None:
            return None
        size = next_batch(history, self.tolerance, self.max_samples)
        if size == 0:
            return None
        method = SAMPLINGS[self.sampling]
        if method == "sobol":
            every = random_nodes(self.distributions, done + size, method, self.seed)
            return NodeSet(self.distributions, every.nodes[done:], every.params[done:])
        seed = int(np.random.SeedSequence((self.seed, done)).generate_state(1)[0])
        return random_nodes(self.distributions, size, method, seed)

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The next round's nodes while the estimated error of a fit on every node so far
        exceeds the tolerance and the budget allows (:meth:`next_nodes`), else ``None``."""
        if self.tolerance is None:
            return None
        if nodes.size == self.samples:  # the first round of a (new) run
            self._history = []
        found = self._fits(nodes, values, ok)
        estimate = estimated_error(
            {name: fit.fit for name, fit in found.items()},
            {name: fit.effective for name, fit in found.items()},
        )
        self._history.append((nodes.size, estimate))
        return self.next_nodes(nodes.size, self._history)

    def _fits(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        weights: NDArray[np.float64] | None = None,
    ) -> dict[str, _Fit]:
        """Each output's fit over its rows (``ok``, and with ``weights`` a weight above 0),
        weighted by them."""
        rows = ok if weights is None else ok & (weights > 0)
        kept = None if weights is None else weights[rows]
        runs = int(rows.sum())
        effective = runs if kept is None else _effective(kept)
        held_out = int(rows[self._made :].sum())
        germ = nodes.nodes[rows]
        return {
            name: _Fit(
                fit_sparse(self.candidates, germ, y[rows], self.selection, kept),
                runs,
                effective,
                held_out,
            )
            for name, y in values.items()
        }

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        self._made = nodes.size
        return self._recovery(nodes, values, ok, None, times)

    def refit(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        weights: NDArray[np.float64],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """The final fit (:class:`~pcmb.designs.base.RefittingDesign`): each output fitted
        again, with the same candidates and selection (LARS and OMP select again), over
        ``nodes``, the design's runs followed by the held-out runs, by least squares weighted
        by its ``weights`` (N,): 1 for the design's runs, the held-out draws' importance
        weights, 0 for a row left out. The records describe these fits; the design's record
        is unchanged."""
        return self._recovery(nodes, values, ok, weights, times)

    def _recovery(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        weights: NDArray[np.float64] | None,
        times: NDArray[np.float64] | None,
    ) -> Recovery:
        """The expansions of :meth:`recover` (``weights`` ``None``) or :meth:`refit`."""
        weighted = self._fits(nodes, values, ok, weights)
        fits = {name: found.fit for name, found in weighted.items()}
        expansions = {}
        if fits:
            union, where = np.unique(
                np.concatenate([f.multi_index for f in fits.values()]),
                axis=0,
                return_inverse=True,
            )
            start = 0
            for name, fit in fits.items():
                coefficients = np.zeros((union.shape[0], *fit.coefficients.shape[1:]))
                coefficients[where[start : start + fit.multi_index.shape[0]]] = fit.coefficients
                start += fit.multi_index.shape[0]
                expansions[name] = ChaosExpansion(
                    coefficients, union, self.distributions, self.names
                )
        records = tuple(
            record
            for name, (fit, runs, _, _) in weighted.items()
            if (record := self._loo_warning(name, fit, runs, times)) is not None
        )
        errors = output_errors(fits, {name: found.effective for name, found in weighted.items()})
        records += tuple(
            self._budget_warning(name, error, fits[name])
            for name, error in errors.items()
            if self.tolerance is not None and error > self.tolerance
        )
        regression = {
            name: RegressionFit(
                fit.multi_index, np.atleast_1d(fit.loo_error), fit.condition, held_out, effective
            )
            for name, (fit, _, effective, held_out) in weighted.items()
        }
        warnings = records + statistics_warnings(expansions, values, ok, times)
        return Recovery(expansions, warnings, RegressionReport(regression))

    def _budget_warning(self, name: str, estimate: float, fit: SparseFit) -> WarningRecord:
        """The ``regression-budget`` record of an output whose estimated error of the mean and
        std, ``estimate``, missed ``method.tolerance`` when ``max_samples`` ended the rounds."""
        return WarningRecord(
            "regression-budget",
            f"the rounds ended after {self._made} of {self.max_samples} runs "
            f"(method.max_samples) before the tolerance was met: estimated error of the mean "
            f"and std {estimate:.3g} > {self.tolerance:g} (from the corrected leave-one-out "
            f"error up to {float(np.nanmax(fit.loo_error, initial=0.0)):.3g}); raise "
            "method.max_samples, or lower the order",
            name,
        )

    def _loo_warning(
        self, name: str, fit: SparseFit, runs: int, times: NDArray[np.float64] | None
    ) -> WarningRecord | None:
        """A ``regression-loo`` record where the corrected LOO error exceeds
        :data:`LOO_WARNING`, else ``None``."""
        limit = LOO_WARNING
        loo = np.atleast_1d(fit.loo_error)
        large = np.flatnonzero(loo > limit)
        if large.size == 0:
            return None
        span = None if times is None else (float(times[large[0]]), float(times[large[-1]]))
        return WarningRecord(
            "regression-loo",
            f"corrected leave-one-out error up to {float(np.nanmax(loo)):.3g} (> {limit:.3g}) at "
            f"{large.size} of {loo.size} times, with {fit.multi_index.shape[0]} of "
            f"{self.candidates.size} candidate terms selected ({self.selection}) from {runs} "
            "runs: an indicator of the surrogate's pointwise error, not a verdict (the "
            "held-out check judges the mean and std); more samples or another order lower it",
            name,
            span,
        )


class _Fit(NamedTuple):
    """An output's fit, the rows it was fitted to, the runs they count as (weighted:
    :func:`_effective`) and how many of them are held-out runs."""

    fit: SparseFit
    runs: int
    effective: float
    held_out: int


def _final(fit: RegressionFit) -> str:
    """`` (final fit, with 10 held-out runs)`` where the fit used held-out runs, else empty."""
    return f" (final fit, with {fit.held_out_fitted} held-out runs)" if fit.held_out_fitted else ""


def _effective(weights: NDArray[np.float64]) -> float:
    """The runs that rows of ``weights`` count as: (Σ w)² / Σ w²."""
    return float(np.sum(weights) ** 2 / np.sum(weights**2))


@dataclass(frozen=True)
class RegressionReport(RecordReport):
    """Each output's sparse regression fit (:class:`~pcmb.result.RegressionFit`), stored
    beside its values: ``/outputs/<name>/loo`` (T,), ``selected`` (S_k, n), attributes
    ``condition``, ``held_out_fitted`` and ``effective_runs``."""

    key: ClassVar[str] = "regression"
    GROUP: ClassVar[str] = "outputs/{output}"
    RECORD: ClassVar[type] = RegressionFit
    LAYOUT: ClassVar[dict[str, Placement]] = {
        "loo": POINTS,
        "selected": (None, "input"),
        "condition": ATTRIBUTE,
        "held_out_fitted": ATTRIBUTE,
        "effective_runs": ATTRIBUTE,
    }

    regression: dict[str, RegressionFit]

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        return [
            (
                "fit",
                f"{name}: {fit.selected.shape[0]} terms selected{_final(fit)}, leave-one-out "
                f"error up to {np.nanmax(fit.loo, initial=0.0):.3g}, condition number "
                f"{fit.condition:.3g}",
            )
            for name, fit in self.regression.items()
        ]

    #: The corrected LOO estimate fell to 0.26 of the true error (docs/methods.md).
    UNDERSTATES: ClassVar[float] = 1.0 / 0.26

    def statistics_error(self, result: StudyResult, output: str) -> float | None:
        """:func:`loo_statistics_error` of ``output``'s fit: its stored ``loo``, the std of
        its expansion in ``result``, and the runs the fit counts as (``effective_runs``)."""
        fit, expansion = self.regression.get(output), result.expansions.get(output)
        if fit is None or expansion is None or np.isnan(fit.effective_runs):
            return None
        return loo_statistics_error(fit.loo, expansion.std(), fit.effective_runs)

    def merged(self, other: RegressionReport) -> RegressionReport:
        return RegressionReport({**self.regression, **other.regression})
