"""Noise-free simulations of two model files in numpy: an independent check of
`ModelFile::compare_simulation` and `sysid compare --model` (tests/simulation.rs).

    python simulation_numpy.py            # from the repository's root

The equations are written out below by hand (not parsed from the files); only the
parameter values are read from the files. For each model it prints the simulated
outputs at a few steps and the RMS error against the record, from a given initial
state (the one the Rust test passes), and for the cascaded tanks also from the
initial state scipy's least squares fits to the first 5 validation samples (the
benchmark's protocol). Tools: numpy 2.4.6, scipy 1.17.1 (Python 3.11).
"""

import tomllib

import numpy as np
from scipy.optimize import least_squares


def values(path):
    with open(path, "rb") as f:
        params = tomllib.load(f)["parameters"]
    return {k: (v["value"] if isinstance(v, dict) else v) for k, v in params.items()}


def tanks(p, u, x0):
    h1, h2 = x0
    y = np.empty(len(u))
    for t in range(len(u)):
        y[t] = min(h2 + p["yo"], 10.0)
        out1 = p["a1"] * np.sqrt(abs(h1)) + p["b1"] * h1
        fill = h1 - out1 + p["kp"] * u[t]
        spill = max(fill - p["top1"], 0.0)
        out2 = p["a2"] * np.sqrt(abs(h2)) + p["b2"] * h2
        h1, h2 = min(fill, p["top1"]), min(h2 + out1 - out2 + p["c"] * spill, p["top2"])
    return y


def oscillator(p, steps, x0):
    pos, vel = x0
    y = np.empty(steps)
    for t in range(steps):
        y[t] = np.tanh(pos)
        pos, vel = (
            pos + p["dt"] * vel,
            vel - p["dt"] * (p["k"] * pos**3 + p["c"] * vel) + p["dt"] * np.cos(0.3 * t),
        )
    return y


def show(name, y_sim, y, x0):
    rms = np.sqrt(np.mean((y - y_sim) ** 2))
    print(f"{name}: x0 = {[float(v) for v in x0]!r}")
    for t in (0, 1, 10, 100, len(y) - 1):
        print(f"  y[{t}] = {float(y_sim[t])!r}")
    print(f"  rms = {float(rms)!r}")


def main():
    val = np.loadtxt("examples/data/cascaded_tanks_val.csv", delimiter=",", skiprows=1)
    p = values("examples/models/cascaded_tanks_fitted.toml")
    x0 = [30.0, 4.5]
    show("tanks, given x0", tanks(p, val[:, 1], x0), val[:, 2], x0)
    fit = least_squares(lambda x: tanks(p, val[:5, 1], x) - val[:5, 2], [30.0, 4.5])
    show("tanks, x0 from 5 samples (scipy)", tanks(p, val[:, 1], fit.x), val[:, 2], list(fit.x))

    osc = np.loadtxt("examples/data/oscillator.csv", delimiter=",", skiprows=1)
    with open("examples/data/oscillator.csv") as f:
        header = f.readline().strip().split(",")
    y = osc[:, header.index("y")]
    q = values("examples/models/oscillator.toml")
    x0 = [0.5, 0.0]
    show("oscillator, given x0", oscillator(q, len(y), x0), y, x0)


main()
