"""Evaluates the exact log-likelihood of EM iterates at 50 significant digits.

Independent check of the likelihood decrease that `examples/em_decrease.rs` reports
(lti2x2, T = 200, seed 3, near iteration 5276): a conventional Kalman filter (no
square roots) in mpmath arithmetic, so the rounding of the f64 filters plays no part.

    DUMP=/tmp/emdec cargo run --release -p sysid --example em_decrease
    python em_decrease_mpmath.py /tmp/emdec

Tool: mpmath 1.3.0 (Python 3.11). Prints one line per iterate.
"""

import json
import pathlib
import sys

import mpmath as mp

mp.mp.dps = 50


def matrix(rows):
    return mp.matrix([[mp.mpf(repr(v)) for v in row] for row in rows])


def loglik(model, y, u):
    a, b, c, d = (matrix(model[k]) for k in "abcd")
    q, r, s = matrix(model["q"]), matrix(model["r"]), matrix(model["s"])
    h = matrix(model["h"])
    x = matrix(model["mu"])
    p = matrix(model["p1"])
    n, m = a.rows, len(u)
    total = mp.mpf(0)
    steps = len(y[0])
    for t in range(steps):
        yt = mp.matrix([[mp.mpf(repr(row[t]))] for row in y])
        ut = mp.matrix([[mp.mpf(repr(row[t]))] for row in u]) if m else None
        pred = c * x + h + (d * ut if m else 0)
        e = yt - pred
        sv = c * p * c.T + r
        sv = (sv + sv.T) / 2
        # Cov(x_{t+1}, y_t | past) = A P C' + S; gain for the one-step predictor
        cross = a * p * c.T + s
        sinv_e = mp.lu_solve(sv, e)
        total += -mp.mpf(len(e)) / 2 * mp.log(2 * mp.pi) - mp.log(mp.det(sv)) / 2 - (e.T * sinv_e)[0] / 2
        k = cross * mp.inverse(sv)
        x = a * x + (b * ut if m else 0) + k * e
        p = a * p * a.T + q - k * sv * k.T
        p = (p + p.T) / 2
    return total


def main():
    folder = pathlib.Path(sys.argv[1])
    data = json.loads((folder / "data.json").read_text())
    y, u = data["y"], data["u"]
    previous = None
    for path in sorted(folder.glob("theta_*.json"), key=lambda p: int(p.stem.split("_")[1])):
        model = json.loads(path.read_text())
        value = loglik(model, y, u)
        change = "" if previous is None else f"  change {mp.nstr(value - previous, 6)}"
        print(f"{path.stem}: {mp.nstr(value, 20)}{change}")
        previous = value


if __name__ == "__main__":
    main()
