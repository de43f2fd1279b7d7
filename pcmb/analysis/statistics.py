"""What people look at: quantile bands, PDFs at chosen times, and spectra with error bars.

:func:`analyse` computes them from the runs and expansions alone, so a result read back from
its file gives the same numbers (what each is: ``docs/architecture.md``).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.basis import PolynomialBasis
from pcmb.chaos.density import DENSITY_POINTS, kernel_density
from pcmb.chaos.elements import PiecewiseExpansion, piecewise_spectrum
from pcmb.chaos.expansion import ChaosExpansion, sample_mean, sample_std
from pcmb.chaos.nodes import TensorGrid, draw_germs
from pcmb.chaos.spectral import ChaosSpectrum, chaos_spectrum, periodogram, taper, uniform_step
from pcmb.errors import ConfigError, ConfigProblem, UsageError

if TYPE_CHECKING:
    from pcmb.result import StudyResult

__all__ = [
    "Analysis",
    "AnalysisSettings",
    "Density",
    "OutputAnalysis",
    "Spectrum",
    "analyse",
    "draws_are_runs",
    "is_uniform_grid",
    "nearest_indices",
    "output_draws",
    "psd_draws",
    "psd_draws_are_runs",
    "spectrum",
    "tensor_grid_of",
]

_R = TypeVar("_R")

#: Fewest surrogate draws allowed for PDFs and quantiles.
MIN_SAMPLES = 100
#: Surrogate values held in memory at once while computing quantile bands (32 MB).
_BLOCK_VALUES = 4_000_000
#: Surrogate draws for quantile bands: the standard error of a 5 % quantile is then
#: sqrt(0.05 · 0.95 / 20 000) = 0.0015 in probability, far below what a band plot shows.
QUANTILE_DRAWS = 20_000


def is_uniform_grid(times: NDArray[np.float64]) -> bool:
    """Whether ``times`` is a uniform grid of at least two points (what a PSD needs)."""
    try:
        uniform_step(times)
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class AnalysisSettings:
    """What to compute beyond mean, std and Sobol' indices (the config's ``analysis:``).

    Attributes
    ----------
    psd:
        Outputs whose spectrum is computed; ``None``: every output (when the time grid is
        uniform), ``()``: none.
    window:
        Window used for every spectrum, one of :data:`pcmb.chaos.spectral.WINDOWS`.
    pdf_times:
        Times at which PDFs are tabulated; ``None``: the final time.
    pdf_freqs:
        Frequencies (Hz) at which the PSD's PDF is tabulated; ``None``: each spectrum's
        highest peak above f = 0.
    quantiles:
        Probability levels of the quantile bands, each in (0, 1).
    samples:
        Surrogate draws for PDFs and quantiles.
    seed:
        Seed of those draws.
    units:
        Output name -> unit text, for figure labels.
    time_unit:
        Unit of time, for figure labels.

    Raises
    ------
    ConfigError
        If a value is impossible (key path ``analysis.<key>`` in the message).
    """

    psd: tuple[str, ...] | None = None
    window: str = "hann"
    pdf_times: tuple[float, ...] | None = None
    pdf_freqs: tuple[float, ...] | None = None
    quantiles: tuple[float, ...] = (0.05, 0.95)
    samples: int = 100_000
    seed: int = 0
    units: Mapping[str, str] = field(default_factory=dict)
    time_unit: str = ""

    def __post_init__(self) -> None:
        for key in ("psd", "pdf_times", "pdf_freqs"):
            value = getattr(self, key)
            if value is not None:
                object.__setattr__(self, key, tuple(value))
        object.__setattr__(self, "quantiles", tuple(float(q) for q in self.quantiles))
        object.__setattr__(self, "units", dict(self.units))
        problems = []
        if any(not 0.0 < q < 1.0 for q in self.quantiles):
            problems.append(("analysis.quantiles", f"each must be in (0, 1), got {self.quantiles}"))
        if len(set(self.quantiles)) != len(self.quantiles):
            problems.append(("analysis.quantiles", f"a level is listed twice: {self.quantiles}"))
        if self.samples < MIN_SAMPLES:
            problems.append(("analysis.samples", f"need >= {MIN_SAMPLES}, got {self.samples}"))
        if any(f < 0 for f in self.pdf_freqs or ()):
            problems.append(("analysis.pdf_freqs", f"must be >= 0, got {self.pdf_freqs}"))
        window = window_problem(self.window)
        if window is not None:
            problems.append(("analysis.window", window))
        _raise(problems)

    def problems(
        self,
        times: NDArray[np.float64],
        outputs: Sequence[str],
        on_time: Sequence[str] | None = None,
    ) -> list[tuple[str, str]]:
        """What does not fit a study's time grid and outputs, as (key path, message).

        An unknown output, a spectrum of an output that is not on time (``on_time``: those
        that are; default all), a PDF time outside the grid, a spectrum on a non-uniform
        grid, a frequency above the grid's Nyquist frequency.
        """
        found = []
        for key, names in (("psd", self.psd or ()), ("units", self.units)):
            for i, name in enumerate(names):
                if name not in outputs:
                    where = f"analysis.{key}[{i}]" if key == "psd" else f"analysis.units.{name}"
                    found.append((where, f"{name!r} is not an output ({', '.join(outputs)})"))
                elif key == "psd" and on_time is not None and name not in on_time:
                    found.append((f"analysis.psd[{i}]", f"{name!r} is not a time output"))
        for i, t in enumerate(self.pdf_times or ()):
            if not times[0] <= t <= times[-1]:
                found.append(
                    (f"analysis.pdf_times[{i}]", f"{t} is outside [{times[0]}, {times[-1]}]")
                )
        if self.psd and not is_uniform_grid(times):
            found.append(("analysis.psd", "a spectrum needs a uniform time grid of >= 2 points"))
        elif is_uniform_grid(times):
            nyquist = 0.5 / (times[1] - times[0])
            for i, f in enumerate(self.pdf_freqs or ()):
                if f > nyquist:
                    found.append(
                        (
                            f"analysis.pdf_freqs[{i}]",
                            f"{f} Hz is above the Nyquist frequency {nyquist:g} Hz of the grid",
                        )
                    )
        return found

    def check(
        self,
        times: NDArray[np.float64],
        outputs: Sequence[str],
        on_time: Sequence[str] | None = None,
    ) -> None:
        """Check the settings against a study's time grid and outputs, before it runs.

        Raises
        ------
        ConfigError
            With every problem :meth:`problems` finds.
        """
        _raise(self.problems(times, outputs, on_time))

    def spectrum_outputs(self, times: NDArray[np.float64], outputs: Sequence[str]) -> list[str]:
        """The outputs that get a spectrum."""
        if self.psd is None:
            return list(outputs) if is_uniform_grid(times) else []
        return [name for name in outputs if name in self.psd]

    def describe(self) -> dict[str, Any]:
        """A JSON-able description (stored in the result file)."""
        return {
            "psd": None if self.psd is None else list(self.psd),
            "window": self.window,
            "pdf_times": None if self.pdf_times is None else list(self.pdf_times),
            "pdf_freqs": None if self.pdf_freqs is None else list(self.pdf_freqs),
            "quantiles": list(self.quantiles),
            "samples": self.samples,
            "seed": self.seed,
            "units": dict(self.units),
            "time_unit": self.time_unit,
        }

    @classmethod
    def from_description(cls, description: str | Mapping[str, Any]) -> AnalysisSettings:
        """Settings from :meth:`describe`'s output (or its JSON text)."""
        data = json.loads(description) if isinstance(description, str) else dict(description)
        return cls(**data)


