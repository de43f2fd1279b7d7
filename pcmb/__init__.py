"""pcmb: simulations with error bars by generalized polynomial chaos.

Uncertain inputs (:mod:`pcmb.chaos.inputs`) are mapped to standard germs with orthonormal
polynomial families (:mod:`pcmb.chaos.polynomials`); a simulator is run at tensor Gauss nodes
(:mod:`pcmb.chaos.nodes`); the runs are turned into chaos coefficients
(:mod:`pcmb.chaos.recovery`) and statistics (:mod:`pcmb.chaos.expansion`). Importing pcmb is cheap:
heavy optional modules (h5py, mujoco, matplotlib, dask) load only where used.
"""

import importlib
from typing import Any

#: Public name -> module that defines it. Loaded on first access (PEP 562), so that
#: ``pcmb --help`` does not pay for scipy.stats, h5py or mujoco.
_EXPORTS = {
    "pcmb.integrate.stacked_ode": ["StackedODEModel", "solve_projected", "solve_stacked"],
    "pcmb.designs.polynomial_form": ["Polynomial", "PolynomialForm", "PolynomialSpace"],
    "pcmb.analysis.statistics": ["AnalysisSettings", "analyse"],
    "pcmb.chaos.basis": [
        "PolynomialBasis",
        "hyperbolic_index_set",
        "tensor_index_set",
        "total_index_set",
    ],
    "pcmb.analysis.comparison": ["compare"],
    "pcmb.config": ["StudyConfig", "config_json_schema", "load_config", "validate_config"],
    "pcmb.errors": [
        "ClusterError",
        "ConfigError",
        "IllPosedError",
        "MissingDependencyError",
        "ModelDefinitionError",
        "ModelError",
        "ModelRunError",
        "PcmbError",
        "PcmbWarning",
        "ResultFileError",
        "UsageError",
    ],
    "pcmb.chaos.density": ["kernel_density"],
    "pcmb.run.executor": ["RunResult", "run_nodes"],
    "pcmb.result": ["Design", "NodeFailure", "Status", "StudyResult", "WarningRecord"],
    "pcmb.chaos.expansion": ["ChaosExpansion"],
    "pcmb.chaos.inputs": [
        "Beta",
        "Distribution",
        "Gamma",
        "LogUniform",
        "Normal",
        "Transformed",
        "Uniform",
    ],
    "pcmb.chaos.kl": ["KarhunenLoeve", "line_covariance", "spectral_covariance"],
    "pcmb.adapters.protocol": ["Model", "ModelFactory", "PointwiseModel"],
    "pcmb.adapters.python": ["FunctionModel", "as_model", "batched", "load_entry", "pointwise"],
    "pcmb.adapters.command": ["CommandModel"],
    "pcmb.adapters.mujoco.model": ["MujocoModel", "MujocoModelFactory"],
    "pcmb.adapters.fmu.factory": ["FmuModelFactory"],
    "pcmb.adapters.fmu.model": ["FmuModel"],
    "pcmb.chaos.polynomials": [
        "GaussRule",
        "Hermite",
        "Jacobi",
        "Laguerre",
        "Legendre",
        "OrthonormalFamily",
    ],
    "pcmb.chaos.recovery": [
        "LeastSquaresFit",
        "evaluate_tensor",
        "fit_largest_stable",
        "fit_least_squares",
        "project_tensor",
    ],
    "pcmb.analysis.report": ["write_report"],
    "pcmb.chaos.nodes": ["NodeSet", "TensorGrid", "random_nodes"],
    "pcmb.store": ["load"],
    "pcmb.chaos.spectral": ["ChaosSpectrum", "chaos_spectrum", "periodogram"],
    "pcmb.study": ["Study"],
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__version__ = "0.1.0"

__all__ = [
    "AnalysisSettings",
    "Beta",
    "ChaosExpansion",
    "ChaosSpectrum",
    "ClusterError",
    "CommandModel",
    "ConfigError",
    "Design",
    "Distribution",
    "FmuModel",
    "FmuModelFactory",
    "FunctionModel",
    "Gamma",
    "GaussRule",
    "Hermite",
    "IllPosedError",
    "Jacobi",
    "KarhunenLoeve",
    "Laguerre",
    "LeastSquaresFit",
    "Legendre",
    "LogUniform",
    "MissingDependencyError",
    "Model",
    "ModelDefinitionError",
    "ModelError",
    "ModelFactory",
    "ModelRunError",
    "MujocoModel",
    "MujocoModelFactory",
    "NodeFailure",
    "NodeSet",
    "Normal",
    "OrthonormalFamily",
    "PcmbError",
    "PcmbWarning",
    "PointwiseModel",
    "Polynomial",
    "PolynomialBasis",
    "PolynomialForm",
    "PolynomialSpace",
    "ResultFileError",
    "RunResult",
    "StackedODEModel",
    "Status",
    "Study",
    "StudyConfig",
    "StudyResult",
    "TensorGrid",
    "Transformed",
    "Uniform",
    "UsageError",
    "WarningRecord",
    "analyse",
    "as_model",
    "batched",
    "chaos_spectrum",
    "compare",
    "config_json_schema",
    "evaluate_tensor",
    "fit_largest_stable",
    "fit_least_squares",
    "hyperbolic_index_set",
    "kernel_density",
    "line_covariance",
    "load",
    "load_config",
    "load_entry",
    "periodogram",
    "pointwise",
    "project_tensor",
    "random_nodes",
    "run_nodes",
    "solve_projected",
    "solve_stacked",
    "spectral_covariance",
    "tensor_index_set",
    "total_index_set",
    "validate_config",
    "write_report",
]


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'pcmb' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_MODULE_OF])
