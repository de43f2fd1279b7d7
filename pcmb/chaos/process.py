"""Gaussian random processes on a grid, truncated by accuracy (Karhunen–Loève).

A zero-mean Gaussian process z(x) with a stationary covariance R(|x1 - x2|) on the interval
of a uniform grid is expanded as

    z(x) = Σ_k √λ_k g_k(x) ξ_k,   ξ_k independent N(0, 1),

keeping the fewest terms whose eigenvalues carry a requested share (``energy``) of the total
variance ∫ R(0) dx, or a given number of terms. Each kept ξ_k is an ordinary standard normal
input of a study; the model receives the realised field at the grid points, (B, m).

The eigenproblem ∫ R(x, y) g(y) dy = λ g(x) is solved by a symmetric Nyström method on the
grid refined to at least :data:`NYSTROM_POINTS` points, with Gregory's end-corrected
trapezoid weights and, for a covariance with a kink at zero lag (R'(0+) < 0: exponential,
Matérn ν = 1/2), the Euler–Maclaurin correction of that kink, (h²/6)·R'(0+) added to every
eigenvalue. The error is then O(h⁴) in the spacing h (about (ω_k h)⁴/240 relative for the
exponential kernel's k-th eigenfunction of frequency ω_k) instead of the O(h²) of a plain
rule; ``docs/processes.md`` has the measurements. The kept eigenfunctions are the eigenvector
entries at the grid points (the refined grid contains them), so no interpolation is involved.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.inputs import Distribution, Normal
from pcmb.chaos.kl import ZERO_RATIO, Kernel, Spectrum, line_covariance, spectral_covariance

_T = TypeVar("_T")
_STANDARD_NORMAL = Normal(0.0, 1.0)

__all__ = [
    "COVARIANCES",
    "MAX_GRID_POINTS",
    "NYSTROM_POINTS",
    "Covariance",
    "RandomProcess",
    "covariance_from_description",
    "exponential",
    "germ_inputs",
    "germ_names",
    "line_spectrum",
    "matern",
    "model_params",
    "per_germ",
    "squared_exponential",
    "tabulated_psd",
]

#: The Nyström grid is the process grid refined to at least this many points.
NYSTROM_POINTS = 2000
#: Most points of a process grid (the eigenproblem is dense: m² memory, m³ work).
MAX_GRID_POINTS = 2001
#: Share of the variance kept when neither ``energy`` nor ``terms`` is given.
DEFAULT_ENERGY = 0.99


@dataclass(frozen=True)
class Covariance:
    """A stationary covariance R(x1, x2) = R(|x1 - x2|).

    Attributes
    ----------
    function:
        R(τ) at lags τ >= 0, (L,) -> (L,).
    variance:
        R(0), the pointwise variance.
    slope:
        R'(0+) (<= 0): the one-sided slope at zero lag; 0 for a covariance that is smooth
        there. A kink corrects the Nyström eigenvalues (see the module notes).
    description:
        The settings, for messages and the result file.
    rate:
        p, the order in the spacing h of the Nyström eigenvalues' error (4 with the kink
        corrected), used to estimate that error from a grid of half the points.
    length:
        ℓ, the correlation length (``None`` for a spectrum): the expansion refuses a grid
        whose spacing no ℓ-sized feature spans.
    """

    function: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    variance: float
    slope: float
    description: dict[str, object]
    rate: float = 4.0
    length: float | None = None


def _positive(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")


def _at_lags(kernel: Kernel, width: int) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """R(τ) = kernel(τ, 0) of a stationary kernel, evaluated ``width`` lags at a time (a
    tabulated spectrum costs lags x frequencies memory)."""

    def function(lag: NDArray[np.float64]) -> NDArray[np.float64]:
        zero = np.zeros(1)
        chunks = [kernel(lag[i : i + width], zero)[:, 0] for i in range(0, lag.size, width)]
        return np.concatenate(chunks) if chunks else np.zeros(0)

    return function


def exponential(sigma: float, length: float) -> Covariance:
    """R(τ) = σ² exp(-|τ|/ℓ) (Ornstein–Uhlenbeck; rough: a kink at zero lag)."""
    _positive(sigma=sigma, length=length)
    return Covariance(
        lambda lag: sigma**2 * np.exp(-lag / length),
        sigma**2,
        -(sigma**2) / length,
        {"kind": "exponential", "sigma": sigma, "length": length},
        length=length,
    )


def squared_exponential(sigma: float, length: float) -> Covariance:
    """R(τ) = σ² exp(-τ²/(2ℓ²)) (smooth)."""
    _positive(sigma=sigma, length=length)
    return Covariance(
        lambda lag: sigma**2 * np.exp(-0.5 * (lag / length) ** 2),
        sigma**2,
        0.0,
        {"kind": "squared-exponential", "sigma": sigma, "length": length},
        length=length,
    )


def matern(sigma: float, length: float, nu: float) -> Covariance:
    """R(τ) = σ² 2^(1-ν)/Γ(ν) (√(2ν) τ/ℓ)^ν K_ν(√(2ν) τ/ℓ).

    ν = 1/2 is the exponential covariance, ν → ∞ the squared exponential; the process is
    ⌈ν⌉ - 1 times mean-square differentiable. For ν < 1/2 the kink at zero lag is sharper
    than the correction handles and the eigenvalues converge as h^(1+2ν).
    """
    _positive(sigma=sigma, length=length, nu=nu)
    import scipy.special as sp  # here: reading a config never needs it

    scale = math.sqrt(2 * nu) / length
    factor = sigma**2 * 2 ** (1 - nu) / sp.gamma(nu)

    def function(lag: NDArray[np.float64]) -> NDArray[np.float64]:
        u = scale * lag
        with np.errstate(invalid="ignore", over="ignore"):
            values = factor * u**nu * sp.kv(nu, u)
        # Limits: σ² at zero lag, 0 where K_ν underflows.
        return np.where(u == 0, sigma**2, np.nan_to_num(values, nan=0.0, posinf=0.0))

    # R'(0+) = -σ²·scale at ν = 1/2; zero for ν > 1/2; unbounded (not corrected) below.
    slope = -(sigma**2) * scale if nu == 0.5 else 0.0
    return Covariance(
        function,
        sigma**2,
        slope,
        {"kind": "matern", "sigma": sigma, "length": length, "nu": nu},
        rate=4.0 if nu == 0.5 else min(4.0, 1 + 2 * nu),
        length=length,
    )


def line_spectrum(omega: ArrayLike, variance: ArrayLike) -> Covariance:
    """R(τ) = Σ_i σ_i² cos(ω_i τ): random-phase cosines at angular frequencies ω_i.

    On an interval holding a whole number of periods of every line, each line with ω_i > 0
    gives exactly two eigenpairs (cos and sin), each with eigenvalue (b - a) σ_i²/2.
    """
    kernel = line_covariance(omega, variance)
    omega, variance = np.asarray(omega, dtype=float), np.asarray(variance, dtype=float)
    return Covariance(
        _at_lags(kernel, max(1, 10_000_000 // omega.size)),
        float(variance.sum()),
        0.0,
        {"kind": "lines", "omega": omega.tolist(), "variance": variance.tolist()},
    )


def tabulated_psd(omega: ArrayLike, density: ArrayLike) -> Covariance:
    """R(τ) = ∫_0^∞ S(ω) cos(ωτ) dω from a sampled one-sided PSD (Wiener–Khinchin)."""
    kernel = spectral_covariance(omega, density)
    omega, density = np.asarray(omega, dtype=float), np.asarray(density, dtype=float)
    return Covariance(
        _at_lags(kernel, max(1, 10_000_000 // omega.size)),
        float(kernel(np.zeros(1), np.zeros(1))[0, 0]),
        0.0,
        {"kind": "psd", "omega": omega.tolist(), "density": density.tolist()},
    )


#: ``covariance.kind`` -> constructor; the other keys of the section are its arguments.
COVARIANCES: dict[str, Callable[..., Covariance]] = {
    "exponential": exponential,
    "squared-exponential": squared_exponential,
    "matern": matern,
    "lines": line_spectrum,
    "psd": tabulated_psd,
}


def covariance_from_description(description: Mapping[str, Any]) -> Covariance:
    """The covariance of a :attr:`Covariance.description` (or a config's ``covariance``)."""
    settings = dict(description)
    return COVARIANCES[settings.pop("kind")](**settings)


def germ_names(name: str, terms: int) -> tuple[str, ...]:
    """Names of a process's germ inputs: ``name[0]``, ``name[1]``, ..."""
    return tuple(f"{name}[{k}]" for k in range(terms))


def germ_inputs(inputs: Mapping[str, Distribution | RandomProcess]) -> dict[str, Distribution]:
    """The inputs in germ order, each process replaced by its standard normal germs."""
    germs: dict[str, Distribution] = {}
    for name, value in inputs.items():
        if isinstance(value, RandomProcess):
            germs.update(dict.fromkeys(germ_names(name, value.terms), _STANDARD_NORMAL))
        else:
            germs[name] = value
    return germs


def per_germ(values: Mapping[str, _T], inputs: Mapping[str, object]) -> dict[str, _T]:
    """A mapping by input name with a process's value given to each of its germs."""
    out: dict[str, _T] = {}
    for name, value in values.items():
        found = inputs.get(name)
        if isinstance(found, RandomProcess):
            out.update(dict.fromkeys(germ_names(name, found.terms), value))
        else:
            out[name] = value
    return out


def model_params(
    inputs: Mapping[str, Distribution | RandomProcess], values: ArrayLike
) -> dict[str, NDArray[np.float64]]:
    """What a model receives for nodes of physical values (N, n) in germ order: a
    distribution's column (N,), a process's field realised from its germs (N, m)."""
    values = np.asarray(values, dtype=float)
    params, column = {}, 0
    for name, value in inputs.items():
        if isinstance(value, RandomProcess):
            params[name] = value.realize(values[:, column : column + value.terms])
            column += value.terms
        else:
            params[name] = values[:, column]
            column += 1
    return params


def _gregory_weights(points: int, h: float) -> NDArray[np.float64]:
    """Gregory's end-corrected trapezoid weights (exact for cubics, O(h⁴)), (points,)."""
    weights = np.full(points, h)
    if points >= 6:
        ends = h * np.array([3 / 8, 7 / 6, 23 / 24])
        weights[:3], weights[-3:] = ends, ends[::-1]
    else:
        weights[[0, -1]] = h / 2
    return weights


def _parity_bases(points: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Orthonormal bases (J, ⌈J/2⌉) and (J, ⌊J/2⌋) of the vectors even and odd about the
    middle of J points."""
    half = points // 2
    even = np.zeros((points, points - half))
    odd = np.zeros((points, half))
    pairs = np.arange(half)
    even[pairs, pairs] = even[points - 1 - pairs, pairs] = np.sqrt(0.5)
    odd[pairs, pairs], odd[points - 1 - pairs, pairs] = np.sqrt(0.5), -np.sqrt(0.5)
    if points % 2:
        even[half, half] = 1.0
    return even, odd


@dataclass(frozen=True)
class _Nystrom:
    """The Nyström eigenproblem of a stationary covariance on ``points`` uniform points.

    A stationary kernel on a uniform grid with symmetric weights is a centro-symmetric
    matrix: its eigenvectors are even or odd about the middle, found from two problems of
    half the size (4x less work). That also fixes the basis of a double eigenvalue (the
    cos/sin pair of a spectral line on whole periods) and, with the sign rule (largest entry
    positive), makes the modes the same on every machine.
    """

    covariance: Covariance
    start: float
    stop: float
    points: int

    @functools.cached_property
    def _problems(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """(basis (J, n_b), symmetric matrix (n_b, n_b)) of the even and the odd half."""
        import scipy.linalg  # here: reading a config never needs it

        h = (self.stop - self.start) / (self.points - 1)
        root = np.sqrt(_gregory_weights(self.points, h))
        # Stationary on a uniform grid: R(|x_i - x_j|) is a Toeplitz matrix of J lags.
        lags = self.covariance.function(np.arange(self.points) * h)
        matrix = root[:, None] * scipy.linalg.toeplitz(lags) * root[None, :]
        return [
            (basis, basis.T @ matrix @ basis)
            for basis in _parity_bases(self.points)
            if basis.shape[1]
        ]

    @functools.cached_property
    def spectrum(self) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Every eigenvalue (J,), decreasing, and the half (0 even, 1 odd) it belongs to."""
        import scipy.linalg  # here: reading a config never needs it

        found = [scipy.linalg.eigvalsh(block) for _, block in self._problems]
        values = np.concatenate(found)
        half = np.repeat(np.arange(len(found)), [f.size for f in found])
        order = np.argsort(values, kind="stable")[::-1]
        h = (self.stop - self.start) / (self.points - 1)
        # Euler–Maclaurin: the kink of R at zero lag sits on a node of every row.
        return values[order] + h**2 / 6 * self.covariance.slope, half[order]

    def modes(self, count: int) -> NDArray[np.float64]:
        """The leading ``count`` eigenfunctions at the points, (J, count), orthonormal in
        L²(start, stop) under the rule, in the order of :attr:`spectrum`."""
        import scipy.linalg  # here: reading a config never needs it

        _, half = self.spectrum
        h = (self.stop - self.start) / (self.points - 1)
        root = np.sqrt(_gregory_weights(self.points, h))
        out = np.empty((self.points, count))
        for b, (basis, block) in enumerate(self._problems):
            where = np.flatnonzero(half[:count] == b)
            if where.size:
                n = block.shape[0]
                _, inner = scipy.linalg.eigh(block, subset_by_index=[n - where.size, n - 1])
                out[:, where] = basis @ inner[:, ::-1]
        peaks = np.argmax(np.abs(out), axis=0)
        out *= np.sign(out[peaks, np.arange(count)])
        return out / root[:, None]


@dataclass(frozen=True)
class RandomProcess(Spectrum):
    """A zero-mean Gaussian process on a uniform grid, truncated Karhunen–Loève.

    Attributes
    ----------
    covariance:
        Its :class:`Covariance`.
    grid:
        (m,) the points where the model receives the field.
    eigenvalues:
        (K,) kept eigenvalues λ_1 >= ... >= λ_K > 0.
    modes:
        (K, m) √λ_k g_k at the grid points: the field is ``germs @ modes``.
    energy:
        The requested share of the variance (``None`` when ``terms`` was given).
    total_variance:
        ∫ R(0) dx = R(0)·(stop - start), the sum of all eigenvalues.
    eigenvalue_error:
        Estimated largest relative error of a kept eigenvalue: the change from a Nyström
        grid of half the points, divided by 2^p - 1 (Richardson, p the covariance's rate).
    nystrom_points:
        J, points of the Nyström grid (the grid refined by a whole factor).
    """

    covariance: Covariance
    grid: NDArray[np.float64]
    eigenvalues: NDArray[np.float64]
    modes: NDArray[np.float64]
    energy: float | None
    total_variance: float
    eigenvalue_error: float
    nystrom_points: int

    def __post_init__(self) -> None:
        for array in (self.grid, self.eigenvalues, self.modes):
            array.setflags(write=False)  # shared: a config's expansion is made once

    @classmethod
    def karhunen_loeve(
        cls,
        covariance: Covariance,
        start: float,
        stop: float,
        points: int,
        *,
        energy: float | None = None,
        terms: int | None = None,
    ) -> RandomProcess:
        """Expand a process on ``numpy.linspace(start, stop, points)``.

        Parameters
        ----------
        covariance:
            A stationary :class:`Covariance`.
        start, stop, points:
            The grid (start < stop, 2 <= points <= :data:`MAX_GRID_POINTS`).
        energy:
            Keep the fewest terms whose eigenvalues carry this share of the total variance,
            in (0, 1] (default :data:`DEFAULT_ENERGY` when ``terms`` is not given either).
        terms:
            Keep exactly this many terms instead.

        Raises
        ------
        ValueError
            "key: message", naming ``grid``, ``energy`` or ``terms`` for a bad grid or
            truncation setting, or a covariance with fewer non-zero eigenvalues than
            ``terms``; ``covariance.length`` for a correlation length shorter than the
            spacing of the Nyström grid (no term resolves it); ``covariance`` for a
            covariance without a positive eigenvalue on the grid.
        """
        if not start < stop:
            raise ValueError(f"grid: expected start < stop, found {start!r} >= {stop!r}")
        if not 2 <= points <= MAX_GRID_POINTS:
            raise ValueError(f"grid.points: expected 2 to {MAX_GRID_POINTS} points, found {points}")
        if energy is not None and terms is not None:
            raise ValueError("terms: give energy or terms, not both")
        if energy is not None and not 0 < energy <= 1:
            raise ValueError(f"energy: expected a share in (0, 1], found {energy!r}")
        if terms is not None and terms < 1:
            raise ValueError(f"terms: expected at least 1, found {terms}")
        if terms is None and energy is None:
            energy = DEFAULT_ENERGY
        # The Nyström grid refines the process grid by a whole factor, so that it contains
        # the grid's points, into an even number of intervals, so that a grid of half as many
        # points exists for the error estimate.
        factor = max(1, math.ceil((NYSTROM_POINTS - 1) / (points - 1)))
        factor += factor * (points - 1) % 2
        fine = factor * (points - 1) + 1
        spacing = (stop - start) / (fine - 1)
        if covariance.length is not None and covariance.length < spacing:
            raise ValueError(
                f"covariance.length: the correlation length {covariance.length:g} is shorter "
                f"than the spacing {spacing:.3g} of the grid the expansion is solved on "
                f"({fine} points on [{start:g}, {stop:g}]), so no term of the expansion "
                "resolves it (the field would be noise from point to point); give a length "
                f"of at least {spacing:.3g}, or a shorter interval"
            )
        nystrom = _Nystrom(covariance, start, stop, fine)
        values, _ = nystrom.spectrum
        total = covariance.variance * (stop - start)
        if not values[0] > 0:
            raise ValueError(
                "covariance: no eigenvalue of the covariance is positive on this grid, so the "
                "expansion would capture none of its variance"
            )
        positive = int(np.sum(values > ZERO_RATIO * values[0]))
        if terms is None:
            captured = np.cumsum(values[:positive]) / total
            terms = min(positive, int(np.searchsorted(captured, energy * (1 - 1e-12)) + 1))
            if terms > points:
                # The field at m points has at most m independent germs: the rest would be
                # inputs that change nothing the model sees.
                key = "grid.points" if covariance.length is None else "covariance.length"
                raise ValueError(
                    f"{key}: the expansion needs {terms} terms to carry {energy:g} of the "
                    f"variance, more than the {points} points of the grid, whose spacing "
                    f"{(stop - start) / (points - 1):g} does not resolve the covariance"
                    + ("" if covariance.length is None else f" (length {covariance.length:g})")
                    + f"; give grid.points of at least {terms}, a longer correlation, or a "
                    "smaller energy"
                )
        elif terms > positive:
            raise ValueError(
                f"terms: the covariance has {positive} non-zero eigenvalues on this grid, "
                f"fewer than the {terms} asked for"
            )
        coarse = _Nystrom(covariance, start, stop, fine // 2 + 1).spectrum[0][:terms]
        change = np.abs(coarse - values[: coarse.size]) / values[: coarse.size]
        change /= 2**covariance.rate - 1
        kept = values[:terms]
        return cls(
            covariance=covariance,
            grid=np.linspace(start, stop, points),
            eigenvalues=kept.copy(),
            modes=(nystrom.modes(terms)[::factor] * np.sqrt(kept)).T.copy(),
            energy=energy,
            total_variance=total,
            eigenvalue_error=float(change.max()),
            nystrom_points=fine,
        )

    @property
    def truncation_error(self) -> float:
        """Relative mean-square error of the truncated field over the interval:
        E ∫ (z - z_K)² dx / E ∫ z² dx = Σ_{k>K} λ_k / Σ_k λ_k."""
        return max(0.0, 1.0 - self.captured_energy)

    @property
    def variance_error(self) -> NDArray[np.float64]:
        """(m,) variance the truncation loses at each grid point, R(0) - Σ_k λ_k g_k(x)²."""
        return self.covariance.variance - np.sum(self.modes**2, axis=0)

    def realize(self, germs: ArrayLike) -> NDArray[np.float64]:
        """The field at the grid points, (B, m), for germs (B, K)."""
        germs = np.asarray(germs, dtype=float)
        if germs.ndim != 2 or germs.shape[1] != self.terms:
            raise ValueError(f"germs must be (B, {self.terms}), got shape {germs.shape}")
        return germs @ self.modes

    def describe(self) -> dict[str, object]:
        """The settings as plain data (JSON-able)."""
        return {
            "process": "kl",
            "covariance": self.covariance.description,
            "grid": {
                "start": float(self.grid[0]),
                "stop": float(self.grid[-1]),
                "points": int(self.grid.size),
            },
            **({"energy": self.energy} if self.energy is not None else {"terms": self.terms}),
        }
