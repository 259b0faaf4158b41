# Reference maxima of the log-likelihood that `sysid fit lti` reports, by scipy,
# independent of sysid: the exact Gaussian log-likelihood of the record under
# x' = A x + B u + w, y = C x + D u + h + e, w ~ N(0, Q) (full), e ~ N(0, R) (diagonal
# for several outputs), x_1 ~ N(mu, P1) with P1 the stationary covariance and mu the
# steady state of the mean input over the model's memory H: the input response's energy
# centroid L = tr(C V C') / tr(C W C') (W = A W A' + B B', V = A V A' + A W A') as the
# steps in which a first-order system with that centroid falls to 1 %, clamped to
# [1, T], the window's edge smoothed (input k weighs s(H - k), s(x) = 3x^2 - 2x^3 on
# [0, 1]). h is held at the written model's value (the fit holds N4SID's). A
# covariance-form Kalman filter over N models at once (for the central differences).
# Run from this folder: `python reference.py FITS` (FITS holds sysNN.json written by
# `sysid fit lti --order n` at its defaults) writes reference.json.
import json, sys, numpy as np
from scipy.optimize import minimize
from scipy.linalg import solve_discrete_lyapunov

def read(path):
    rows = open(path).read().strip().split("\n")
    head = rows[0].split(",")
    data = np.array([[float(v) for v in r.split(",")] for r in rows[1:]])
    ui = [i for i, h in enumerate(head) if h.startswith("u")]
    yi = [i for i, h in enumerate(head) if h.startswith("y")]
    return data[:, ui], data[:, yi]

def loglik_batch(A, B, C, D, h, Q, R, u, y):
    """log-likelihoods of N models at once (arrays with a leading model axis)."""
    N, n, _ = A.shape; T, p = y.shape
    out = np.full(N, -np.inf)
    rho = np.max(np.abs(np.linalg.eigvals(A)), axis=1)
    ok = rho < 1
    if not ok.any():
        return out
    A, B, C, D, Q, R, rho = A[ok], B[ok], C[ok], D[ok], Q[ok], R[ok], rho[ok]
    M = A.shape[0]
    H = np.zeros(M)
    for i in range(M):
        W = solve_discrete_lyapunov(A[i], B[i] @ B[i].T)
        V = solve_discrete_lyapunov(A[i], A[i] @ W @ A[i].T)
        energy = np.trace(C[i] @ W @ C[i].T); moment = np.trace(C[i] @ V @ C[i].T)
        if energy > 0 and moment > 0:
            L = moment / energy
            H[i] = 2 * np.log(0.01) / np.log(L / (1 + L))
    H = np.clip(H, 1.0, T)
    ubar = np.zeros((M, u.shape[1]))
    k = np.arange(T)
    for i in range(M):
        xk = H[i] - k
        w = np.where(xk >= 1, 1.0, np.where(xk <= 0, 0.0, xk * xk * (3 - 2 * xk)))
        ubar[i] = (w[:, None] * u).sum(axis=0) / w.sum()
    x = np.linalg.solve(np.eye(n)[None] - A, np.einsum("kij,kj->ki", B, ubar)[..., None])[..., 0]
    P = np.stack([solve_discrete_lyapunov(A[i], Q[i]) for i in range(M)])
    At = np.transpose(A, (0, 2, 1)); Ct = np.transpose(C, (0, 2, 1))
    ll = np.zeros(M)
    Du = np.einsum("kij,tj->tki", D, u)
    Bu = np.einsum("kij,tj->tki", B, u)
    for t in range(T):
        F = C @ P @ Ct + R
        e = y[t][None] - np.einsum("kij,kj->ki", C, x) - Du[t] - h[None]
        Lf = np.linalg.cholesky(F)
        z = np.linalg.solve(Lf, e[..., None])[..., 0]
        ll += -0.5 * (p * np.log(2 * np.pi) + 2 * np.sum(np.log(np.diagonal(Lf, axis1=1, axis2=2)), axis=1) + np.sum(z * z, axis=1))
        PCt = P @ Ct
        K = np.transpose(np.linalg.solve(F, np.transpose(PCt, (0, 2, 1))), (0, 2, 1))
        xf = x + np.einsum("kij,kj->ki", K, e)
        Pf = P - K @ F @ np.transpose(K, (0, 2, 1))
        x = np.einsum("kij,kj->ki", A, xf) + Bu[t]
        P = A @ Pf @ At + Q
        P = 0.5 * (P + np.transpose(P, (0, 2, 1)))
    out[ok] = ll
    return out

