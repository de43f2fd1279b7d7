"""``pcmb report`` pages as a user sees them: rendered by headless Chromium at 1,400 px.

Chromium is driven over the DevTools protocol (a websocket): the page is loaded, then the
test reads what a user would see (the page's text, its width, every image) and every console
error. Skipped, saying so, where no Chromium is installed (``.ci/run`` installs it).
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import shutil
import signal
import subprocess
import textwrap
import time
import urllib.request
from pathlib import Path

import pytest

import pcmb
from pcmb.cli import main

pytest.importorskip("matplotlib")
websockets_sync = pytest.importorskip("websockets.sync.client")

WIDTH, HEIGHT = 1400, 900
CHROMIUM = next(
    (found for name in ("chromium", "chromium-browser") if (found := shutil.which(name))), None
)
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH to render pages"),
]

#: What a user sees, measured in the page once it has loaded.
MEASURE = """(() => {
  const wide = [...document.querySelectorAll('table, pre, img, svg, figure')]
    .filter(e => e.getBoundingClientRect().right > window.innerWidth + 0.5)
    .map(e => e.tagName + ' ' + Math.round(e.getBoundingClientRect().right));
  return {
    scrollWidth: document.documentElement.scrollWidth,
    innerWidth: window.innerWidth,
    wide: wide,
    images: [...document.images].map(i => ({
      src: i.getAttribute('src'), loaded: i.complete && i.naturalWidth > 0})),
    text: document.body.innerText,
  };
})()"""


def _start(profile: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [
            CHROMIUM,
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--disable-crash-reporter",
            "--no-first-run",
            f"--window-size={WIDTH},{HEIGHT}",
            "--remote-debugging-port=0",
            f"--user-data-dir={profile}",
            "about:blank",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # its own process group, ended with it
    )


def _tab(process: subprocess.Popen, profile: Path) -> str:
    """The DevTools websocket of Chromium's tab, once Chromium listens."""
    port_file = profile / "DevToolsActivePort"
    deadline = time.monotonic() + 60
    while not (port_file.exists() and port_file.read_text().count("\n") >= 1):
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"chromium did not start (exit {process.poll()})")
        time.sleep(0.1)
    port = port_file.read_text().split()[0]
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list") as answer:
        return next(t for t in json.load(answer) if t["type"] == "page")["webSocketDebuggerUrl"]


