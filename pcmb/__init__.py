"""pcmb: simulations with error bars by generalized polynomial chaos.

Uncertain inputs (:mod:`pcmb.inputs`) are mapped to standard germs with orthonormal
polynomial families (:mod:`pcmb.polynomials`); a simulator is run at tensor Gauss nodes
(:mod:`pcmb.sampling`); the runs are turned into chaos coefficients
(:mod:`pcmb.recovery`) and statistics (:mod:`pcmb.expansion`). Importing pcmb is cheap:
heavy optional modules (h5py, mujoco, matplotlib, dask) load only where used.
"""

from pcmb.basis import PolynomialBasis, hyperbolic_index_set, tensor_index_set, total_index_set
from pcmb.errors import ConfigError, IllPosedError, ModelError, ModelRunError, PcmbError
from pcmb.expansion import ChaosExpansion
from pcmb.inputs import Beta, Distribution, Gamma, Normal, Transformed, Uniform
from pcmb.kl import KarhunenLoeve, line_covariance, spectral_covariance
from pcmb.polynomials import GaussRule, Hermite, Jacobi, Laguerre, Legendre, OrthonormalFamily
from pcmb.recovery import LeastSquaresFit, fit_largest_stable, fit_least_squares, project_tensor
from pcmb.sampling import NodeSet, TensorGrid, random_nodes

__version__ = "0.1.0"

__all__ = [
    "Beta",
    "ChaosExpansion",
    "ConfigError",
    "Distribution",
    "Gamma",
    "GaussRule",
    "Hermite",
    "IllPosedError",
    "Jacobi",
    "KarhunenLoeve",
    "Laguerre",
    "LeastSquaresFit",
    "Legendre",
    "ModelError",
    "ModelRunError",
    "NodeSet",
    "Normal",
    "OrthonormalFamily",
    "PcmbError",
    "PolynomialBasis",
    "TensorGrid",
    "Transformed",
    "Uniform",
    "__version__",
    "fit_largest_stable",
    "fit_least_squares",
    "hyperbolic_index_set",
    "line_covariance",
    "project_tensor",
    "random_nodes",
    "spectral_covariance",
    "tensor_index_set",
    "total_index_set",
]
