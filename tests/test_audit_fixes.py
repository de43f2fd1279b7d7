"""Fixes of the second contract audit's findings (issue 23): one message where a degenerate
design's runs are all equal while the held-out runs vary."""

from __future__ import annotations

import warnings

import numpy as np

import pcmb

SQUARE = {name: pcmb.Uniform(-1.0, 1.0) for name in ("x1", "x2")}
TIMES = np.linspace(0.0, 3.0, 31)


@pcmb.batched(outputs=("y",))
def vee(params, times):
    """(|x1| + |x2|) sin t: tensor order 1 puts both Gauss points of each input at ±1/√3, so
    every run of the design is the same while the response varies from t > 0."""
    both = np.abs(np.asarray(params["x1"])) + np.abs(np.asarray(params["x2"]))
    return {"y": both[:, None] * np.sin(times)}


def test_a_degenerate_design_does_not_say_the_output_does_not_vary_where_it_does():
    study = pcmb.Study(vee, SQUARE, TIMES, order=1, backend="inprocess")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pcmb.PcmbWarning)
        result = study.run()
    assert result.diagnostics["y"].failing_from == TIMES[1]  # the held-out runs vary there
    messages = [w.message for w in result.warnings if w.output == "y"]
    assert any("runs are all equal" in message for message in messages), messages
    assert not [message for message in messages if "the output does not vary" in message]
