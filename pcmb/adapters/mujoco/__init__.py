"""The MuJoCo adapter (``model.kind: mujoco``): :mod:`.spec` is its binding language and config
section, :mod:`.model` the scene as a model (the only module that imports mujoco)."""
