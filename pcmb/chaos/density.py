"""Gaussian kernel density estimates of samples (PDFs of outputs and of PSD values).

The sum of kernels is computed by linear binning and an FFT convolution (Silverman's
algorithm): O(M) in the number of samples instead of O(M G), which matters for the 10^5
surrogate draws behind every PDF pcmb stores or plots.
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


def kernel_density(
    samples: NDArray[np.float64], *, nonnegative: bool = False, bandwidth: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Gaussian kernel density of (M,) samples, tabulated on DENSITY_POINTS points.

    The bandwidth h is ``bandwidth``, by default Scott's σ M^(-1/5) (as
    :class:`scipy.stats.gaussian_kde`); pass another density's h to smooth two alike. The
    sum of kernels is computed by linear binning on at least 60 cells per bandwidth and an
    FFT convolution (Silverman's algorithm): O(M) instead of O(M G), with a binning error
    below 1e-3 of the peak density. The table spans the samples plus three bandwidths on
    each side. With ``nonnegative`` the kernel mass below zero is reflected back, as a PSD
    is never negative.

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
        bandwidth = float(np.std(samples, ddof=1)) * samples.size ** (-0.2)
    low = samples.min() - 3.0 * bandwidth
    if nonnegative:
        low = max(low, 0.0)
    value = np.linspace(low, samples.max() + 3.0 * bandwidth, DENSITY_POINTS)
    # Points mirrored at zero carry the reflected kernel mass.
    data = np.concatenate([samples, -samples]) if nonnegative else samples
    margin = 6.0 * bandwidth  # the kernel is below 1e-8 of its peak beyond 6 bandwidths
    start, stop = min(data.min(), value[0]) - margin, max(data.max(), value[-1]) + margin
    cells = int(np.clip(np.ceil(60.0 * (stop - start) / bandwidth), _BINS, _MAX_BINS))
    step = (stop - start) / cells
    position = (data - start) / step
    left = np.floor(position).astype(np.int64)
    right_share = position - left
    counts = np.bincount(left, 1.0 - right_share, cells + 2)
    counts += np.bincount(left + 1, right_share, cells + 2)
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
