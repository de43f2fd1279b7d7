"""``pcmb report``: every expected figure, of the right size, not blank; the index page."""

import dataclasses
import html
import itertools
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from executor_models import edges
from model_loading import model_class

import pcmb
from pcmb.cli import main

pytest.importorskip("matplotlib")
from matplotlib.image import imread

from pcmb.analysis.diagnostics.diagnose import diagnose
from pcmb.analysis.report import (
    UNRELIABLE_ALPHA,
    UNRELIABLE_COLOR,
    _Labels,
    _verdict,
    figure_pixels,
    write_report,
)
from pcmb.analysis.statistics import AnalysisSettings, analyse
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.run.status import Status
from pcmb.store import write_result

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


@pytest.mark.slow
def test_report_of_a_file_without_analysis_in_the_default_folder(tmp_path):
    path = _run(tmp_path, "collocation", analysis=False, outputs="[x]")
    assert pcmb.load(path).analysis is None
    assert main(["report", str(path)]) == 0
    folder = path.parent / f"{path.stem}_report"
    # Defaults: PDFs at the final time; a spectrum of every output (analysis.psd not set).
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


@pytest.mark.slow
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


# -- statistics that do not vary or are not finite -------------------------------------------

EDGE_TIMES = np.linspace(0.0, 2.0, 9)


def _edges(path):
    inputs = {"a": pcmb.Uniform(1.0, 3.0), "b": pcmb.Normal(0.0, 1.0)}
    spectra = AnalysisSettings(psd=("huge", "flat", "z"))
    study = pcmb.Study(
        edges, inputs, EDGE_TIMES, order=2, params={"a": 2.0, "b": 0.0}, jobs=1, analysis=spectra
    )
    with pytest.warns(pcmb.PcmbWarning, match=r"\[square-overflow\]"):
        return study.run(path)


@pytest.mark.slow
def test_report_of_a_constant_and_a_huge_output(tmp_path, capsys):
    path = tmp_path / "edges.h5"
    _edges(path)
    out = tmp_path / "edges_report"
    assert main(["report", str(path), "-o", str(out)]) == 0  # and no numpy warning on the way
    assert "wrote" in capsys.readouterr().err
    page = (out / "index.html").read_text()
    # The records are on the page; the PSD of huge (1e400 per Hz) is named as not drawn.
    assert "[sobol-undefined]" in page and "[square-overflow]" in page
    assert "huge: PSD not drawn: its mean is not finite (NaN or inf)" in page
    assert not (out / "huge_psd.png").exists()
    assert '<td>flat</td><td class="num">2.5 .. 2.5</td><td class="num">0</td>' in page
    kinds = ("time", "pdf", "sobol", "psd_pdf")
    assert {f"{name}_{kind}.png" for name in ("huge", "flat", "z") for kind in kinds} <= {
        p.name for p in out.iterdir()
    }
    _check_png(out / "huge_time.png", 1)
    _check_png(out / "z_sobol.png", 2)


@pytest.mark.slow
def test_report_and_compare_of_statistics_that_are_not_finite(tmp_path, capsys):
    result = _edges(None)
    expansion = result.expansions["z"]
    coefficients = expansion.coefficients.copy()
    coefficients[:, 4] = np.nan  # z at t = 1 is lost: mean, std and Sobol' indices are NaN
    broken = ChaosExpansion(coefficients, expansion.multi_index, expansion.distributions)
    broken = dataclasses.replace(result, expansions={**result.expansions, "z": broken})
    assert np.isnan(broken.std("z")[4]) and np.isfinite(np.delete(broken.std("z"), 4)).all()
    paths = [
        write_result(tmp_path / f"{n}.h5", r, provenance={})
        for n, r in (("a", broken), ("b", result))
    ]
    out = tmp_path / "report"
    assert main(["report", str(paths[0]), "--compare", str(paths[1]), "-o", str(out)]) == 0
    page = (out / "index.html").read_text()
    assert "z: mean or std: not finite (NaN or inf) at 1 of 9 points" in page
    assert "(not finite at some times)" in page and "not finite at 1 times" in page
    _check_png(out / "z_time.png", 1)
    capsys.readouterr()
    assert main(["compare", str(paths[0]), str(paths[1])]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("z "))
    assert row.endswith("not finite at 1 times")


def test_the_command_line_module_stays_light():
    code = "import sys, pcmb.cli; print('matplotlib' in sys.modules, 'h5py' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


# -- the range the diagnostics call unreliable -------------------------------------------------


def _shaded_share(path):
    """Share of the pixels of the time plot in the colour of the unreliable range: the shade
    blended over the white axes (within the 256-colour quantisation's rounding)."""
    from matplotlib.colors import to_rgb

    shade = 1.0 - UNRELIABLE_ALPHA * (1.0 - np.array(to_rgb(UNRELIABLE_COLOR)))
    rgb = imread(path)[..., :3]
    return np.mean(np.all(np.abs(rgb - shade) < 3 / 255, axis=-1))


