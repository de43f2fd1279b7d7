"""The chaos core: germs and polynomial families, index sets, node sets, recovery, expansions.

Pure numpy/scipy: nothing here imports h5py, joblib, mujoco, pydantic, matplotlib or
:mod:`pcmb.run`.
"""
