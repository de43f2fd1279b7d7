"""What pcmb needs from a simulator: the model protocol, the per-point base, model factories.

Every adapter (:mod:`pcmb.adapters.registry`) turns a simulator into a :class:`Model` and
builds it through a :class:`ModelFactory`, which the executor ships to each worker.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pcmb.errors import ModelDefinitionError, ModelError, complex_output

__all__ = [
    "Model",
    "ModelDefinitionError",
    "ModelFactory",
    "PointwiseModel",
    "check_batch",
    "check_point_result",
    "describe_exception",
    "float_array",
]


@runtime_checkable
class Model(Protocol):
    """What pcmb needs from a simulator.

    Attributes
    ----------
    outputs:
        Names of the observables :meth:`simulate` returns.

    Notes
    -----
    Optional attributes:

    - ``parameters: Mapping[str, float]``, the nominal value of every named parameter; the
      config validator then checks uncertain inputs against it;
    - ``nominal_from_params: bool``, true when ``parameters`` are exactly the nominal values
      the adapter was given (``model.params``): an uncertain input then needs one there;
    - ``check_times(times)`` raising :class:`~pcmb.errors.ConfigError` when the model cannot
      produce the grid; the config validator calls it before anything runs;
    - ``check_inputs(names)`` raising :class:`~pcmb.errors.ConfigError` (at ``inputs.<name>``)
      when the model cannot vary these uncertain inputs independently (an FMU's aliased
      variables); the config validator calls it before anything runs;
    - ``chunk_size: int``, the nodes per call the model prefers (a stacked integrator pays
      per call); ``execution.chunk_size`` overrides it;
    - ``output_axes: Mapping[str, OutputAxis | None]``, the outputs that are not time
      series: an :class:`~pcmb.axes.OutputAxis` (name, unit, (K,) values: a frequency
      sweep) for an output returned as (B, K) on that axis, ``None`` for a scalar per run
      returned as (B,). Outputs not listed are (B, T) on ``times``. Every statistic,
      Sobol' index, PDF and diagnostic of an output is then per point of its axis, and the
      result file stores it on its own dimension (``docs/models.md``).
    """

    outputs: tuple[str, ...]

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> Mapping[str, NDArray[np.float64]]:
        """Run one batch.

        Parameters
        ----------
        params:
            Uncertain inputs only, each (B,) or (B, m); every other parameter keeps the
            nominal value given at construction.
        times:
            Output grid, (T,).

        Returns
        -------
        Mapping[str, NDArray]
            Every name in ``outputs`` -> (B, T); (B, K) or (B,) for the outputs in
            ``output_axes``.
        """
        ...


class ModelFactory(ABC):
    """A picklable callable that builds a model; each worker calls it once.

    Every factory pcmb builds subclasses this, so ``isinstance(x, ModelFactory)`` tells a
    factory from a model, a class or a function. Problems found while building raise
    :class:`~pcmb.errors.ConfigError` located at the config key they come from.
    """

    @abstractmethod
    def __call__(self) -> Model:
        """Build the model."""

    def model_files(self) -> list[Path]:
        """The files the model reads that are known before it is built (its entry file, its
        program, its scene, its archive, the files its config lists), absolute; a resume
        journal holds their digests. Default: none."""
        return []

    def loaded_files(self) -> list[Path]:
        """The files the model loaded while it was built (its own modules), absolute; called
        in the worker process right after building it. Default: none."""
        return []


def describe_exception(exc: BaseException) -> str:
    """``Type: message`` (or the type alone) of an exception, for messages."""
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def float_array(value: Any, what: str) -> NDArray[np.float64]:
    """``value`` as a float array.

    Raises
    ------
    ModelError
        Naming ``what`` (``"output 'y' in out.npy"``): it is not numeric, or it is complex
        with an imaginary part (a float array would keep only its real part).
    """
    try:
        array = np.asarray(value)
        if np.iscomplexobj(array):
            imaginary = np.abs(array.imag)
            if imaginary.any():
                raise complex_output(what, float(np.max(imaginary)))
            array = array.real
        return np.asarray(array, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{what} is not numeric: {describe_exception(exc)}") from exc


def check_point_result(
    result: object, outputs: Sequence[str], n_times: int, where: str
) -> dict[str, NDArray[np.float64]]:
    """One node's outputs checked: a mapping with every output as a (T,) float array.

    Raises
    ------
    ModelError
        What is wrong, naming ``where`` the result comes from.
    """
    if not isinstance(result, Mapping):
        raise ModelError(f"{where} is a {type(result).__name__}, expected a dict of outputs")
    missing = [name for name in outputs if name not in result]
    if missing:
        found = ", ".join(map(str, result)) or "none"
        raise ModelError(
            f"output(s) {', '.join(map(repr, missing))} missing from {where} (found: {found})"
        )
    checked = {}
    for name in outputs:
        values = float_array(result[name], f"output {name!r} in {where}")
        if values.shape != (n_times,):
            raise ModelError(
                f"output {name!r} in {where} has shape {values.shape}, expected ({n_times},)"
            )
        checked[name] = values
    return checked


def check_batch(
    params: Mapping[str, Any], times: Any, parameters: Mapping[str, Any]
) -> tuple[dict[str, NDArray[Any]], NDArray[np.float64], int]:
    """The batch's inputs as arrays, the grid as floats, and the batch size B.

    Raises
    ------
    ValueError
        Unknown parameter names, inputs not all (B,) or (B, m) with one B, or ``times`` not 1-D.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1:
        raise ValueError(f"times must be 1-D, got shape {times.shape}")
    unknown = sorted(set(params) - set(parameters))
    if unknown:
        raise ValueError(
            f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(parameters) or 'none'}"
        )
    arrays = {name: np.asarray(value) for name, value in params.items()}
    sizes = {len(a) if a.ndim in (1, 2) else -1 for a in arrays.values()}
    if len(sizes) > 1 or -1 in sizes:
        shapes = {name: a.shape for name, a in arrays.items()}
        raise ValueError(f"params must all be (B,) or (B, m) with one B, got {shapes}")
    return arrays, times, sizes.pop() if sizes else 1


