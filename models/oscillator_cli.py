#!/usr/bin/env python3
"""A command-line simulator of the free damped oscillator, for ``model.kind: command``.

    oscillator_cli.py INPUT OUTPUT

solves x'' + c x' + k x = 0 with x(0) = x0, x'(0) = v0 in closed form (under-, critically or
over-damped) and writes OUTPUT, a CSV file with the columns time, x, v (v = x').

INPUT is either the ``params.json`` pcmb writes into every node's work directory,
``{"params": {"k": ..., "c": ..., "x0": ..., "v0": ...}, "times": [...]}``, or an input deck
of ``name = value`` lines (``#`` starts a comment) giving k, c, x0, v0 (default 0) and the
grid as t_start, t_stop, points. Errors go to stderr with exit code 2.

It needs only the standard library, so any Python 3 found as ``python3`` on PATH can run
it. configs/command_oscillator.yaml and docs/examples/command_deck.yaml run it; see
docs/models.md.
"""

import json
import math
import sys


def read_json(path):
    with open(path, encoding="utf-8") as handle:
        document = json.load(handle)
    return document["params"], [float(t) for t in document["times"]]


def read_deck(path):
    values = {}
    with open(path, encoding="utf-8") as handle:
        for number, line in enumerate(handle, start=1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            name, equals, value = line.partition("=")
            if not equals:
                raise ValueError(f"{path} line {number}: expected 'name = value', got {line!r}")
            values[name.strip()] = float(value)
    start, stop, points = values.pop("t_start"), values.pop("t_stop"), values.pop("points")
    if points != int(points) or points < 1:
        raise ValueError(f"points must be a positive whole number, got {points}")
    points = int(points)
    step = (stop - start) / (points - 1) if points > 1 else 0.0
    times = [start + i * step for i in range(points - 1)] + [stop]  # the last one exactly
    return values, times


def oscillator(k, c, x0, v0, t):
    """x(t) and x'(t) for x'' + c x' + k x = 0, x(0) = x0, x'(0) = v0."""
    a = c / 2
    b = k * x0 + a * v0
    d = k - a * a
    if d > 0:  # underdamped: x = e^{-at} (x0 cos wt + (v0 + a x0)/w sin wt)
        w = math.sqrt(d)
        e, cos, sin = math.exp(-a * t), math.cos(w * t), math.sin(w * t)
        return e * (x0 * cos + (v0 + a * x0) / w * sin), e * (v0 * cos - b / w * sin)
    if d < 0:  # overdamped: cosh and sinh, each as two decaying exponentials
        m = math.sqrt(-d)
        slow, fast = math.exp((m - a) * t), math.exp(-(m + a) * t)
        cosh, sinh = (slow + fast) / 2, (slow - fast) / 2
        return x0 * cosh + (v0 + a * x0) / m * sinh, v0 * cosh - b / m * sinh
    e = math.exp(-a * t)  # critically damped
    return e * (x0 + (v0 + a * x0) * t), e * (v0 - b * t)


def main(argv):
    if len(argv) != 3:
        print("usage: oscillator_cli.py INPUT OUTPUT", file=sys.stderr)
        return 2
    source, target = argv[1], argv[2]
    try:
        params, times = read_json(source) if source.endswith(".json") else read_deck(source)
        k, c, x0 = (float(params[name]) for name in ("k", "c", "x0"))
        v0 = float(params.get("v0", 0.0))
    except (OSError, ValueError, KeyError) as exc:
        print(f"oscillator_cli: cannot read {source}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    if not all(math.isfinite(value) for value in (k, c, x0, v0)):
        print(f"oscillator_cli: parameters must be finite: {params}", file=sys.stderr)
        return 2
    with open(target, "w", encoding="utf-8") as handle:
        handle.write("time,x,v\n")
        for t in times:
            x, v = oscillator(k, c, x0, v0, t)
            handle.write(f"{t!r},{x!r},{v!r}\n")  # repr: every digit of the double
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
