"""Gaussian kernel density estimates of samples (PDFs of outputs and of PSD values).

The sum of kernels is computed by linear binning and an FFT convolution (Silverman's
algorithm): O(M) in the number of samples instead of O(M G), which matters for the 10^5
surrogate draws behind every PDF pcmb stores or plots. The bandwidth is the Improved
Sheather-Jones one (Botev, Grotowski and Kroese 2010, Ann. Stat. 38(5)), and the kernel mass
beyond an end of the samples where they pile up is reflected back (docs/architecture.md,
"The PDFs").
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["DENSITY_POINTS", "kernel_density"]

#: Points at which every PDF is tabulated.
DENSITY_POINTS = 256
#: Fewest cells of the binned kernel density estimate.
_BINS = 4096
#: Most cells (8 MB): reached only by far outliers, where the binning error grows.
_MAX_BINS = 1 << 20
#: A spread below this fraction of the magnitude is round-off: the law is a point mass.
_RELATIVE_SPREAD = 1e-12
#: Cells of the histogram whose cosine transform the ISJ bandwidth is solved on.
_ISJ_CELLS = 1 << 12
#: The histogram reaches this fraction of the samples' range past each end (Botev's margin).
_ISJ_PAD = 0.1
#: Order of the highest density derivative the ISJ fixed point starts from (Botev's 7).
_ISJ_ORDER = 7
#: An end of the samples is a hard bound when at least this many lie within a bandwidth of
#: it, and at least half as many as in the next bandwidth (a tail thins out towards its end).
_PILED = 30


def kernel_density(
    samples: NDArray[np.float64], *, nonnegative: bool = False, bandwidth: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Gaussian kernel density of (M,) samples, tabulated on DENSITY_POINTS points.

    The bandwidth h is ``bandwidth``, by default :func:`_default_bandwidth`; pass another
    density's h to smooth two alike. The sum of kernels is computed by linear binning on at
    least 60 cells per bandwidth and an FFT convolution (Silverman's algorithm): O(M) instead
    of O(M G), with a binning error below 1e-3 of the peak density. The table spans the
    samples plus three bandwidths on each side, except beyond an end where the samples pile
    up (at least ``_PILED`` within h of it, and half as many as in the next h: a hard bound
    such as a uniform's or a saturated response's): there the kernel mass is reflected back
    and the table stops at that end. With ``nonnegative`` the kernel mass below zero is
    reflected back too, as a PSD is never negative.

    Returns
    -------
    value, density, bandwidth
        (G,) points and densities, and h; the densities (and h) are NaN when the samples do
        not vary (a point mass at ``value[0]``).
    """
    samples = np.asarray(samples, dtype=float)
    samples = samples[np.isfinite(samples)]
    if samples.size < 2 or not np.ptp(samples) > _RELATIVE_SPREAD * np.max(np.abs(samples)):
        value = np.full(DENSITY_POINTS, samples[0] if samples.size else np.nan)
        return value, np.full(DENSITY_POINTS, np.nan), float("nan")
    if bandwidth is None:
        bandwidth = _default_bandwidth(samples)
    lowest, highest = samples.min(), samples.max()
    low = lowest if _piled(samples - lowest, bandwidth) else lowest - 3.0 * bandwidth
    high = highest if _piled(highest - samples, bandwidth) else highest + 3.0 * bandwidth
    if nonnegative:
        low = max(low, 0.0)
    value = np.linspace(low, high, DENSITY_POINTS)
    margin = 6.0 * bandwidth  # the kernel is below 1e-8 of its peak beyond 6 bandwidths
    # Points mirrored at a bound carry the kernel mass reflected back from beyond it.
    data = [samples]
    if low > lowest - margin:
        data.append(2.0 * low - samples[samples < low + margin])
    if high < highest + margin:
        data.append(2.0 * high - samples[samples > high - margin])
    data = np.concatenate(data)
    start, stop = min(data.min(), value[0]) - margin, max(data.max(), value[-1]) + margin
    cells = int(np.clip(np.ceil(60.0 * (stop - start) / bandwidth), _BINS, _MAX_BINS))
    step = (stop - start) / cells
    counts = _linear_binning((data - start) / step, cells + 2)
    half = int(np.ceil(margin / step))
    offsets = np.arange(-half, half + 1) * step
    kernel = np.exp(-0.5 * (offsets / bandwidth) ** 2) / (bandwidth * np.sqrt(2.0 * np.pi))
    # Linear convolution by a zero-padded FFT ("same" size; the kernel has odd length).
    size = counts.size + kernel.size - 1
    full = np.fft.irfft(np.fft.rfft(counts, size) * np.fft.rfft(kernel, size), size)
    smooth = full[half : half + counts.size] / samples.size
    density = np.interp(value, start + step * np.arange(cells + 2), smooth)
    # FFT round-off can dip below zero in the tails.
    return value, np.maximum(density, 0.0), bandwidth