@pytest.mark.slow
def test_report_shades_and_explains_where_the_chaos_is_unreliable(tmp_path):
    # The double well at order 7: its mean and std fail from t ≈ 3.15 (docs/diagnostics.md);
    # a linear response y = a t is exact at order 1 and never flagged.
    times = np.linspace(0.0, 4.0, 81)
    well = model_class("double_well", "DoubleWell")
    inputs = {"x0": pcmb.Uniform(-0.625, 0.375)}
    # 128 held-out runs: the default 8 leave it undecided (docs/diagnostics.md).
    with pytest.warns(pcmb.PcmbWarning):  # chaos-unreliable, chaos-undecided before it
        flagged = pcmb.Study(well, inputs, times, order=7, jobs=1, validation=128).run()
    start = flagged.diagnostics["x"].failing_from
    assert 2.75 < start < 3.55  # within a tenth of the horizon

    @pcmb.pointwise(outputs=("x",))
    def linear(params, times):
        return {"x": params["a"] * times}

    plain = pcmb.Study(linear, {"a": pcmb.Uniform(1.0, 3.0)}, times, order=1, params={"a": 2})
    unflagged = plain.run()
    assert unflagged.diagnostics["x"].reliable

    write_report(flagged, tmp_path / "flagged")
    write_report(unflagged, tmp_path / "unflagged")
    page = (tmp_path / "flagged" / "index.html").read_text()
    (message,) = [w.message for w in flagged.warnings if w.code == "chaos-unreliable"]
    assert f"unreliable from t = {start:.4g} (shaded in the time plot; tolerance" in page
    assert page.count(html.escape(message)) == 1  # in the diagnostics, not also a warning
    assert "chaos unreliable" not in (tmp_path / "unflagged" / "index.html").read_text()
    # The shade spans (4 - start) / 4 = 20 % of the axes' width, the axes about half of the
    # figure: some 10 % of its pixels, fewer where the ±1σ band lies over the shade.
    assert _shaded_share(tmp_path / "flagged" / "x_time.png") > 0.03
    assert _shaded_share(tmp_path / "unflagged" / "x_time.png") < 1e-3


@pytest.mark.slow
def test_the_sobol_figure_shades_where_the_chaos_is_unreliable_and_names_the_caution(tmp_path):
    # Sobol' indices are drawn from the surrogate: where the verdict fails (the double well at
    # order 7, from t ≈ 3.15) they are shaded as the time plot is, and the title names the
    # surrogate-inaccurate range before it (docs/diagnostics.md, "Surrogate cautions").
    from pcmb.analysis.report import _horizon, _Labels, _surrogate_note
    from pcmb.references import double_well

    @pcmb.batched(outputs=("x",))
    def tilted_well(params, times):
        x0, a = np.asarray(params["x0"]), np.asarray(params["a"])
        return {"x": double_well(times, x0) + 0.1 * np.outer(a, times)}

    inputs = {"x0": pcmb.Uniform(-0.625, 0.375), "a": pcmb.Uniform(0.0, 1.0)}
    times = np.linspace(0.0, 4.0, 41)
    study = pcmb.Study(tilted_well, inputs, times, order=7, backend="inprocess", validation=128)
    with pytest.warns(pcmb.PcmbWarning):  # chaos-unreliable
        result = study.run()
    assert not result.diagnostics["x"].reliable
    write_report(result, tmp_path / "report")
    assert _shaded_share(tmp_path / "report" / "x_sobol.png") > 0.02
    assert any(w.code == "surrogate-inaccurate" for w in result.warnings)
    labels = _Labels(AnalysisSettings(), _horizon(result))
    assert "surrogate-inaccurate" in _surrogate_note(result, "x", labels)


# -- what a figure shows must fit it -----------------------------------------------------------


def _ink_at_the_edges(path):
    """Whether any of the outermost 2 pixel columns of a PNG is not white: a legend or a
    curve cut by the figure's edge."""
    rgb = imread(path)[..., :3]
    return bool(np.any(rgb[:, :2] < 0.95) or np.any(rgb[:, -2:] < 0.95))


@pytest.mark.slow
def test_long_labels_and_titles_stay_inside_the_figure(tmp_path):
    result = pcmb.load(_run(tmp_path, "collocation", outputs="[x]"))
    twin = pcmb.load(_run(tmp_path, "montecarlo", outputs="[x]"))
    # Three panels of PDFs, whose titles and labels must fit a third of the width each.
    three = AnalysisSettings(psd=("x",), pdf_times=(0.5, 1.0, 2.0), pdf_freqs=(0.5, 1.0, 2.5))
    result = dataclasses.replace(result, analysis=analyse(result, three))
    label = "a Monte Carlo twin of 400 runs drawn with seed 1, stored in decay_montecarlo.h5"
    written = write_report(result, tmp_path / "long", comparisons=[twin], labels=[label])
    for path in written[:-1]:
        assert not _ink_at_the_edges(path), path.name