def window_problem(window: str) -> str | None:
    """Why ``window`` is not a supported window name, or ``None``."""
    try:
        taper(window, 2)
    except ValueError as error:
        return str(error)
    return None


def _raise(problems: Sequence[tuple[str, str]]) -> None:
    if problems:
        raise ConfigError([ConfigProblem(path, message) for path, message in problems])


@dataclass(frozen=True)
class Density:
    """Densities of a scalar quantity at several locations (times or frequencies).

    Attributes
    ----------
    at:
        (P,) the times or frequencies (grid points actually used).
    value:
        (P, G) where each density is tabulated.
    density:
        (P, G) the densities; an all-NaN row means a point mass at ``value[p, 0]``.
    bandwidth:
        (P,) the kernel bandwidths (NaN for a point mass).
    """

    at: NDArray[np.float64]
    value: NDArray[np.float64]
    density: NDArray[np.float64]
    bandwidth: NDArray[np.float64]


@dataclass(frozen=True)
class Spectrum:
    """PSD statistics of one output, (F,) arrays.

    Attributes
    ----------
    frequency:
        In Hz (cycles per unit of time).
    mean, std:
        Mean PSD and the PSD's standard deviation, output unit² per Hz.
    nominal:
        PSD of the nominal run (``None`` without one).
    window:
        The window used.
    pdf:
        PDFs of the PSD at chosen frequencies.
    """

    frequency: NDArray[np.float64]
    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    nominal: NDArray[np.float64] | None
    window: str
    pdf: Density | None = None


