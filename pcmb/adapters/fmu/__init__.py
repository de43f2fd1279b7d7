"""The FMU adapter (``model.kind: fmu``): Functional Mock-up Units run through FMPy.

:mod:`.spec` is its config section, :mod:`.factory` the picklable factory (neither imports
fmpy), :mod:`.model` the FMU as a model (the only pcmb module that imports fmpy).
"""
