"""Benchmark of MuJoCo scenes as pcmb models (issue 5).

216 pendulum variants x 15 s at a 1 ms timestep (models/mujoco/pendulum.xml, RK4): the
length L (template), the initial angle (qpos0) and the hinge damping (dof_damping), each
uniform, order 5: 6^3 = 216 nodes, the angle recorded every 10 ms (1501 points).

Compared, median of ``--repeat`` runs each, interleaved so that load from other processes
hits all alike, every ratio against the baseline:

- baseline: a bare script that builds the same 216 models the same way (render the template,
  compile, set the damping, set the initial angle) and calls ``mujoco.rollout.rollout`` with
  2 threads, then keeps every 10th state;
- ``pcmb run`` of the whole study (config validation, the executor, recovery, statistics,
  the HDF5 file) at equal work, the same 216 runs (``method.validation: 0``,
  ``execution.nominal_run: false``), with ``--jobs 1`` (one process; MuJoCo's batch on 2
  threads) and with ``--jobs 2`` (two worker processes, one MuJoCo thread each). Target:
  <= 1.1 x baseline;
- ``pcmb run --jobs 1`` with the defaults: 249 runs (+ 32 held-out runs that check the
  expansion, + the nominal run).

With ``--breakdown`` also: a Python ``mj_step`` loop, rollout on 1 thread, and
``MujocoModel.simulate`` alone on 1 and 2 threads (the adapter without the pipeline).

Run: ``python scripts/bench_mujoco.py [--repeat 5] [--breakdown]``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import mujoco
import mujoco.rollout
import numpy as np

from pcmb.adapters.mujoco.model import MujocoModel
from pcmb.chaos.inputs import Uniform
from pcmb.chaos.nodes import TensorGrid
from pcmb.cli import main

SCENE = Path(__file__).resolve().parents[1] / "models" / "mujoco" / "pendulum.xml"
INPUTS = {"L": (0.8, 1.2), "theta0": (0.6, 0.9), "damping": (0.0, 0.05)}
ORDER = 5
STOP, POINTS, EVERY = 15.0, 1501, 10  # 15 s, a point every 10 steps of 1 ms
FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS

CONFIG = """\
name: bench-mujoco-pendulum
model:
  kind: mujoco
  xml: {scene}
  params: {{L: 1.0}}
  bind:
    theta0: [{{qpos0: hinge}}]
    damping: [{{field: dof_damping, name: hinge}}]
  outputs:
    theta: {{qpos: hinge}}
time: {{start: 0.0, stop: {stop}, points: {points}}}
inputs:
{inputs}
method: {{kind: collocation, order: {order}, validation: {validation}}}
execution: {{nominal_run: {nominal}}}
output: {output}
"""


def grid_params() -> np.ndarray:
    """(216, 3) node values of L, theta0, damping."""
    grid = TensorGrid([Uniform(*bounds) for bounds in INPUTS.values()], [ORDER] * len(INPUTS))
    return grid.params


def build_models(params: np.ndarray) -> list[mujoco.MjModel]:
    """The bare script's scenes: rendered, compiled, damping set (as pcmb does)."""
    template = SCENE.read_text(encoding="utf-8")
    models = []
    for length, _, damping in params:
        model = mujoco.MjModel.from_xml_string(template.replace("{{ L }}", repr(float(length))))
        model.dof_damping[0] = damping
        models.append(model)
    return models


def initial_states(models: list[mujoco.MjModel], params: np.ndarray) -> np.ndarray:
    states = []
    for model, theta0 in zip(models, params[:, 1], strict=True):
        data = mujoco.MjData(model)
        data.qpos[0] = theta0
        state = np.empty(mujoco.mj_stateSize(model, FULL))
        mujoco.mj_getState(model, data, state, FULL)
        states.append(state)
    return np.array(states)


def bare_rollout(params: np.ndarray, threads: int) -> np.ndarray:
    """(216, 1501) angles by mujoco.rollout, from building the models to slicing the states."""
    models = build_models(params)
    datas = [mujoco.MjData(models[0]) for _ in range(threads)]
    state, _ = mujoco.rollout.rollout(
        models, datas, initial_states(models, params), nstep=round(STOP * 1000)
    )
    theta = state[:, EVERY - 1 :: EVERY, 1]  # column 0 is time, 1 is qpos
    return np.concatenate([params[:, 1:2], theta], axis=1)


