"""An independent numpy implementation of sysid's robust particle EM on nlbench.

Written from the description in docs/particle-em.md ("Robust particle EM"), not from
the Rust code: its own simulator, bootstrap filter (systematic resampling at every
step), backward-simulation smoother (FFBSi, exact O(K M) per step, where sysid uses
Tanizaki's sampler of the same law), closed-form M-step, successive halving and
averaged refinement. The starts of one round run as a batch (one numpy array of
shape (starts, particles)).

    python robust_nlbench_numpy.py RUNS [SEED]

prints one JSON line per run (data set r of the study seed, start as in the study:
a, b, c, d times U[0.5, 1.5]) and a summary with the converged fraction (a, b, c, d all
within 10 % of the truth) and its Wilson 95 % interval. The random numbers are numpy's,
so the runs are other draws of the same experiment, compared by converged fraction.

Tool: numpy 2.4.6 (Python 3.11).
"""

import json
import math
import sys
import time

import numpy as np

TRUTH = dict(a=0.5, b=25.0, c=8.0, d=0.05, q=0.01, r=0.1)
T = 1000


def forcing(t):
    """c's regressor of the transition from step t (0-based)."""
    return np.cos(1.2 * (t + 1.0))


def simulate(rng, steps=T):
    x = np.empty(steps)
    x[0] = rng.normal(0.0, 1.0)
    for t in range(steps - 1):
        x[t + 1] = (TRUTH["a"] * x[t] + TRUTH["b"] * x[t] / (1 + x[t] ** 2)
                    + TRUTH["c"] * forcing(t) + rng.normal(0, math.sqrt(TRUTH["q"])))
    y = TRUTH["d"] * x ** 2 + rng.normal(0, math.sqrt(TRUTH["r"]), steps)
    return y


def transition_mean(p, x, t):
    """p: dict of arrays of shape (B, 1); x: (B, M)."""
    return p["a"] * x + p["b"] * x / (1 + x * x) + p["c"] * forcing(t)


def systematic(rng, w):
    """Ancestors for normalised weights w (B, M): systematic resampling per row."""
    B, M = w.shape
    cum = np.cumsum(w, axis=1)
    cum[:, -1] = 1.0
    u = (rng.random((B, 1)) + np.arange(M)) / M
    return np.stack([np.searchsorted(cum[b], u[b]) for b in range(B)])


def log_gauss(v, var):
    return -0.5 * (np.log(2 * np.pi * var) + v * v / var)


def bootstrap(rng, p, y, M, keep=True):
    """Bootstrap filter for a batch of parameter sets; the log-likelihood estimates
    (B,), and if keep, the particles (T, B, M) and normalised weights (T, B, M)."""
    B = p["a"].shape[0]
    x = rng.normal(0.0, 1.0, (B, M))
    xs, ws = [], []
    loglik = np.zeros(B)
    for t in range(len(y)):
        if t > 0:
            x = transition_mean(p, x, t - 1) + rng.normal(size=(B, M)) * np.sqrt(p["q"])
        lw = log_gauss(y[t] - p["d"] * x * x, p["r"])
        top = lw.max(axis=1, keepdims=True)
        w = np.exp(lw - top)
        s = w.sum(axis=1, keepdims=True)
        loglik += (top + np.log(s / M))[:, 0]
        w /= s
        if keep:
            xs.append(x)
            ws.append(w)
        x = np.take_along_axis(x, systematic(rng, w), axis=1)
    return loglik, (np.array(xs), np.array(ws)) if keep else None


def ffbsi(rng, p, history, K):
    """K backward-simulated paths per batch member: (T, B, K)."""
    xs, ws = history
    steps, B, M = xs.shape
    paths = np.empty((steps, B, K))
    cum = np.cumsum(ws[-1], axis=1)
    paths[-1] = np.stack([xs[-1, b][np.searchsorted(cum[b], rng.random(K) * cum[b, -1])]
                          for b in range(B)])
    for t in range(steps - 2, -1, -1):
        mean = transition_mean(p, xs[t], t)                  # (B, M)
        nxt = paths[t + 1]                                     # (B, K)
        lw = np.log(ws[t] + 1e-300)[:, None, :] + log_gauss(
            nxt[:, :, None] - mean[:, None, :], p["q"][:, :, None])  # (B, K, M)
        lw -= lw.max(axis=2, keepdims=True)
        w = np.exp(lw)
        c = np.cumsum(w, axis=2)
        u = rng.random((B, K, 1)) * c[:, :, -1:]
        idx = (c < u).sum(axis=2)
        paths[t] = np.take_along_axis(xs[t], idx, axis=1)
    return paths


