"""What the economy audits (``test_economy_contract``, ``test_economy_audit``) share: a study
run as a user would, what ``pcmb inspect`` prints, and the true error of a result file."""

from __future__ import annotations

import html
import re
from pathlib import Path

import h5py
import numpy as np
from cli_process import pcmb_here


def run_study(folder: Path, models: str, config: str) -> Path:
    """Write ``models`` as ``fresh.py`` and ``config`` (whose output is ``out.h5``) as
    ``study.yaml`` in ``folder``, ``pcmb run`` it; the result file's path."""
    (folder / "fresh.py").write_text(models)
    (folder / "study.yaml").write_text(config)
    done = pcmb_here("run", "study.yaml", "--quiet", cwd=folder)
    assert done.returncode == 0, done.stderr
    return folder / "out.h5"


def inspect(path: Path) -> str:
    """What ``pcmb inspect`` prints of the result file at ``path``."""
    shown = pcmb_here("inspect", str(path))
    assert shown.returncode == 0, shown.stderr
    return shown.stdout


def lines(shown: str, start: str) -> list[str]:
    """The lines of ``shown`` that begin with ``start``."""
    return [line for line in shown.splitlines() if line.startswith(start)]


def runs_line_agrees_with_the_file(path: Path) -> None:
    """``pcmb inspect``'s runs line is what the file holds: design, held-out, nominal."""
    with h5py.File(path) as file:
        nodes, held = file["nodes/params"].shape[0], file["validation/params"].shape[0]
        nominal = sum("nominal" in file[f"outputs/{name}"] for name in file["outputs"])
    total = nodes + held + bool(nominal)
    expected = f"{total} in all: {nodes} of the design, {held} held-out ({held} ok), 1 nominal"
    assert lines(inspect(path), "runs") == [f"runs     {expected}"]


def true_error(path: Path, output: str, response, weights: np.ndarray):
    """(times, true error over the scale, the diagnostics group's arrays and attributes):
    the truth's mean and std are the ``weights`` quadrature of ``response(times)`` (runs x
    times)."""
    with h5py.File(path) as file:
        times = file["time"][:]
        found = file[f"diagnostics/{output}"]
        verdict = {key: found[key][:] for key in found}
        verdict.update(found.attrs)
        values = response(times)
        mean = weights @ values
        std = np.sqrt(np.maximum(weights @ values**2 - mean**2, 0.0))
        verdict["true_mean"], verdict["true_std"] = mean, std
        error = np.fmax(
            abs(file[f"outputs/{output}/mean"][:] - mean),
            abs(file[f"outputs/{output}/std"][:] - std),
        )
    return times, error / verdict["scale"], verdict


def report_text(path: Path) -> str:
    """``pcmb report``'s index page of the result file at ``path`` as text (tags, styles and
    images dropped)."""
    done = pcmb_here("report", str(path), "-o", str(path.parent / "report"))
    assert done.returncode == 0, done.stderr
    page = (path.parent / "report" / "index.html").read_text()
    page = re.sub(r"<(style|script)\b.*?</\1>", " ", page, flags=re.S)
    return html.unescape(re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", page)))


def silent_times(times: np.ndarray, error: np.ndarray, verdict: dict, tolerance: float = 0.05):
    """The times whose true ``error`` passes ``tolerance`` that the verdict neither flags nor
    calls undecided: where it calls the output reliable while it is not."""
    judged = verdict["undecided"].astype(bool) | (times >= verdict["failing_from"])
    return times[(error > tolerance) & ~judged]