class Browser:
    """One Chromium tab, driven over the DevTools protocol."""

    def __init__(self, socket):
        self.socket = socket
        self.calls = 0
        self.events: list[dict] = []
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")

    def call(self, method: str, **params: object) -> dict:
        """Send one command and wait for its answer; events on the way are kept."""
        self.calls += 1
        self.socket.send(json.dumps({"id": self.calls, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv(timeout=60))
            if message.get("id") == self.calls:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]
            self.events.append(message)

    def wait_for(self, event: str) -> None:
        while not any(e.get("method") == event for e in self.events):
            self.events.append(json.loads(self.socket.recv(timeout=60)))

    def open(self, page: Path) -> dict:
        """Load a page; what a user sees of it, with ``errors``: the console's errors."""
        self.events.clear()
        self.call("Page.navigate", url=page.resolve().as_uri())
        self.wait_for("Page.loadEventFired")
        seen = self.call("Runtime.evaluate", expression=MEASURE, returnByValue=True)
        found = seen["result"]["value"]
        found["errors"] = [
            e["params"]
            for e in self.events
            if e.get("method") == "Runtime.exceptionThrown"
            or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")
            or (e.get("method") == "Runtime.consoleAPICalled" and e["params"]["type"] == "error")
        ]
        return found

    def screenshot(self, path: Path) -> Path:
        """The whole page as a PNG (to look at when a check fails)."""
        shot = self.call("Page.captureScreenshot", format="png", captureBeyondViewport=True)
        path.write_bytes(base64.b64decode(shot["data"]))
        return path


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    profile = tmp_path_factory.mktemp("chromium-profile")
    process = _start(profile)
    try:
        with websockets_sync.connect(_tab(process, profile), max_size=None) as socket:
            yield Browser(socket)
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        with contextlib.suppress(ProcessLookupError):  # helpers still shutting down
            os.killpg(process.pid, signal.SIGKILL)


def _fits_and_loads(seen: dict) -> None:
    """What every page must do: fit 1,400 px, load every image, log no error."""
    assert seen["innerWidth"] == WIDTH
    assert seen["scrollWidth"] <= seen["innerWidth"], seen["wide"]
    assert not seen["wide"]
    assert seen["images"] and all(i["loaded"] for i in seen["images"]), seen["images"]
    assert seen["errors"] == []


# -- a normal run: a charging curve on a 0.5 ms horizon --------------------------------------

CHARGE = '''
import numpy as np


class Charge:
    """v = V (1 - exp(-t / (R C))): a capacitor charging through a resistor."""

    outputs = ("v",)

    def __init__(self, R=1.0e3, C=1.0e-7, V=5.0):
        self.parameters = {"R": R, "C": C, "V": V}

    def simulate(self, params, times):
        R = np.asarray(params["R"], float)[:, None]
        C = np.asarray(params["C"], float)[:, None]
        return {"v": self.parameters["V"] * -np.expm1(-times / (R * C))}
'''


def _run(folder: Path, name: str, text: str) -> Path:
    config = folder / f"{name}.yaml"
    config.write_text(textwrap.dedent(text))
    out = folder / f"{name}.h5"
    assert main(["run", str(config), "-o", str(out), "--quiet"]) == 0
    return out


def _report(path: Path) -> Path:
    folder = path.with_name(path.stem + "_report")
    assert main(["report", str(path), "-o", str(folder)]) == 0
    return folder / "index.html"


@pytest.fixture(scope="module")
def charge(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("charge")
    (folder / "charge.py").write_text(CHARGE)
    return _run(
        folder,
        "charge",
        """\
        name: rc-charge
        model: {kind: python, entry: charge.py:Charge, params: {R: 1000.0, C: 1.0e-7, V: 5.0}}
        time: {start: 0.0, stop: 5.0e-4, points: 51}
        inputs:
          R: {dist: uniform, low: 900.0, high: 1100.0}
          C: {dist: normal, mean: 1.0e-7, std: 5.0e-9}
        method: {kind: collocation, order: 4, validation: 8}
        execution: {jobs: 1}
        analysis: {psd: [], pdf_times: [5.0e-4], units: {v: V}, time_unit: s}
        """,
    )


def test_a_normal_run_fits_and_shows_its_inputs_runs_and_verdict(browser, charge):
    page = _report(charge)
    seen = browser.open(page)
    browser.screenshot(page.with_name("screen.png"))
    _fits_and_loads(seen)
    text = seen["text"]
    # Every input's law with its parameters, mean and std.
    assert "normal(mean=1e-07, std=5e-09)" in text
    # R's row, cell by cell: U[900, 1100] has mean 1000 and std 200 / √12.
    row = ("R", "uniform(low=900, high=1100)", "900 .. 1100", "1000", f"{200 / 12**0.5:.4g}")
    assert "\t".join(row) in text, text
    # The runs made: 25 design nodes, 8 held-out runs, the nominal run.
    assert "25 design nodes" in text and "8 held-out" in text and "nominal" in text
    assert "reliable" in text and "error up to" in text
    assert "Warnings" not in text  # a zero variance at t = 0 is information, not a warning
    # Units everywhere: the key numbers in V, the 0.5 ms horizon in ms.
    assert f"{pcmb.load(charge).std('v').max():.4g} V" in text
    assert "0 .. 0.5 ms" in text
    # No spectrum of a charging curve: analysis.psd asks for none.
    assert not any("psd" in i["src"] for i in seen["images"])


# -- a flagged run: the double well, whose chaos fails from t ≈ 3.1 (64 held-out runs flag it;
# 16 leave it undecided) ------------------------------------------------------------------


@pytest.fixture(scope="module")
def double_well(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("well")
    model = Path(__file__).resolve().parent.parent / "models" / "double_well.py"
    return _run(
        folder,
        "well",
        f"""\
            name: double-well
            model: {{kind: python, entry: "{model}:DoubleWell", params: {{x0: -0.125}}}}
            time: {{start: 0.0, stop: 4.0, points: 41}}
            inputs:
              x0: {{dist: uniform, low: -0.625, high: 0.375}}
            method: {{kind: collocation, order: 7, validation: 64}}
            execution: {{jobs: 1}}
            analysis: {{pdf_times: [4.0], time_unit: s}}
            """,
    )


def test_a_flagged_run_shows_its_verdict_once_with_its_numbers(browser, double_well):
    page = _report(double_well)
    seen = browser.open(page)
    browser.screenshot(page.with_name("screen.png"))
    _fits_and_loads(seen)
    text = seen["text"]
    diagnostics = pcmb.load(double_well).diagnostics["x"]
    start = f"{diagnostics.failing_from:.3g}"
    assert f"unreliable from t = {start} s" in text
    assert f"tolerance {diagnostics.tolerance:g}" in text
    (record,) = [w for w in pcmb.load(double_well).warnings if w.code == "chaos-unreliable"]
    assert text.count(record.message[:60]) == 1  # said once, not twice
    assert "uniform(low=-0.625, high=0.375)" in text


# -- a sweep ----------------------------------------------------------------------------------

GROWTH = '''
import numpy as np


class Growth:
    """y = exp(a t)."""

    outputs = ("y",)

    def __init__(self, a=0.5):
        self.parameters = {"a": a}

    def simulate(self, params, times):
        return {"y": np.exp(np.asarray(params["a"], float)[:, None] * times)}
'''


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep")
    (folder / "growth.py").write_text(GROWTH)
    config = folder / "growth.yaml"
    config.write_text(
        textwrap.dedent(
            """\
            name: growth
            model: {kind: python, entry: growth.py:Growth, params: {a: 0.5}}
            time: {start: 0.0, stop: 2.0, points: 11}
            inputs:
              a: {dist: uniform, low: 0.0, high: 1.0}
            method: {kind: collocation, order: 3, validation: 0}
            execution: {jobs: 1}
            sweep:
              methods:
                - {kind: collocation, order: [1, 2, 3, 4, 5]}
                - {kind: collocation, elements: {a: [0.25, 0.5, 0.75]}, order: [1, 2]}
                - {kind: montecarlo, samples: [20, 40], seed: 3}
              reference: {kind: collocation, order: 12}
            """
        )
    )
    out = folder / "out"
    assert main(["sweep", str(config), "-o", str(out), "--quiet"]) == 0
    return out / "sweep.h5"


def test_a_sweep_page_fits_and_says_what_reaching_an_accuracy_costs(browser, sweep, capsys):
    page = _report(sweep)
    seen = browser.open(page)
    browser.screenshot(page.with_name("screen.png"))
    _fits_and_loads(seen)
    text = seen["text"]
    assert str(sweep.parent) not in text  # no machine paths
    assert "reference.h5" in text
    capsys.readouterr()
    assert main(["inspect", str(sweep)]) == 0
    said = capsys.readouterr().out
    line = next(x for x in said.splitlines() if x.strip().startswith("collocation"))
    cells = [cell.strip() for cell in line.split("  ") if "runs" in cell]
    assert cells and all(cell in text for cell in cells)
