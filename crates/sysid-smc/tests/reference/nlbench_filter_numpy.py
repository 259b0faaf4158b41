"""Particle filters for nlbench in numpy: an independent check of the log-likelihood
estimates behind docs/particle-em.md (why M = 50 fails the seed-000 study).

    cargo run --release -p sysid-cli -- simulate nlbench --steps 1000 --seed 1 --out nl.csv
    python nlbench_filter_numpy.py nl.csv          # M sweep and two filter variants
    python nlbench_filter_numpy.py --noise-sweep   # M = 50 at other noise variances

Model (ALGORITHMS.md 3, 1-based t): x_1 ~ N(0, 1), y_t = d x_t^2 + e_t,
x_{t+1} = a x_t + b x_t / (1 + x_t^2) + c cos(1.2 t) + w_t, w ~ N(0, q), e ~ N(0, r),
a, b, c, d = 0.5, 25, 8, 0.05 and by default q, r = 0.01, 0.1.
Filters: bootstrap with systematic resampling at every step (the E-step's filter);
the same resampling only when ESS < M / 2; an auxiliary filter that resamples with the
look-ahead weights N(y_{t+1}; d m^2 + d q, r + 4 d^2 m^2 q), m the transition mean.
Each prints log-likelihood estimates at the truth. Tool: numpy 2.4.6 (Python 3.11).
"""

import sys

import numpy as np

A, B, C, D = 0.5, 25.0, 8.0, 0.05


def transition_mean(x, t):
    return A * x + B * x / (1 + x * x) + C * np.cos(1.2 * t)


def log_sum_exp(v):
    m = v.max()
    return m + np.log(np.exp(v - m).sum())


def log_observation(y, x, r):
    return -0.5 * (y - D * x * x) ** 2 / r - 0.5 * np.log(2 * np.pi * r)


def systematic(weights, rng):
    n = len(weights)
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(weights), u), n - 1)


def bootstrap(y, particles, rng, q=0.01, r=0.1, ess_fraction=1.0):
    """Bootstrap filter; resamples when ESS < ess_fraction * M (1: at every step)."""
    x = rng.normal(size=particles)
    log_w = np.full(particles, -np.log(particles))
    loglik = 0.0
    for t in range(1, len(y) + 1):
        if t > 1:
            x = transition_mean(x, t - 1) + np.sqrt(q) * rng.normal(size=particles)
        v = log_w + log_observation(y[t - 1], x, r)
        total = log_sum_exp(v)
        loglik += total
        log_w = v - total
        w = np.exp(log_w)
        if ess_fraction >= 1.0 or 1.0 / (w * w).sum() < ess_fraction * particles:
            x = x[systematic(w, rng)]
            log_w = np.full(particles, -np.log(particles))
    return loglik


def auxiliary(y, particles, rng, q=0.01, r=0.1):
    x = rng.normal(size=particles)
    lo = log_observation(y[0], x, r)
    loglik = log_sum_exp(lo) - np.log(particles)
    log_w = lo - log_sum_exp(lo)
    for t in range(2, len(y) + 1):
        m = transition_mean(x, t - 1)
        s2 = r + 4 * D * D * m * m * q
        look = -0.5 * (y[t - 1] - D * m * m - D * q) ** 2 / s2 - 0.5 * np.log(2 * np.pi * s2)
        v = log_w + look
        first = log_sum_exp(v)
        idx = systematic(np.exp(v - first), rng)
        x = m[idx] + np.sqrt(q) * rng.normal(size=particles)
        lw = log_observation(y[t - 1], x, r) - look[idx]
        loglik += first + log_sum_exp(lw) - np.log(particles)
        log_w = lw - log_sum_exp(lw)
    return loglik


def simulate(steps, rng, q, r):
    x = rng.normal()
    y = np.empty(steps)
    for t in range(1, steps + 1):
        y[t - 1] = D * x * x + np.sqrt(r) * rng.normal()
        x = transition_mean(x, t) + np.sqrt(q) * rng.normal()
    return y


def summary(label, values):
    values = np.array(values)
    print(
        f"{label}: median {np.median(values):9.1f}, min {values.min():9.1f}, "
        f"max {values.max():9.1f} ({len(values)} replicates)"
    )


def data_file(path):
    y = np.loadtxt(path, delimiter=",", skiprows=1, usecols=1)
    rng = np.random.default_rng(2026)
    for particles, replicates in [(50, 20), (200, 20), (500, 20), (10000, 4)]:
        summary(f"bootstrap M = {particles:5}", [bootstrap(y, particles, rng) for _ in range(replicates)])
    summary("ESS < M/2, M =    50", [bootstrap(y, 50, rng, ess_fraction=0.5) for _ in range(20)])
    summary("auxiliary, M =    50", [auxiliary(y, 50, rng) for _ in range(20)])


def noise_sweep():
    """M = 50 against M = 5000 on data simulated at each (q, r): log-likelihood deficits."""
    for q, r in [(0.01, 0.1), (0.1, 0.1), (1.0, 0.1), (0.01, 0.01), (0.1, 0.01), (10.0, 1.0)]:
        deficits = []
        for seed in range(4):
            rng = np.random.default_rng(seed)
            y = simulate(1000, rng, q, r)
            reference = bootstrap(y, 5000, rng, q, r)
            deficits += [bootstrap(y, 50, rng, q, r) - reference for _ in range(4)]
        summary(f"q = {q:5}, r = {r:4}: M = 50 minus M = 5000", deficits)


if __name__ == "__main__":
    if sys.argv[1] == "--noise-sweep":
        noise_sweep()
    else:
        data_file(sys.argv[1])
