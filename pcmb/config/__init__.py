"""Study configuration: :mod:`.loader` (YAML), :mod:`.schema` (pydantic), :mod:`.messages`
(located problems), :mod:`.checks` (checks against the model), :mod:`.types` (shared values).

The public names load on first use, so that adapters can import :mod:`.types` cheaply.
"""

import importlib
from typing import Any

__all__ = ["StudyConfig", "config_json_schema", "load_config", "validate_config"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module("pcmb.config.schema"), name)
    raise AttributeError(f"module 'pcmb.config' has no attribute {name!r}")
