"""``pcmb report``: every expected figure, of the right size, not blank; the index page."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import pcmb
from pcmb.cli import main

pytest.importorskip("matplotlib")
from matplotlib.image import imread

from pcmb.analysis.report import figure_pixels, write_report

MODEL = '''
import numpy as np


class Decay:
    """x = x0 exp(-k t) cos(2 pi t), v = its derivative: closed form, batched."""

    outputs = ("x", "v")

    def __init__(self, k=0.5, x0=1.0):
        self.parameters = {"k": k, "x0": x0}

    def simulate(self, params, times):
        k = np.asarray(params.get("k", self.parameters["k"]), float)[:, None]
        x0 = np.asarray(params.get("x0", self.parameters["x0"]), float)[:, None]
        w = 2 * np.pi
        x = x0 * np.exp(-k * times) * np.cos(w * times)
        v = -x0 * np.exp(-k * times) * (k * np.cos(w * times) + w * np.sin(w * times))
        return {"x": x, "v": v}
'''


def _config(folder, method, analysis=True, outputs="[x, v]"):
    (folder / "decay.py").write_text(MODEL)
    path = folder / f"decay_{method}.yaml"
    units = "{x: m, v: m/s}" if "v" in outputs else "{x: m}"
    section = (
        f"analysis: {{psd: {outputs}, pdf_times: [0.5, 2.0], pdf_freqs: [1.0], samples: 20000,"
        f" units: {units}, time_unit: s}}"
        if analysis
        else ""
    )
    kind = (
        "{kind: collocation, order: 3}"
        if method == "collocation"
        else f"{{kind: {method}, samples: 400, seed: 1}}"
    )
    path.write_text(
        textwrap.dedent(
            f"""\
            name: decay-{method}
            model:
              kind: python
              entry: decay.py:Decay
              params: {{k: 0.5, x0: 1.0}}
              outputs: {outputs}
            time: {{start: 0.0, stop: 2.0, points: 81}}
            inputs:
              k: {{dist: uniform, low: 0.3, high: 0.7}}
              x0: {{dist: normal, mean: 1.0, std: 0.1}}
            method: {kind}
            execution: {{jobs: 1}}
            """
        )
        + section
        + "\n"
    )
    return path


def _run(folder, method, **options):
    path = folder / f"{method}_{len(options)}.h5"
    config = _config(folder, method, **options)
    assert main(["run", str(config), "-o", str(path), "--quiet"]) == 0
    return path


def _check_png(path, panels):
    image = imread(path)
    width, height = figure_pixels(panels)
    assert image.shape[:2] == (height, width), path.name
    # Not a blank canvas: many distinct colours, and a sizeable share of non-white pixels.
    rgb = image[..., :3].reshape(-1, 3)
    assert np.unique(np.round(rgb * 255), axis=0).shape[0] > 50, path.name
    assert np.mean(np.any(rgb < 0.9, axis=1)) > 0.02, path.name


@pytest.mark.slow  # 12 figures, about 15 s on 2 busy cores
def test_report_with_a_monte_carlo_comparison(tmp_path, capsys):
    chaos, monte_carlo = _run(tmp_path, "collocation"), _run(tmp_path, "montecarlo")
    out = tmp_path / "with_mc"
    assert main(["report", str(chaos), "--compare", str(monte_carlo), "-o", str(out)]) == 0
    panels = {"time": 1, "pdf": 2, "sobol": 2, "psd": 1, "psd_pdf": 1, "compare": 2}
    expected = {f"{name}_{kind}.png" for name in ("x", "v") for kind in panels}
    assert {p.name for p in out.iterdir()} == expected | {"index.html"}
    for name in ("x", "v"):
        for kind, count in panels.items():
            _check_png(out / f"{name}_{kind}.png", count)
    page = (out / "index.html").read_text()
    for figure in expected:
        assert f'src="{figure}"' in page
    assert "decay-collocation" in page and "16 ok, 0 failed" in page
    assert "montecarlo (400 runs)" in page and "verdict" in page
    assert "wrote 12 figures" in capsys.readouterr().err


def test_report_of_a_file_without_analysis_in_the_default_folder(tmp_path):
    path = _run(tmp_path, "collocation", analysis=False, outputs="[x]")
    assert pcmb.load(path).analysis is None
    assert main(["report", str(path)]) == 0
    folder = path.parent / f"{path.stem}_report"
    # Defaults: PDFs at the final time, spectra of every output, PSD PDF at the peak.
    kinds = ("time", "pdf", "sobol", "psd", "psd_pdf")
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        ["index.html", *(f"x_{kind}.png" for kind in kinds)]
    )
    _check_png(folder / "x_pdf.png", 1)
    _check_png(folder / "x_sobol.png", 2)


def test_inspect_mentions_the_nominal_run_and_the_analysis(tmp_path, capsys):
    path = _run(tmp_path, "collocation", outputs="[x]")
    assert main(["inspect", str(path)]) == 0
    report = capsys.readouterr().out
    assert "nominal  k=0.5, x0=1 (stored)" in report
    assert "PDFs at t = 0.5, 2; spectra: x" in report


def test_a_sampling_result_has_no_sobol_figure(tmp_path):
    result = pcmb.load(_run(tmp_path, "lhs", outputs="[x]"))
    written = write_report(result, tmp_path / "lhs")
    assert sorted(p.name for p in written) == sorted(
        ["index.html", "x_time.png", "x_pdf.png", "x_psd.png", "x_psd_pdf.png"]
    )
    _check_png(tmp_path / "lhs" / "x_pdf.png", 2)


def test_report_errors(tmp_path, capsys, monkeypatch):
    assert main(["report", str(tmp_path / "missing.h5")]) == 2
    assert "missing.h5: no such file" in capsys.readouterr().err
    path = _run(tmp_path, "collocation", analysis=False, outputs="[x]")
    # Without matplotlib: a clear message and exit code 2, nothing unexpected.
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    assert main(["report", str(path), "-o", str(tmp_path / "no_mpl")]) == 2
    assert 'pip install "pcmb[plot]"' in capsys.readouterr().err
    assert not (tmp_path / "no_mpl").exists()


def test_the_command_line_module_stays_light():
    code = "import sys, pcmb.cli; print('matplotlib' in sys.modules, 'h5py' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
