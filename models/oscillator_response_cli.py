#!/usr/bin/env python3
"""A command-line frequency-response analysis of the damped oscillator, for ``kind: command``.

    oscillator_response_cli.py params.json response.csv

For x'' + c x' + k x = F e^{iωt} (unit mass) it writes the steady-state gain
|H(f)| = 1 / √((k − ω²)² + (c ω)²) and the phase −atan2(c ω, k − ω²) (rad), ω = 2π f, at
``points`` frequencies spaced logarithmically from ``f_start`` to ``f_stop`` Hz, as a CSV
file with the columns f, gain, phase: an AC sweep, whose outputs live on a frequency axis
instead of time (``model.output.axis`` in configs/command_frequency_response.yaml). It needs
only the standard library.
"""

import csv
import json
import math
import sys


def main(argv):
    if len(argv) != 3:
        print("usage: oscillator_response_cli.py params.json response.csv", file=sys.stderr)
        return 2
    with open(argv[1], encoding="utf-8") as handle:
        params = json.load(handle)["params"]
    k, c = float(params["k"]), float(params["c"])
    start, stop, points = float(params["f_start"]), float(params["f_stop"]), int(params["points"])
    ratio = (stop / start) ** (1.0 / (points - 1))
    with open(argv[2], "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["f", "gain", "phase"])
        for j in range(points):
            f = start * ratio**j
            omega = 2.0 * math.pi * f
            real, imag = k - omega**2, c * omega
            writer.writerow(
                [repr(f), repr(1.0 / math.hypot(real, imag)), repr(-math.atan2(imag, real))]
            )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
