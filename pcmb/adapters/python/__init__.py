"""The python adapter (``model.kind: python``): classes, model objects, factories, marked functions.

Its config section is :mod:`pcmb.adapters.python.spec`; this package imports no pydantic.
"""

from pcmb.adapters.protocol import Model, ModelFactory, PointwiseModel
from pcmb.adapters.python.model import (
    MARKER,
    BatchFunctionModel,
    FunctionModel,
    ObjectModelFactory,
    PythonModelFactory,
    as_model,
    batched,
    function_kind,
    is_function_model,
    load_entry,
    model_factory,
    pointwise,
)

__all__ = [
    "MARKER",
    "BatchFunctionModel",
    "FunctionModel",
    "Model",
    "ModelFactory",
    "ObjectModelFactory",
    "PointwiseModel",
    "PythonModelFactory",
    "as_model",
    "batched",
    "function_kind",
    "is_function_model",
    "load_entry",
    "model_factory",
    "pointwise",
]