def loglik(A, B, C, D, h, Q, R, u, y):
    return loglik_batch(A[None], B[None], C[None], D[None], h, Q[None], R[None], u, y)[0]

def pack(A, B, C, D, Q, R):
    n = A.shape[0]; p = C.shape[0]
    L = np.linalg.cholesky(Q)
    li = np.tril_indices(n)
    Lv = L[li].copy()
    diag = li[0] == li[1]
    Lv[diag] = np.log(Lv[diag])
    return np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel(), Lv, np.log(np.diag(R))])

def unpack(x, n, m, p):
    k = 0
    def take(r, c):
        nonlocal k
        v = x[k:k + r * c].reshape(r, c); k += r * c; return v
    A = take(n, n); B = take(n, m); C = take(p, n); D = take(p, m)
    li = np.tril_indices(n); nl = len(li[0])
    Lv = x[k:k + nl].copy(); k += nl
    diag = li[0] == li[1]
    Lv[diag] = np.exp(Lv[diag])
    L = np.zeros((n, n)); L[li] = Lv
    R = np.diag(np.exp(x[k:k + p]))
    return A, B, C, D, L @ L.T, R

def maximise(x0, n, m, p, h, u, y):
    def models(X):
        parts = [unpack(x, n, m, p) for x in X]
        return [np.stack([q[i] for q in parts]) for i in range(6)]
    def values(X):
        A, B, C, D, Q, R = models(X)
        return loglik_batch(A, B, C, D, h, Q, R, u, y)
    def fg(x):
        k = len(x)
        steps = 1e-6 * np.maximum(np.abs(x), 1e-2)
        X = np.vstack([x[None], x[None] + np.diag(steps), x[None] - np.diag(steps)])
        v = values(X)
        if not np.isfinite(v[0]):
            return np.inf, np.zeros(k)
        up, down = v[1:k + 1], v[k + 1:]
        g = np.where(np.isfinite(up) & np.isfinite(down), (up - down) / (2 * steps), 0.0)
        return -v[0], -g
    best = minimize(fg, x0, jac=True, method="BFGS", options={"gtol": 1e-6, "maxiter": 5000})
    for _ in range(5):
        nxt = minimize(fg, best.x, jac=True, method="BFGS", options={"gtol": 1e-6, "maxiter": 5000})
        improved = nxt.fun < best.fun - 1e-7
        if nxt.fun < best.fun:
            best = nxt
        if not improved:
            break
    return -best.fun, best

def reference(k, fitted):
    u, y = read(f"sys{k}.csv")
    truth = json.load(open(f"sys{k}.truth.json"))
    model = json.load(open(fitted))
    n, m, p = truth["n"], truth["m"], truth["p"]
    h = np.array(model["h"], dtype=float).ravel()
    arr = lambda key: np.array(model[key], dtype=float).reshape(len(model[key]), -1)
    ours = loglik(arr("a"), arr("b"), arr("c"), arr("d"), h, arr("q"), arr("r"), u, y)
    T = {key: np.array(truth[key]) for key in "ABCDQR"}
    best, res = maximise(pack(T["A"], T["B"], T["C"], T["D"], T["Q"], T["R"]), n, m, p, h, u, y)
    q0 = arr("q") + 1e-12 * np.eye(n)
    from_ours, _ = maximise(pack(arr("a"), arr("b"), arr("c"), arr("d"), q0,
                                 np.maximum(arr("r"), 1e-300)), n, m, p, h, u, y)
    R = unpack(res.x, n, m, p)[5]
    return {"system": k, "order": n, "h": h.tolist(), "ours": ours, "at_truth": 0.0 + loglik(
                T["A"], T["B"], T["C"], T["D"], h, T["Q"], T["R"], u, y),
            "max_from_truth": best, "max_from_ours": from_ours,
            "min_r_over_variance_at_max_from_truth": float(np.min(np.diag(R) / y.var(axis=0)))}

if __name__ == "__main__":
    # usage: python reference.py DIR  (DIR holds sysNN.json written by `sysid fit lti`)
    import scipy
    from concurrent.futures import ProcessPoolExecutor
    fits = sys.argv[1]
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(reference, [f"{k:02d}" for k in range(20)],
                             [f"{fits}/sys{k:02d}.json" for k in range(20)]))
    json.dump({"tool": f"numpy {np.__version__}, scipy {scipy.__version__} (BFGS, central differences)",
               "systems": rows}, open("reference.json", "w"), indent=1)
