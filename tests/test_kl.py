"""Karhunen–Loève: the periodic terrain's exact eigenpairs, spectra, and convergence."""

import numpy as np
import pytest

from pcmb.chaos.kl import KarhunenLoeve, line_covariance, spectral_covariance
from pcmb.references import cosine_covariance, cosine_covariance_kl

# The periodic terrain of Part II Eq. 12 and 16.
D, A1, A2 = 100.0, 0.2, 0.1
L1, L2 = D / (6 * np.pi), D / (14 * np.pi)


def terrain_kernel(x1, x2):
    return cosine_covariance(x1, x2, [A1**2, A2**2], [L1, L2])


def _check_terrain(kl):
    """Two distinct eigenvalues D·A²/2, each twice (cos and sin), spanned by cos/sin(x/L)."""
    assert kl.terms == 4
    x = np.linspace(0.0, D, 301)
    expected, exact = cosine_covariance_kl(x, [A1**2, A2**2], [L1, L2], D)
    np.testing.assert_allclose(kl.eigenvalues, expected, rtol=1e-10)
    assert kl.captured_energy == pytest.approx(1.0, rel=1e-10)
    g = kl.eigenfunctions(x)
    for pair in (slice(0, 2), slice(2, 4)):
        # Eigenvectors of a double eigenvalue are any orthonormal basis of its space:
        # compare the L2 projectors onto span{cos, sin}(x/L) normalised on [0, D].
        projector = exact[:, pair] @ exact[:, pair].T
        np.testing.assert_allclose(g[:, pair] @ g[:, pair].T, projector, atol=1e-9)


def test_periodic_terrain_from_its_covariance():
    _check_terrain(KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), points=120))


def test_periodic_terrain_from_its_line_spectrum():
    """Wiener–Khinchin: lines at ω = 1/L1, 1/L2 with variances A1², A2² give the same KL."""
    kernel = line_covariance([1 / L1, 1 / L2], [A1**2, A2**2])
    _check_terrain(KarhunenLoeve.from_covariance(kernel, (0.0, D), points=120))


def test_realizations_reproduce_the_covariance():
    kl = KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), points=120)
    x = np.array([0.0, 7.0, 31.0, 77.0])
    # The sample covariance over the Gauss rule of the germs equals R exactly for KL:
    # E[z(x1) z(x2)] = Σ λ_k g_k(x1) g_k(x2).
    g = kl.eigenfunctions(x)
    np.testing.assert_allclose((g * kl.eigenvalues) @ g.T, terrain_kernel(x, x), atol=1e-10)
    z = kl.realize(x, np.eye(4))
    np.testing.assert_allclose(z.T @ z, terrain_kernel(x, x), atol=1e-10)


def test_squared_exponential_eigenvalues_converge_with_refinement():
    def kernel(x1, x2):
        return np.exp(-(np.subtract.outer(x1, x2) ** 2) / (2 * 0.3**2))

    coarse = KarhunenLoeve.from_covariance(kernel, (0.0, 1.0), points=10, terms=5).eigenvalues
    medium = KarhunenLoeve.from_covariance(kernel, (0.0, 1.0), points=20, terms=5).eigenvalues
    fine = KarhunenLoeve.from_covariance(kernel, (0.0, 1.0), points=80, terms=5).eigenvalues
    # Nyström on Gauss points converges exponentially for an analytic kernel.
    assert np.max(np.abs(medium - fine)) < 0.1 * np.max(np.abs(coarse - fine))
    assert np.max(np.abs(medium - fine) / fine) < 1e-8


def test_truncation_by_energy_picks_the_fewest_terms():
    def kernel(x1, x2):
        return np.exp(-np.abs(np.subtract.outer(x1, x2)))

    kl = KarhunenLoeve.from_covariance(kernel, (0.0, 1.0), points=200, energy=0.9)
    fewer = KarhunenLoeve.from_covariance(kernel, (0.0, 1.0), points=200, terms=kl.terms - 1)
    assert kl.captured_energy >= 0.9 > fewer.captured_energy


def test_truncation_by_eigenvalue_ratio():
    kl = KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), points=120, ratio=0.5)
    # λ = D·A1²/2 (twice) and D·A2²/2 = λ_1 / 4 (twice): only the first pair passes 0.5.
    assert kl.terms == 2
    assert KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), ratio=0.2).terms == 4
    with pytest.raises(ValueError, match="ratio"):
        KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), ratio=0.0)


def test_covariance_from_a_continuous_spectrum():
    """Exponential covariance σ² e^{-|τ|/ℓ} has the one-sided PSD (2σ²ℓ/π) / (1 + (ωℓ)²)."""
    sigma2, ell = 2.0, 0.5
    omega = np.linspace(0.0, 4000.0, 400_001)
    kernel = spectral_covariance(omega, 2 * sigma2 * ell / np.pi / (1 + (omega * ell) ** 2))
    tau = np.array([0.0, 0.25, 1.0])
    # The truncated tail beyond ω_max carries ~ 2σ²/(π ℓ ω_max) ≈ 6e-4 of variance.
    np.testing.assert_allclose(
        kernel(tau, np.zeros(1))[:, 0], sigma2 * np.exp(-tau / ell), atol=1e-3
    )


def test_invalid_inputs():
    with pytest.raises(ValueError, match="a < b"):
        KarhunenLoeve.from_covariance(terrain_kernel, (1.0, 0.0))
    with pytest.raises(ValueError, match="terms must be between"):
        KarhunenLoeve.from_covariance(terrain_kernel, (0.0, D), points=60, terms=5)
    with pytest.raises(ValueError, match="not symmetric"):
        KarhunenLoeve.from_covariance(lambda a, b: np.add.outer(a, 2 * b), (0.0, 1.0))
    with pytest.raises(ValueError, match="positive semi-definite"):
        KarhunenLoeve.from_covariance(lambda a, b: -np.ones((a.size, b.size)), (0.0, 1.0))
    with pytest.raises(ValueError, match=">= 0"):
        spectral_covariance([0.0, 1.0], [1.0, -1.0])
