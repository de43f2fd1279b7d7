"""The MuJoCo adapter (the only package that imports mujoco)."""