def python_loop(params: np.ndarray) -> np.ndarray:
    """(216, 1501) angles by mj_step in a Python loop over nodes and output times."""
    out = np.empty((len(params), POINTS))
    for i, model in enumerate(build_models(params)):
        data = mujoco.MjData(model)
        data.qpos[0] = params[i, 1]
        out[i, 0] = data.qpos[0]
        for k in range(1, POINTS):
            mujoco.mj_step(model, data, nstep=EVERY)
            out[i, k] = data.qpos[0]
    return out


@contextlib.contextmanager
def threads(count: int) -> Iterator[None]:
    """The thread budget pcmb's MuJoCo batch reads (see pcmb.adapters.mujoco.model)."""
    saved = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = str(count)
    try:
        yield
    finally:
        if saved is None:
            del os.environ["OMP_NUM_THREADS"]
        else:
            os.environ["OMP_NUM_THREADS"] = saved


def adapter(params: np.ndarray, count: int) -> np.ndarray:
    model = MujocoModel(
        xml=SCENE,
        params={"L": 1.0},
        bind={
            "theta0": [{"qpos0": "hinge"}],
            "damping": [{"field": "dof_damping", "name": "hinge"}],
        },
        outputs={"theta": {"qpos": "hinge"}},
    )
    with threads(count):
        values = dict(zip(INPUTS, params.T, strict=True))
        return model.simulate(values, np.linspace(0.0, STOP, POINTS))["theta"]


def write_config(folder: Path, equal_work: bool = True) -> Path:
    """The study's config; ``equal_work``: only the 216 runs of the baseline (no held-out
    check, no nominal run), else pcmb's defaults."""
    inputs = "\n".join(
        f"  {name}: {{dist: uniform, low: {low}, high: {high}}}"
        for name, (low, high) in INPUTS.items()
    )
    path = folder / f"bench_mujoco_{'equal' if equal_work else 'defaults'}.yaml"
    path.write_text(
        CONFIG.format(
            scene=SCENE,
            stop=STOP,
            points=POINTS,
            inputs=inputs,
            order=ORDER,
            validation=0 if equal_work else 32,
            nominal="false" if equal_work else "true",
            output=folder / "out.h5",
        ),
        encoding="utf-8",
    )
    return path


def pcmb_run(config: Path, jobs: int) -> None:
    out = config.parent / f"out_{config.stem}_{jobs}.h5"
    out.unlink(missing_ok=True)
    code = main(["run", str(config), "-o", str(out), "--jobs", str(jobs)])
    if code != 0:
        raise SystemExit(f"pcmb run failed with exit code {code}")


def bench(cases: dict[str, Callable[[], object]], repeat: int) -> dict[str, float]:
    seconds: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(repeat):
        for name, case in cases.items():
            start = time.perf_counter()
            case()
            seconds[name].append(time.perf_counter() - start)
    return {name: statistics.median(values) for name, values in seconds.items()}


def run(repeat: int, breakdown: bool) -> None:
    params = grid_params()
    reference = bare_rollout(params, threads=2)
    same = np.abs(adapter(params, 2) - reference).max()
    print(f"216 pendulums x 15 s at 1 ms (RK4); pcmb vs bare rollout, max |dtheta| = {same:.1e}")
    with tempfile.TemporaryDirectory() as folder:
        config = write_config(Path(folder))
        defaults = write_config(Path(folder), equal_work=False)
        cases: dict[str, Callable[[], object]] = {
            "bare mujoco.rollout, 2 threads (baseline)": lambda: bare_rollout(params, 2),
            "pcmb run --jobs 1 (batch on 2 threads)": lambda: pcmb_run(config, 1),
            "pcmb run --jobs 2 (2 workers x 1 thread)": lambda: pcmb_run(config, 2),
            "pcmb run --jobs 1, defaults (249 runs)": lambda: pcmb_run(defaults, 1),
        }
        if breakdown:
            cases |= {
                "Python mj_step loop": lambda: python_loop(params),
                "bare mujoco.rollout, 1 thread": lambda: bare_rollout(params, 1),
                "MujocoModel.simulate, 1 thread": lambda: adapter(params, 1),
                "MujocoModel.simulate, 2 threads": lambda: adapter(params, 2),
            }
        medians = bench(cases, repeat)
    baseline = next(iter(medians.values()))
    print(f"median of {repeat} runs:")
    for name, seconds in medians.items():
        print(f"  {name:<44} {seconds:7.2f} s  {seconds / baseline:5.2f} x")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--breakdown", action="store_true")
    arguments = parser.parse_args()
    run(arguments.repeat, arguments.breakdown)