def m_step(paths, y, p, hold_r):
    """Closed-form M-step per batch member from the paths (T, B, K)."""
    steps, B, K = paths.shape
    x, xn = paths[:-1], paths[1:]
    t = np.arange(steps - 1)[:, None, None]
    reg = np.stack([x, x / (1 + x * x), np.broadcast_to(forcing(t), x.shape)], axis=-1)
    new = {}
    for b in range(B):
        X = reg[:, b].reshape(-1, 3)
        z = xn[:, b].reshape(-1)
        beta, *_ = np.linalg.lstsq(X, z, rcond=None)
        resid = z - X @ beta
        x2 = paths[:, b] ** 2
        d = (x2 * y[:, None]).sum() / (x2 * x2).sum()
        r = ((y[:, None] - d * x2) ** 2).mean()
        for k, v in zip("abcdqr", [*beta, d, (resid ** 2).mean(), r]):
            new.setdefault(k, []).append(v)
    new = {k: np.array(v)[:, None] for k, v in new.items()}
    if hold_r is not None:
        new["r"] = hold_r.copy()
    return new


def take(p, rows):
    return {k: v[rows] for k, v in p.items()}


def average(iterates):
    return {k: np.mean([it[k] for it in iterates], axis=0) for k in iterates[0]}


def robust(rng, y, start, starts=8, explore=50, hold=10, runaway=10.0, select=1000,
           refine=600, refine_particles=100, explore_particles=50):
    """The robust driver for one data set; the refined averaged estimate."""
    first = {k: np.full((starts, 1), v) for k, v in start.items()}
    first["q"] *= 10.0
    first["r"] *= 10.0
    for k in "abcd":
        first[k][1:, 0] *= rng.uniform(0.5, 1.5, starts - 1)
    limit = first["q"] * runaway
    current = {k: v.copy() for k, v in first.items()}
    averaged = {k: v.copy() for k, v in first.items()}
    live = np.arange(starts)
    done = np.zeros(starts, dtype=int)
    iterations = explore
    while True:
        p = take(current, live)
        tail = []
        alive = np.ones(len(live), dtype=bool)
        for k in range(iterations):
            _, hist = bootstrap(rng, p, y, explore_particles)
            paths = ffbsi(rng, p, hist, explore_particles)
            held = done[live] + k < hold
            p = m_step(paths, y, p, None)
            p["r"][held] = first["r"][live][held]
            if k >= iterations - max(iterations // 4, 1):
                tail.append(p)
            ran = (done[live] + k + 1 >= 50) & (p["q"][:, 0] > limit[live][:, 0])
            alive &= ~ran
        done[live] += iterations
        # the next round continues from the last iterate; the score and the
        # refinement use the average of the last quarter
        for k in p:
            current[k][live] = p[k]
        est = average(tail)
        for k in est:
            averaged[k][live] = est[k]
        seed = int(rng.integers(1 << 62))
        scores = bootstrap(np.random.default_rng(seed), est, y, select, keep=False)[0]
        scores[~alive] = -np.inf
        order = np.argsort(-scores)
        keep = live[order[: max(1, math.ceil(len(live) / 2))]]
        keep = keep[np.isfinite(scores[order[: len(keep)]])] if np.isfinite(scores).any() else keep
        if len(live) <= 1 or len(keep) <= 1:
            live = keep[:1]
            break
        live = keep
        iterations *= 2
    p = take(averaged, live)
    trace = []
    for k in range(refine):
        _, hist = bootstrap(rng, p, y, refine_particles)
        p = m_step(ffbsi(rng, p, hist, refine_particles), y, p, None)
        trace.append(p)
    final = average(trace[len(trace) // 2:])
    return {k: float(v[0, 0]) for k, v in final.items()}


def wilson(k, n, z=1.96):
    p = k / n
    d = 1 + z * z / n
    c = p + z * z / (2 * n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (c - h) / d, (c + h) / d


def main():
    runs = int(sys.argv[1])
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    converged = 0
    for r in range(runs):
        rng = np.random.default_rng([seed, r])
        y = simulate(rng)
        start = dict(TRUTH)
        for k in "abcd":
            start[k] = TRUTH[k] * rng.uniform(0.5, 1.5)
        began = time.time()
        est = robust(rng, y, start)
        ok = all(abs(est[k] - TRUTH[k]) <= 0.1 * TRUTH[k] for k in "abcd")
        converged += ok
        print(json.dumps({"run": r, "start": start, "estimate": est, "converged": ok,
                          "seconds": time.time() - began}), flush=True)
    lo, hi = wilson(converged, runs)
    print(json.dumps({"runs": runs, "converged": converged, "wilson95": [lo, hi],
                      "numpy": np.__version__}))


if __name__ == "__main__":
    main()