@dataclass(frozen=True)
class OutputAnalysis:
    """Derived statistics of one output.

    Attributes
    ----------
    quantiles:
        (Q, T) quantile bands at :attr:`AnalysisSettings.quantiles`.
    pdf:
        PDFs at the chosen times.
    spectrum:
        Frequency-domain statistics, or ``None``.
    """

    quantiles: NDArray[np.float64]
    pdf: Density
    spectrum: Spectrum | None = None


@dataclass(frozen=True)
class Analysis:
    """The settings and, per output, the derived statistics."""

    settings: AnalysisSettings
    outputs: dict[str, OutputAnalysis]


def tensor_grid_of(result: StudyResult) -> TensorGrid | None:
    """The tensor Gauss grid a collocation result was computed on, or, for an expansion made
    without nodes (``grid`` ``"none"``: Galerkin), the one of its orders (``None`` otherwise)."""
    design = result.design
    if design.orders is None or design.grid not in ("tensor-gauss", "none"):
        return None
    return TensorGrid(result.distributions, design.orders)


def _density_table(at: NDArray[np.float64], columns: NDArray, *, nonnegative: bool) -> Density:
    """KDEs of each column of (M, P) samples, at the P locations ``at``."""
    tables = [kernel_density(columns[:, p], nonnegative=nonnegative) for p in range(at.size)]
    value = np.array([t[0] for t in tables]).reshape(at.size, DENSITY_POINTS)
    density = np.array([t[1] for t in tables]).reshape(at.size, DENSITY_POINTS)
    bandwidth = np.array([t[2] for t in tables], dtype=float).reshape(at.size)
    return Density(np.asarray(at, dtype=float), value, density, bandwidth)


def nearest_indices(grid: NDArray[np.float64], points: Sequence[float]) -> NDArray[np.int64]:
    """Index of the grid point nearest each point, (P,)."""
    return np.array([int(np.argmin(np.abs(grid - p))) for p in points], dtype=np.int64)


def _germ_draws(result: StudyResult, settings: AnalysisSettings) -> NDArray[np.float64]:
    """(samples, n) germ draws from the settings' seed, shared by every output."""
    rng = np.random.default_rng(settings.seed)
    return draw_germs(result.distributions, settings.samples, rng)


