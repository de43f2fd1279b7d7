"""The MuJoCo adapter (``model.kind: mujoco``): :mod:`.binding` is its binding language,
:mod:`.spec` its config section, :mod:`.model` the scene as a model (the only module that
imports mujoco)."""
