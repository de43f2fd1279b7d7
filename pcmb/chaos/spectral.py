"""Frequency-domain statistics: the chaos expansion of a spectrum (Part I Eq. 71–72).

The Fourier transform is linear, so the transform of y(t, ξ) = Σ_α c_α(t) φ_α(ξ) is
Ŷ(f, ξ) = Σ_α ĉ_α(f) φ_α(ξ): transforming the S coefficient series gives the spectrum
of every realisation. The power spectral density at ξ is s(f) |Ŷ(f, ξ)|², so

- the **mean PSD** is exact from the coefficient spectra: E[PSD(f)] = s(f) Σ_α |ĉ_α(f)|²
  (orthonormality);
- the **PSD band** (±1σ) comes from the PSD's own chaos expansion: PSD(f, ξ) is evaluated
  at the collocation nodes and projected like any other output — on a tensor grid this
  equals the quadrature of the per-node PSDs, Var = Σ_i w_i (PSD_i - mean)². It is the
  collocation estimate of the model's PSD spread, not the exact variance of the squared
  surrogate (a degree-4P integrand the (P+1)-point rule does not integrate exactly); the
  two differ by the truncation error and agree as the order grows;
- the **PDF of the PSD at a frequency** comes from sampling ξ through the coefficient
  spectra (the exact surrogate PSD, not its projection).

Conventions: uniform time grid (checked), one-sided density ("PSD") in units of y² per Hz,
the same as :func:`scipy.signal.periodogram` with ``scaling="density"``: for a window w_n
over T samples at step Δt, PSD_k = 2 Δt |Σ_n w_n y_n e^{-2πikn/T}|² / Σ_n w_n², with the
factor 2 dropped at f = 0 and at the Nyquist frequency. Default window ``"hann"`` (a
transient record is not periodic; use ``"boxcar"`` for exactly periodic records). The
mean is *not* removed: the deterministic offset shows at f = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import evaluate_tensor, project_tensor

__all__ = [
    "WINDOWS",
    "ChaosSpectrum",
    "chaos_spectrum",
    "coefficient_spectra",
    "periodogram",
    "taper",
    "uniform_step",
]

#: Supported windows: numpy's symmetric windows, made periodic (DFT-even) like
#: ``scipy.signal.get_window(name, n, fftbins=True)`` — without importing scipy.signal (~1 s).
WINDOWS = {
    "boxcar": np.ones,
    "hann": np.hanning,
    "hamming": np.hamming,
    "blackman": np.blackman,
    "bartlett": np.bartlett,
}


def taper(window: str, n_times: int) -> NDArray[np.float64]:
    """The periodic window of length ``n_times``.

    Raises
    ------
    ValueError
        If the window is not one of :data:`WINDOWS`.
    """
    if window not in WINDOWS:
        raise ValueError(f"expected one of {', '.join(WINDOWS)}, found {window!r}")
    return WINDOWS[window](n_times + 1)[:-1]


def uniform_step(times: ArrayLike) -> float:
    """The step of a uniform, increasing grid of at least two points.

    Raises
    ------
    ValueError
        If the grid is shorter, not uniform or not increasing.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size < 2:
        raise ValueError("a spectrum needs a 1-D time grid of at least two points")
    steps = np.diff(times)
    if not np.allclose(steps, steps[0], rtol=1e-9, atol=0.0) or steps[0] <= 0:
        raise ValueError("a spectrum needs a uniform, increasing time grid")
    return float(steps[0])


def _transform(
    values: NDArray[np.float64], times: ArrayLike, window: str
) -> tuple[NDArray[np.float64], NDArray[np.complex128], NDArray[np.float64]]:
    """Frequencies (F,), windowed transforms (..., F) and the density scale s(f) (F,)."""
    dt = uniform_step(times)
    n_times = values.shape[-1]
    weights = taper(window, n_times)
    transform = np.fft.rfft(values * weights, axis=-1)
    frequency = np.fft.rfftfreq(n_times, dt)
    scale = np.full(frequency.size, 2.0 * dt / np.sum(weights**2))
    scale[0] /= 2.0
    if n_times % 2 == 0:
        scale[-1] /= 2.0
    return frequency, transform, scale


def periodogram(
    values: ArrayLike, times: ArrayLike, window: str = "hann"
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One-sided PSD of signals on a uniform grid.

    Parameters
    ----------
    values:
        (..., T) signals, time last.
    times:
        (T,) uniform grid.
    window:
        One of :data:`WINDOWS`.

    Returns
    -------
    frequency, psd
        (F,) frequencies in Hz (cycles per unit of time) and (..., F) densities.

    Raises
    ------
    ValueError
        If the grid is not uniform.
    """
    frequency, transform, scale = _transform(np.asarray(values, dtype=float), times, window)
    return frequency, scale * np.abs(transform) ** 2


def coefficient_spectra(
    expansion: ChaosExpansion, times: ArrayLike, window: str = "hann"
) -> tuple[NDArray[np.float64], NDArray[np.complex128], NDArray[np.float64]]:
    """The spectra ĉ_α(f) of an (S, T) expansion's coefficient series.

    Returns
    -------
    frequency, spectra, scale
        (F,) frequencies, (S, F) complex coefficient spectra, (F,) density scale s(f) such
        that PSD(f, ξ) = s(f) |Σ_α ĉ_α(f) φ_α(ξ)|².
    """
    if expansion.coefficients.ndim != 2:
        raise ValueError("coefficient spectra need an (S, T) expansion over time")
    return _transform(expansion.coefficients, times, window)


@dataclass(frozen=True)
class ChaosSpectrum:
    """Frequency-domain statistics of one output.

    Attributes
    ----------
    frequency:
        (F,) in Hz.
    mean, std:
        (F,) mean PSD (exact, from Σ|ĉ_α|²) and standard deviation of the PSD.
    psd_expansion:
        Chaos expansion of the PSD itself, coefficients (S, F).
    spectra, scale:
        Coefficient spectra (S, F) and density scale (F,), the exact surrogate PSD.
    """

    frequency: NDArray[np.float64]
    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    psd_expansion: ChaosExpansion
    spectra: NDArray[np.complex128]
    scale: NDArray[np.float64]


def chaos_spectrum(
    expansion: ChaosExpansion, grid: TensorGrid, times: ArrayLike, window: str = "hann"
) -> ChaosSpectrum:
    """Mean PSD, PSD standard deviation and the PSD's chaos expansion of one output.

    Parameters
    ----------
    expansion:
        (S, T) chaos expansion of the output over time, recovered on ``grid``.
    grid:
        The tensor grid of the study (the PSD is projected on it, like any output).
    times:
        (T,) uniform grid.
    window:
        Window name (see module docstring).

    Raises
    ------
    ValueError
        If the time grid is not uniform or the expansion is not over time.
    """
    frequency, spectra, scale = coefficient_spectra(expansion, times, window)
    mean = scale * np.sum(np.abs(spectra) ** 2, axis=0)
    index = expansion.multi_index
    at_nodes = scale * np.abs(evaluate_tensor(grid, spectra, index)) ** 2
    psd = ChaosExpansion(
        project_tensor(grid, at_nodes, index), index, expansion.distributions, expansion.names
    )
    return ChaosSpectrum(frequency, mean, psd.std(), psd, spectra, scale)
