"""A tiny external simulator for the command-adapter tests.

Usage: python sim_decay.py OUTPUT [--deck FILE]

Reads the parameters from params.json (or, with --deck, from "name = value" lines of a
rendered template), computes y = y0 exp(-k t), dy = -k y and writes OUTPUT in the format
of its extension (.csv with a time column, .txt: a whitespace table like ngspice's
``wrdata``, .json, .npy, .npz). The parameter ``mode``
selects a misbehaviour: 1 exit 3, 2 hang (with a grandchild), 3 garbage, 4 no output,
5 one row short, 6 SIGSEGV, 7 NaN, 8 wrong time column.
"""

import json
import os
import signal
import subprocess
import sys
import time

output = sys.argv[1]
if "--deck" in sys.argv:
    deck = {}
    with open(sys.argv[sys.argv.index("--deck") + 1]) as handle:
        for line in handle:
            name, _, value = line.partition("=")
            deck[name.strip()] = value.strip()
    params = {k: float(v) for k, v in deck.items() if not k.startswith("times.")}
else:
    with open("params.json") as handle:
        document = json.load(handle)
    params = document["params"]

# The misbehaviours come before numpy is imported, so that they happen at once.
mode = int(params.get("mode", 0))
if mode == 1:
    print("something went wrong in the solver", file=sys.stderr)
    sys.exit(3)
if mode == 2:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    with open("grandchild.pid", "w") as handle:
        handle.write(str(child.pid))
    time.sleep(60)
if mode == 6:
    os.kill(os.getpid(), signal.SIGSEGV)

import numpy as np  # noqa: E402

if "--deck" in sys.argv:
    times = np.linspace(
        float(deck["times.start"]), float(deck["times.stop"]), int(deck["times.points"])
    )
else:
    times = np.array(document["times"])

y = params["y0"] * np.exp(-params["k"] * times)
dy = -params["k"] * y
if mode == 7:
    y[len(y) // 2] = np.nan
if mode == 5:
    times, y, dy = times[:-1], y[:-1], dy[:-1]
if mode == 8:
    times = times + 0.5 * (times[1] - times[0])

if mode == 4:
    sys.exit(0)
if mode == 3:
    with open(output, "w") as handle:
        handle.write("time,y,dy\n0.0,not-a-number,\x00\x01\n")
    sys.exit(0)
if output.endswith(".csv"):
    with open(output, "w") as handle:
        handle.write("time, y, dy\n")
        for row in zip(times, y, dy, strict=True):
            handle.write(",".join(repr(float(v)) for v in row) + "\n")
elif output.endswith(".txt"):
    with open(output, "w") as handle:
        handle.write(" time     y    dy\n")
        for row in zip(times, y, dy, strict=True):
            handle.write(" " + "\t ".join(repr(float(v)) for v in row) + "  \n")
elif output.endswith(".json"):
    with open(output, "w") as handle:
        json.dump({"time": times.tolist(), "y": y.tolist(), "dy": dy.tolist()}, handle)
elif output.endswith(".npy"):
    np.save(output, np.column_stack([y, dy]))
elif output.endswith(".npz"):
    np.savez(output, y=y, dy=dy, time=times)
