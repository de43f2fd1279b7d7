"""``pcmb sweep``: one case run by many methods at rising cost, measured against a reference.

:mod:`.plan` expands the ``sweep:`` section into settings, :mod:`.runner` runs them as
ordinary studies, :mod:`.table` holds the errors and costs (``sweep.csv``, ``sweep.h5``) and
:mod:`.chart` draws error against runs and seconds (``sweep.png``).
"""