def _linear_binning(position: NDArray[np.float64], cells: int) -> NDArray[np.float64]:
    """(cells,) weights of points at fractional cell ``position``, each shared between the two
    cells it falls between in proportion to its distance to them."""
    left = np.floor(position).astype(np.int64)
    right_share = position - left
    counts = np.bincount(left, 1.0 - right_share, cells)
    return counts + np.bincount(left + 1, right_share, cells)


def _piled(distance: NDArray[np.float64], bandwidth: float) -> bool:
    """Whether samples at ``distance`` >= 0 from an end of theirs pile up against it."""
    near = np.count_nonzero(distance <= bandwidth)
    return near >= _PILED and 2 * near >= np.count_nonzero(distance <= 2.0 * bandwidth) - near


def _default_bandwidth(samples: NDArray[np.float64]) -> float:
    """The Improved Sheather-Jones bandwidth of (M,) samples, but at least their range over
    DENSITY_POINTS - 7, the table's step (finer, the table would sample noise); Scott's
    σ M^(-1/5) where the ISJ fixed point has no root. Computed on the samples scaled to
    [0, 1], so that values whose squares overflow (1e200) do not."""
    lowest, span = samples.min(), np.ptp(samples)
    unit = (samples - lowest) / span
    width = 1.0 + 2.0 * _ISJ_PAD
    counts = _linear_binning((unit + _ISJ_PAD) / width * (_ISJ_CELLS - 1), _ISJ_CELLS)
    shortest = 1.0 / (DENSITY_POINTS - 7)
    cosines = _cosine_transform(counts / samples.size)
    time = _isj_time(cosines, samples.size, (shortest / width) ** 2)
    scott = np.std(unit, ddof=1) * unit.size**-0.2
    return float(max(width * np.sqrt(time) if np.isfinite(time) else scott, shortest) * span)


def _cosine_transform(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """The unnormalized type-II cosine transform, 2 Σ_n x_n cos(π k (2n + 1) / 2N), by one
    FFT of the even samples followed by the odd ones reversed (Makhoul 1980): scipy.fft's
    ``dct`` gives the same to round-off, but its import (0.2 s) doubled a study's first PDF."""
    size = values.size
    shuffled = np.concatenate((values[::2], values[1::2][::-1]))
    twiddle = np.exp(-0.5j * np.pi * np.arange(size) / size)
    return 2.0 * (twiddle * np.fft.fft(shuffled)).real


def _isj_time(cosines: NDArray[np.float64], size: int, shortest: float) -> float:
    """The squared ISJ bandwidth, over the histogram's span squared, of ``size`` samples whose
    normalized histogram has the type-II cosine transform ``cosines``: the root of Botev's
    fixed point t = ξ γ^[l](t) in (``shortest``, 0.1); ``shortest`` where the root lies below
    it, NaN where there is none below 0.1."""
    wave = np.arange(1, cosines.size, dtype=float) ** 2
    power = (cosines[1:] / 2.0) ** 2
    # 2 π^(2s) Σ k^(2s) a_k² e^(-k² π² t): the integral of the squared s-th derivative.
    weights = {s: 2.0 * np.pi ** (2 * s) * wave**s * power for s in range(2, _ISJ_ORDER + 1)}

    def functional(s: int, t: float) -> float:
        """The sum over the waves whose factor e^(-k² π² t) is above 1e-20 (k² < 4.67 / t)."""
        count = int(min(wave.size, np.sqrt(4.67 / t) + 1.0))
        return float(weights[s][:count] @ np.exp(-(np.pi**2) * t * wave[:count]))

    def constant(s: int) -> float:
        """2 (1 + 2^(-s-1/2)) / 3 (2s - 1)!! / √(2π), Botev's Eq. (29)."""
        odd_product = np.prod(np.arange(1.0, 2 * s, 2))
        return 2.0 * (1.0 + 0.5 ** (s + 0.5)) / 3.0 * odd_product / np.sqrt(2.0 * np.pi)

    @np.errstate(divide="ignore", over="ignore")
    def gap(t: float) -> float:
        f = functional(_ISJ_ORDER, t)
        for s in range(_ISJ_ORDER - 1, 1, -1):
            f = functional(s, (constant(s) / (size * f)) ** (2.0 / (3 + 2 * s)))
        return t - (2.0 * size * np.sqrt(np.pi) * f) ** -0.4

    if not gap(0.1) > 0.0:
        return float("nan")
    if gap(shortest) >= 0.0:
        return shortest
    # Bisection in log t to a relative 1e-6 (scipy.optimize's import, 0.2 s, would double
    # the cost of a study's first PDF).
    low, high = np.log(shortest), np.log(0.1)
    while high - low > 1e-6:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if gap(float(np.exp(middle))) >= 0.0 else (middle, high)
    return float(np.exp(0.5 * (low + high)))