def _point_shape(axes: Mapping[str, Any], name: str, n_times: int) -> tuple[int, ...]:
    """One node's shape of output ``name``: (T,), (K,) on its own axis, () a scalar."""
    if name not in axes:
        return (n_times,)
    return () if axes[name] is None else axes[name].values.shape


class PointwiseModel(ABC):
    """A model that runs one node at a time; :meth:`simulate` loops over the batch.

    Subclasses set ``outputs`` and ``parameters`` and implement :meth:`run_point`. In a batch
    of several nodes a failed node becomes a row of NaN (the executor treats non-finite rows
    as failed nodes and keeps the others); a batch of one node raises
    :class:`~pcmb.errors.ModelError` with the reason.
    """

    outputs: tuple[str, ...]
    parameters: Mapping[str, Any]
    #: ``parameters`` are the nominal values given to the adapter (see :class:`Model`).
    nominal_from_params: ClassVar[bool] = False

    @abstractmethod
    def run_point(
        self, values: Mapping[str, Any], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run one node.

        Parameters
        ----------
        values:
            The node's uncertain inputs (floats, or (m,) arrays for field inputs).
        times:
            Output grid, (T,).

        Returns
        -------
        dict[str, NDArray]
            Every name in ``outputs`` -> (T,).

        Raises
        ------
        ModelError
            The run failed; the message says how.
        ModelDefinitionError
            The model cannot work at any node; the whole batch stops.
        """

    def simulate(
        self, params: Mapping[str, NDArray[np.float64]], times: NDArray[np.float64]
    ) -> dict[str, NDArray[np.float64]]:
        """Run a batch node by node.

        Parameters
        ----------
        params:
            Uncertain inputs, each (B,) or (B, m); names must be in ``parameters``.
        times:
            Output grid, (T,).

        Returns
        -------
        dict[str, NDArray]
            Every output -> (B, T); rows of failed nodes are NaN when B > 1.

        Raises
        ------
        ValueError
            Unknown parameter names, inconsistent batch sizes, or ``times`` not 1-D.
        ModelError
            The single node of a batch of one failed.
        ModelDefinitionError
            A node showed that the model cannot work at any node.
        """
        arrays, times, batch = check_batch(params, times, self.parameters)
        axes = getattr(self, "output_axes", None) or {}
        out = {
            name: np.full((batch, *_point_shape(axes, name, times.size)), np.nan)
            for name in self.outputs
        }
        for i in range(batch):
            values = {name: a[i] if a.ndim == 2 else float(a[i]) for name, a in arrays.items()}
            try:
                result = self.run_point(values, times)
            except ModelDefinitionError:
                raise
            except ModelError:
                if batch == 1:
                    raise
                continue
            for name in self.outputs:
                out[name][i] = result[name]
        return out