def _block_rows(terms: int) -> int:
    """Draws per block so that a block of the basis matrix stays near _BLOCK_VALUES."""
    return max(1, _BLOCK_VALUES // max(terms, 1))


Surrogate = ChaosExpansion | PiecewiseExpansion


def _pieces(
    expansion: Surrogate, xi: NDArray[np.float64]
) -> list[tuple[NDArray[np.intp], NDArray[np.float64], PolynomialBasis]]:
    """(rows, germ, basis) per piece of a surrogate at the global germ draws ``xi``: all
    rows for a chaos expansion; for a piecewise one, per element the draws inside it, in the
    element's own germ."""
    if not isinstance(expansion, PiecewiseExpansion):
        return [(np.arange(xi.shape[0]), xi, expansion.basis)]
    distributions = expansion.distributions
    theta = np.column_stack([d.to_physical(xi[:, k]) for k, d in enumerate(distributions)])
    where = expansion.partition.locate(theta)
    pieces = []
    for e, element in enumerate(expansion.elements):
        rows = np.flatnonzero(where == e)
        pieces.append((rows, element.to_germ(theta[rows]), element.basis))
    return pieces


def _piece_key(expansion: Surrogate) -> bytes:
    """Surrogates with equal keys share their basis matrices at the same draws."""
    key = expansion.multi_index.tobytes()
    if isinstance(expansion, PiecewiseExpansion):
        key += expansion.partition.bounds.tobytes()
    return key


def _stacked(columns: NDArray) -> NDArray[np.float64]:
    """Coefficient columns (S, K) or (E, S, K) as (E, S, K), E = 1 for a chaos expansion."""
    columns = np.asarray(columns, dtype=float)
    return columns.reshape(-1, *columns.shape[-2:])


class _Surrogates:
    """Surrogate values of many coefficient columns at the same global germ draws: (S, K)
    of a chaos expansion, (E, S, K) of a piecewise one.

    Evaluating the basis matrices is the costly part, so all requests on the same basis
    (and elements) are evaluated together, one block of draws at a time.
    """

    def __init__(self, xi: NDArray[np.float64]):
        self.xi = xi
        self._requests: list[tuple[Any, Surrogate, NDArray[np.float64]]] = []

    def add(self, key: Any, expansion: Surrogate, columns: NDArray[np.float64]) -> None:
        self._requests.append((key, expansion, _stacked(columns)))

    def evaluate(self) -> dict[Any, NDArray[np.float64]]:
        """Key -> (M, K) values."""
        groups: dict[bytes, list[tuple[Any, Surrogate, NDArray[np.float64]]]] = {}
        for request in self._requests:
            groups.setdefault(_piece_key(request[1]), []).append(request)
        found = {}
        for requests in groups.values():
            columns = np.concatenate([r[2] for r in requests], axis=2)
            values = np.empty((self.xi.shape[0], columns.shape[2]))
            for e, (rows, germ, basis) in enumerate(_pieces(requests[0][1], self.xi)):
                step = _block_rows(basis.size)
                for start in range(0, rows.size, step):
                    block = slice(start, start + step)
                    values[rows[block]] = basis.series(germ[block], columns[e])
            offsets = np.cumsum([0, *(r[2].shape[2] for r in requests)])
            for (key, _, _), low, high in zip(requests, offsets[:-1], offsets[1:], strict=True):
                found[key] = values[:, low:high]
        return found


def _quiet_overflow(method: Callable[..., _R]) -> Callable[..., _R]:
    """A PSD is in output units squared: for an output beyond ~1e154 it exceeds the largest
    float and becomes inf, without numpy's overflow warnings (the recovery's
    "square-overflow" warning record says so once)."""

    @functools.wraps(method)
    def quiet(*args: Any, **kwargs: Any) -> _R:
        with np.errstate(over="ignore", invalid="ignore"):
            return method(*args, **kwargs)

    return quiet


def _chaos_spectrum(result: StudyResult, name: str, window: str) -> ChaosSpectrum | None:
    """The chaos PSD of an output: on the study's tensor grid, on each element's for a
    piecewise expansion; ``None`` without either."""
    expansion, grid = result.expansions.get(name), tensor_grid_of(result)
    if isinstance(expansion, PiecewiseExpansion):
        return piecewise_spectrum(expansion, result.times, window)
    if expansion is None or grid is None:
        return None
    return chaos_spectrum(expansion, grid, result.times, window)


class _PsdSource:
    """The PSD of one output: chaos on a tensor grid (or each element's), else per-run
    periodograms."""

    @_quiet_overflow
    def __init__(self, result: StudyResult, name: str, settings: AnalysisSettings):
        self.chaos = _chaos_spectrum(result, name, settings.window)
        self.expansion = result.expansions.get(name)
        self.per_run = None
        if self.chaos is not None:
            self.frequency, self.mean, self.std = (
                self.chaos.frequency,
                self.chaos.mean,
                self.chaos.std,
            )
        else:
            ok = result.values[name][result.ok]
            self.frequency, self.per_run = periodogram(ok, result.times, settings.window)
            self.mean, self.std = sample_mean(self.per_run), sample_std(self.per_run)

    def bins(self, frequencies: Sequence[float] | None) -> NDArray[np.int64]:
        """Bins nearest ``frequencies``; ``None``: the highest peak above f = 0 (the DC bin
        holds the offset, not a vibration)."""
        if frequencies is None:
            return np.array([1 + int(np.argmax(self.mean[1:])) if self.mean.size > 1 else 0])
        return nearest_indices(self.frequency, frequencies)

    def request(self, surrogates: _Surrogates, key: Any, bins: NDArray[np.int64]) -> None:
        """Ask for the surrogate's Re and Im of Ŷ(f, ξ) at ``bins`` (chaos only)."""
        spectra = self.chaos.spectra[..., bins]
        surrogates.add(key, self.expansion, np.concatenate([spectra.real, spectra.imag], axis=-1))

    @_quiet_overflow
    def draws(self, bins: NDArray[np.int64], parts: NDArray | None) -> NDArray[np.float64]:
        """(M, P) PSD draws: per run, or s(f) |Ŷ(f, ξ)|² from the requested parts."""
        if self.chaos is None:
            return self.per_run[:, bins]
        real, imaginary = parts[:, : bins.size], parts[:, bins.size :]
        return self.chaos.scale[bins] * (real**2 + imaginary**2)

    @_quiet_overflow
    def spectrum(self, result: StudyResult, name: str, settings: AnalysisSettings, pdf: Density):
        nominal = result.nominal.get(name)
        psd = None if nominal is None else periodogram(nominal, result.times, settings.window)[1]
        return Spectrum(self.frequency, self.mean, self.std, psd, settings.window, pdf)


def output_draws(
    result: StudyResult, name: str, times: Sequence[float], settings: AnalysisSettings
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Draws of an output at the grid times nearest ``times`` (the points of its own axis
    for an output off the time grid; ``[0.]`` for a scalar).

    Surrogate values at ``settings.samples`` random inputs when the output has a chaos
    expansion, else the model runs themselves (see :func:`draws_are_runs`).

    Returns
    -------
    at, draws
        (P,) the grid times used and (M, P) the draws.
    """
    grid = result.grid(name)
    indices = nearest_indices(grid, times)
    expansion = result.expansions.get(name)
    if expansion is None:
        return grid[indices], result.values[name][result.ok][:, indices]
    surrogates = _Surrogates(_germ_draws(result, settings))
    surrogates.add(name, expansion, expansion.coefficients[..., indices])
    return grid[indices], surrogates.evaluate()[name]


def draws_are_runs(result: StudyResult, name: str) -> bool:
    """Whether :func:`output_draws` returns the model runs (sampling without a chaos fit)."""
    return name not in result.expansions


def _psd_draws(
    source: _PsdSource, result: StudyResult, settings: AnalysisSettings, bins: NDArray[np.int64]
) -> NDArray[np.float64]:
    """(M, P) PSD draws of one source at ``bins``."""
    parts = None
    if source.chaos is not None:
        surrogates = _Surrogates(_germ_draws(result, settings))
        source.request(surrogates, "psd", bins)
        parts = surrogates.evaluate()["psd"]
    return source.draws(bins, parts)


def psd_draws(
    result: StudyResult, name: str, frequencies: Sequence[float], settings: AnalysisSettings
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Draws of an output's PSD at the frequency bins nearest ``frequencies``.

    The surrogate PSD at ``settings.samples`` random inputs on a collocation grid, else the
    per-run periodograms (see :func:`psd_draws_are_runs`).

    Returns
    -------
    at, draws
        (P,) the bin frequencies used and (M, P) the draws.

    Raises
    ------
    ValueError
        If the time grid is not uniform.
    """
    source = _PsdSource(result, name, settings)
    bins = source.bins(frequencies)
    return source.frequency[bins], _psd_draws(source, result, settings, bins)


def psd_draws_are_runs(result: StudyResult, name: str) -> bool:
    """Whether :func:`psd_draws` returns per-run periodograms (no collocation expansion)."""
    expansion = result.expansions.get(name)
    return expansion is None or (
        tensor_grid_of(result) is None and not isinstance(expansion, PiecewiseExpansion)
    )


def spectrum(
    result: StudyResult,
    name: str,
    settings: AnalysisSettings,
    frequencies: Sequence[float] | None = None,
) -> Spectrum:
    """PSD statistics of one output, with PDFs of the PSD at ``frequencies``.

    Parameters
    ----------
    frequencies:
        Where to tabulate the PSD's PDF; default ``settings.pdf_freqs``, else the highest
        peak of the mean PSD above f = 0.

    Raises
    ------
    ValueError
        If the time grid is not uniform.
    """
    source = _PsdSource(result, name, settings)
    bins = source.bins(settings.pdf_freqs if frequencies is None else frequencies)
    draws = _psd_draws(source, result, settings, bins)
    pdf = _density_table(source.frequency[bins], draws, nonnegative=True)
    return source.spectrum(result, name, settings, pdf)


def _quantile_bands(
    result: StudyResult, xi: NDArray[np.float64], levels: Sequence[float]
) -> dict[str, NDArray[np.float64]]:
    """Output -> (Q, T) quantiles over time; the basis matrices of the draws are evaluated
    once per basis (and elements) and the values in time blocks that bound memory."""
    bands = {}
    phis: dict[bytes, list[tuple[NDArray[np.intp], NDArray[np.float64]]]] = {}
    block = max(1, _BLOCK_VALUES // xi.shape[0])
    for name in result.outputs:
        n_times = result.values[name].shape[1]
        expansion = result.expansions.get(name)
        if expansion is None:
            runs = result.values[name][result.ok]
            bands[name] = np.quantile(runs, levels, axis=0).reshape(len(levels), n_times)
            continue
        key = _piece_key(expansion)
        if key not in phis:
            phis[key] = [
                (rows, basis.evaluate(germ)) for rows, germ, basis in _pieces(expansion, xi)
            ]
        coefficients = _stacked(expansion.coefficients)
        parts = []
        for start in range(0, n_times, block):
            values = np.empty((xi.shape[0], min(block, n_times - start)))
            for e, (rows, phi) in enumerate(phis[key]):
                values[rows] = phi @ coefficients[e][:, start : start + block]
            parts.append(_column_quantiles(values, levels))
        bands[name] = np.concatenate(parts, axis=1).reshape(len(levels), n_times)
    return bands


def _column_quantiles(values: NDArray[np.float64], levels: Sequence[float]) -> NDArray[np.float64]:
    """``np.quantile(values, levels, axis=0)`` (method "linear"), the same numbers, faster.

    np.quantile partitions every column around several ranks at once, which is slow; a sort
    is several times faster. Each level's value is numpy's own interpolation between the
    two order statistics around its virtual index (n - 1)·q, obtained from np.quantile on
    that pair with the same fractional part, so the arithmetic is numpy's. Columns with NaN
    or with a zero order statistic (where numpy's choice of -0.0 or +0.0 depends on the
    partition) go through np.quantile itself.
    """
    n = values.shape[0]
    ordered = np.ascontiguousarray(values.T)
    ordered.sort(axis=1)
    if n < 2 or np.isnan(ordered[:, -1]).any():
        return np.quantile(values, levels, axis=0)
    bands = np.empty((len(levels), values.shape[1]))
    fallback = np.zeros(values.shape[1], dtype=bool)
    for i, level in enumerate(levels):
        virtual = (n - 1) * np.float64(level)
        low = int(np.floor(virtual))
        if low >= n - 1:
            bands[i] = ordered[:, -1]
            fallback |= ordered[:, -1] == 0
            continue
        pair = ordered[:, low : low + 2]
        bands[i] = np.quantile(pair, virtual - low, axis=1)
        fallback |= (pair == 0).any(axis=1)
    if fallback.any():
        bands[:, fallback] = np.quantile(values[:, fallback], levels, axis=0)
    return bands


def _pdf_points(result: StudyResult, name: str, settings: AnalysisSettings) -> NDArray[np.intp]:
    """Where an output's PDFs are tabulated: a time output at ``settings.pdf_times`` (the
    final time by default); an output on its own axis at the point of its largest std; a
    scalar at its one point."""
    if result.on_time(name):
        times = result.times
        return nearest_indices(times, settings.pdf_times or (times[-1],))
    std = np.nan_to_num(np.atleast_1d(result.std(name)), nan=-1.0)
    return np.array([int(np.argmax(std))])


def analyse(result: StudyResult, settings: AnalysisSettings | None = None) -> Analysis:
    """Quantile bands, PDFs and spectra of every output of a result.

    Parameters
    ----------
    result:
        A study result (from :meth:`pcmb.Study.run` or :func:`pcmb.load`).
    settings:
        What to compute (default :class:`AnalysisSettings`).

    Returns
    -------
    Analysis

    Raises
    ------
    ConfigError
        If the settings do not fit the result (see :meth:`AnalysisSettings.check`).
    """
    settings = settings or AnalysisSettings()
    times = result.times
    on_time = [name for name in result.outputs if result.on_time(name)]
    settings.check(times, result.outputs, on_time)
    if result.moments:
        raise UsageError(
            f"a {result.method} result holds the mean and std only (no runs, no expansion): "
            "quantiles, PDFs and spectra cannot be drawn from it; compare it with pcmb compare"
        )
    xi = _germ_draws(result, settings)
    pdf_at = {name: _pdf_points(result, name, settings) for name in result.outputs}
    sources = {
        name: _PsdSource(result, name, settings)
        for name in settings.spectrum_outputs(times, on_time)
        if name in on_time
    }
    bins = {name: source.bins(settings.pdf_freqs) for name, source in sources.items()}
    # Every surrogate draw of every output in one pass over the basis matrix.
    surrogates = _Surrogates(xi)
    for name, expansion in result.expansions.items():
        surrogates.add(("time", name), expansion, expansion.coefficients[..., pdf_at[name]])
    for name, source in sources.items():
        if source.chaos is not None:
            source.request(surrogates, ("psd", name), bins[name])
    drawn = surrogates.evaluate()
    bands = _quantile_bands(result, xi[:QUANTILE_DRAWS], settings.quantiles)
    outputs = {}
    for name in result.outputs:
        indices = pdf_at[name]
        at_times = drawn.get(("time", name))
        if at_times is None:
            at_times = result.values[name][result.ok][:, indices]
        spectrum_ = None
        if name in sources:
            source, k = sources[name], bins[name]
            psd = source.draws(k, drawn.get(("psd", name)))
            pdf = _density_table(source.frequency[k], psd, nonnegative=True)
            spectrum_ = source.spectrum(result, name, settings, pdf)
        outputs[name] = OutputAnalysis(
            quantiles=bands[name],
            pdf=_density_table(result.grid(name)[indices], at_times, nonnegative=False),
            spectrum=spectrum_,
        )
    return Analysis(settings, outputs)