def _tick_labels(axes):
    """The tick labels drawn on both axes of a drawn figure's panel, as window extents."""
    boxes = {}
    for name, axis in (("x", axes.xaxis), ("y", axes.yaxis)):
        labels = [*axis.get_majorticklabels(), *axis.get_minorticklabels()]
        boxes[name] = [
            (label.get_text(), label.get_window_extent())
            for label in labels
            if label.get_visible() and label.get_text()
        ]
    return boxes


@pytest.mark.slow
@pytest.mark.parametrize("decades", [0.3, 1.2, 1.9, 6.0])
def test_sweep_log_axes_have_readable_ticks_at_every_span(decades):
    from pcmb.sweep.chart import sweep_figure
    from pcmb.sweep.table import SweepRow, SweepTable

    runs = np.round(np.geomspace(20, 20 * 10**decades, 5)).astype(int)
    errors = np.geomspace(3e-3, 3e-3 / 10**decades, 5)
    rows = tuple(
        SweepRow("collocation", f"order={k}", int(n), 0.01 * n, "y", e, e, e, e)
        for k, (n, e) in enumerate(zip(runs, errors, strict=True))
    )
    table = SweepTable(rows, np.zeros(1), np.zeros((5, 1)), np.zeros((5, 1)), "reference.h5")
    figure = sweep_figure(table)
    figure.canvas.draw()
    for axes in figure.axes:
        for name, boxes in _tick_labels(axes).items():
            assert len(boxes) >= 2, (name, decades, [text for text, _ in boxes])
            for (text, box), (other, next_box) in itertools.combinations(boxes, 2):
                assert not box.overlaps(next_box), (name, decades, text, other)


@pcmb.batched(outputs=("y",))
def smooth(params, times):
    """A smooth response of ``a`` (and ``b``, if an input), which every design resolves."""
    a = params["a"][:, None]
    b = params.get("b", np.zeros_like(params["a"]))[:, None]
    return {"y": np.exp(0.3 * a) * np.cos(times) + b * times}


def _verdict_text(result):
    """The report's verdict on the output ``y`` (without rendering the report)."""
    return _verdict(result, "y", _Labels(AnalysisSettings(), float(result.times[-1])))[1]


@pytest.mark.parametrize(
    ("inputs", "method", "source", "shown"),
    [
        (
            # The normal input linear: no tail along it to place the runs on (docs/diagnostics.md).
            {"a": pcmb.Uniform(-1.0, 1.0), "b": pcmb.Normal(0.0, 1.0)},
            {"order": 4},
            "held-out",
            "8 held-out runs drawn at random, surrogate error up to",
        ),
        (
            {"a": pcmb.Normal(0.0, 1.0)},
            {"order": 6},
            "placed",
            "8 held-out runs placed to extend the design's nodes, surrogate error up to",
        ),
        (
            {"a": pcmb.Uniform(-1.0, 1.0), "b": pcmb.Uniform(0.0, 1.0)},
            {"order": 4, "validation": 0},
            "decay",
            "no held-out runs: estimated from the spectral decay",
        ),
        (
            {"a": pcmb.Uniform(-1.0, 1.0)},
            {"order": "auto", "validation": 0},
            "design",
            "no held-out runs: estimated from the design's own estimate",
        ),
    ],
    ids=["drawn", "placed", "decay", "design"],
)
def test_the_verdict_names_where_the_estimate_comes_from(tmp_path, inputs, method, source, shown):
    """``diagnose`` records where each output's estimate comes from (``estimated_by``), and
    the report's verdict says it."""
    study = pcmb.Study(
        smooth,
        inputs,
        np.linspace(0.0, 2.0, 11),
        method={"kind": "collocation", **method},
        execution={"backend": "inprocess"},
    )
    result = study.run()
    assert result.diagnostics["y"].estimated_by == source
    assert shown in _verdict_text(result)


def test_the_report_takes_the_estimate_s_source_from_the_diagnostics(tmp_path):
    """Where a design's own error (an adaptive grid's, ``order: auto``'s) lies below the
    spectral decay at some times, ``diagnose`` takes it there and says so; the report's page
    names that source, from ``estimated_by``, not from the numbers."""
    study = pcmb.Study(
        smooth,
        {"a": pcmb.Uniform(-1.0, 1.0)},
        np.linspace(0.0, 2.0, 11),
        method={"kind": "collocation", "order": 4, "validation": 0},
        execution={"backend": "inprocess"},
    )
    result = study.run()
    decay = result.diagnostics["y"].decay
    ok = result.status == Status.OK
    found = diagnose(
        "y",
        result.expansions["y"],
        result.values["y"][ok],
        result.times,
        node_germ=result.germ[ok],
        design_error=float(np.median(decay)),
    )
    assert found.estimated_by == "design" and np.any(found.estimate == found.decay)
    result = dataclasses.replace(result, diagnostics={"y": found})
    write_report(result, tmp_path)
    page = html.unescape((tmp_path / "index.html").read_text())
    assert "estimated from the design's own estimate" in page
