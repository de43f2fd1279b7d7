"""Every registered adapter kind honours the adapter contract (pcmb.adapters.registry).

Each kind brings a small example, ``tests/data/adapters/<kind>.yaml``: its ``model:``
section, two nodes of its inputs and a time grid (``${PYTHON}`` stands for this interpreter,
``${FMU_DIR}`` for the folder of FMUs built at test time).
"""

from __future__ import annotations

import pickle
import sys
import typing
from pathlib import Path

import numpy as np
import pytest

from pcmb.adapters.protocol import Model, ModelFactory
from pcmb.adapters.registry import ADAPTERS, adapter_kinds, spec_class
from pcmb.config import validate_config
from pcmb.config.loader import parse_yaml
from pcmb.config.types import ModelSection

EXAMPLES = Path(__file__).parent / "data" / "adapters"
SUBSTITUTIONS = {"${PYTHON}": sys.executable}


def example(kind: str) -> dict:
    path = EXAMPLES / f"{kind}.yaml"
    text = path.read_text(encoding="utf-8")
    for placeholder, value in SUBSTITUTIONS.items():
        text = text.replace(placeholder, value)
    data, _, problems = parse_yaml(text, str(path))
    assert not problems
    return data


def test_every_registered_kind_has_an_example():
    assert {p.stem for p in EXAMPLES.glob("*.yaml")} == set(ADAPTERS)
    assert adapter_kinds() == tuple(ADAPTERS)


@pytest.fixture(params=sorted(ADAPTERS))
def kind(request):
    if request.param == "fmu":
        SUBSTITUTIONS["${FMU_DIR}"] = str(request.getfixturevalue("fmu_dir"))
    return request.param


def test_the_section_class_is_a_model_section_tagged_by_its_kind(kind):
    section = spec_class(kind)
    assert issubclass(section, ModelSection)
    assert typing.get_args(section.model_fields["kind"].annotation) == (kind,)
    assert "params" in section.model_fields
    assert ADAPTERS[kind].summary


def test_the_example_builds_a_picklable_factory_of_a_working_model(kind):
    data = example(kind)
    section = spec_class(kind).model_validate(data["model"])
    factory = section.factory(EXAMPLES)
    assert isinstance(factory, ModelFactory)
    clone = pickle.loads(pickle.dumps(factory))
    assert clone == factory
    model = clone()
    assert isinstance(model, Model)
    times = np.linspace(data["times"]["start"], data["times"]["stop"], data["times"]["points"])
    nodes = {name: np.array(values, dtype=float) for name, values in data["nodes"].items()}
    out = model.simulate(nodes, times)
    for name in section.output_names or model.outputs:
        assert out[name].shape == (2, times.size), name
        assert np.isfinite(out[name]).all(), name
    assert not np.array_equal(*next(iter(out.values())))  # the two nodes differ


def test_the_example_is_a_valid_model_section_of_a_config(kind):
    data = example(kind)
    inputs = {
        name: {"dist": "uniform", "low": min(values), "high": max(values)}
        for name, values in data["nodes"].items()
    }
    config = validate_config(
        {
            "name": f"{kind} example",
            "model": data["model"],
            "time": data["times"],
            "inputs": inputs,
            "method": {"kind": "collocation", "order": 1},
        },
        base_dir=EXAMPLES,
    )
    assert config.model.kind == kind
    assert isinstance(config.model_factory(), ModelFactory)
