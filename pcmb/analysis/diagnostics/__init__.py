"""When polynomial chaos fails: per-time error indicators and a verdict per output.

Every indicator is an array over time measured in units of the output's *largest* standard
deviation over time (the scale): an error that is small against the output's typical spread
is accepted even where the spread itself is small (near a fixed initial state, or where a
damped output settles), which is where a per-time normalisation raises false alarms.

One concept per module: the spectral decay (:mod:`.decay`), the held-out runs
(:mod:`.draws`), the check against drawn runs (:mod:`.check`), against placed ones
(:mod:`.placed`) and against runs placed along one input of several (:mod:`.line`), the
range checks (:mod:`.ranges`), the verdict rule (:mod:`.verdict`), the remedy named to the
user (:mod:`.remedies`), and the diagnosis of an output that joins them (:mod:`.diagnose`),
in the words of :mod:`.phrases`; see ``docs/diagnostics.md``.
"""

from pcmb.analysis.diagnostics.check import (
    CONFIDENCE,
    HeldOutCheck,
    chi_square_quantile,
    holdout_error,
    statistics_error,
)
from pcmb.analysis.diagnostics.decay import spectral_decay
from pcmb.analysis.diagnostics.diagnose import (
    CODES,
    OutputDiagnostics,
    diagnose,
    diagnose_all,
    more_runs,
)
from pcmb.analysis.diagnostics.draws import (
    ELEMENT_POINTS,
    FIRST_BATCH,
    HELD_OUT_SEED,
    TAIL_BOUND,
    HeldOut,
    element_importance,
    held_out_budget,
    held_out_draws,
    held_out_placed,
    held_out_placed_elements,
    held_out_unit,
    linear_in_widened,
    widened_inputs,
)
from pcmb.analysis.diagnostics.line import held_out_line, line_check, tail_input
from pcmb.analysis.diagnostics.placed import placed_check
from pcmb.analysis.diagnostics.ranges import (
    RANGE_DRAWS,
    out_of_range,
    pdf_outside_runs,
    range_checks,
)
from pcmb.analysis.diagnostics.verdict import TOLERANCE, verdict

__all__ = [
    "CODES",
    "CONFIDENCE",
    "ELEMENT_POINTS",
    "FIRST_BATCH",
    "HELD_OUT_SEED",
    "RANGE_DRAWS",
    "TAIL_BOUND",
    "TOLERANCE",
    "HeldOut",
    "HeldOutCheck",
    "OutputDiagnostics",
    "chi_square_quantile",
    "diagnose",
    "diagnose_all",
    "element_importance",
    "held_out_budget",
    "held_out_draws",
    "held_out_line",
    "held_out_placed",
    "held_out_placed_elements",
    "held_out_unit",
    "holdout_error",
    "line_check",
    "linear_in_widened",
    "more_runs",
    "out_of_range",
    "pdf_outside_runs",
    "placed_check",
    "range_checks",
    "spectral_decay",
    "statistics_error",
    "tail_input",
    "verdict",
    "widened_inputs",
]
