"""Frequency-domain statistics against per-node spectra and Parseval."""

import numpy as np
import pytest
from scipy.signal import periodogram as scipy_periodogram

from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.chaos.spectral import WINDOWS, chaos_spectrum, periodogram
from pcmb.references import damped_oscillator

TIMES = np.linspace(0.0, 20.0, 400, endpoint=False)


def oscillator(stiffness):
    """Free damped linear oscillator x'' + 0.2 x' + k x = 0, x(0) = 1, x'(0) = 0 (closed form)."""
    return damped_oscillator(TIMES, stiffness, 0.2)


@pytest.fixture(scope="module", params=["hann", "boxcar"])
def study(request):
    dists = [Uniform(1.0, 4.0)]
    grid = TensorGrid(dists, [8])
    values = oscillator(grid.params[:, 0])
    expansion = ChaosExpansion(project_tensor(grid, values), grid.multi_index, dists)
    return grid, values, chaos_spectrum(expansion, grid, TIMES, request.param), request.param


def test_periodogram_matches_scipy():
    x = oscillator([2.0, 3.0])
    for window in WINDOWS:
        fs = 1 / (TIMES[1] - TIMES[0])
        f_ref, p_ref = scipy_periodogram(x, fs=fs, window=window, detrend=False)
        f, p = periodogram(x, TIMES, window)
        np.testing.assert_allclose(f, f_ref)
        np.testing.assert_allclose(p, p_ref, rtol=1e-12, atol=1e-14 * p_ref.max())


def test_mean_and_band_match_quadrature_of_per_node_spectra(study):
    grid, values, spectrum, window = study
    _, per_node = periodogram(values, TIMES, window)
    mean = grid.weights @ per_node
    std = np.sqrt(grid.weights @ (per_node - mean) ** 2)
    scale = per_node.max()
    np.testing.assert_allclose(spectrum.mean, mean, atol=1e-10 * scale)
    np.testing.assert_allclose(spectrum.std, std, atol=1e-10 * scale)
    np.testing.assert_allclose(spectrum.psd_expansion.mean(), mean, atol=1e-10 * scale)


def test_parseval_holds_for_the_mean_psd():
    """With the rectangular window, ∫ mean PSD df = E[mean square of y over the record]."""
    dists = [Uniform(1.0, 4.0)]
    grid = TensorGrid(dists, [8])
    values = oscillator(grid.params[:, 0])
    expansion = ChaosExpansion(project_tensor(grid, values), grid.multi_index, dists)
    spectrum = chaos_spectrum(expansion, grid, TIMES, "boxcar")
    df = spectrum.frequency[1] - spectrum.frequency[0]
    mean_square = grid.weights @ np.mean(values**2, axis=1)
    assert np.sum(spectrum.mean) * df == pytest.approx(mean_square, rel=1e-12)


def test_non_uniform_grids_and_unknown_windows_are_rejected():
    with pytest.raises(ValueError, match="uniform"):
        periodogram(np.zeros(3), [0.0, 1.0, 3.0])
    with pytest.raises(ValueError, match="found 'kaiser'"):
        periodogram(np.zeros(3), [0.0, 1.0, 2.0], "kaiser")
