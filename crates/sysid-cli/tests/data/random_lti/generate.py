# 20 random stable systems (orders 2 and 3, 1 or 2 inputs and outputs), T = 500, simulated
# with noise by numpy (independent of sysid); run from this folder (numpy 2.4.6).
import numpy as np, json, sys
rng = np.random.default_rng(58)
T = 500
for k in range(20):
    n = 2 + k % 2
    m = 1 + (k // 2) % 2
    p = 1 + (k // 4) % 2
    while True:
        # eigenvalues: a real one and a pair, or reals, moduli in [0.3, 0.95]
        M = rng.normal(size=(n, n))
        ev = np.linalg.eigvals(M)
        A = M / np.max(np.abs(ev)) * rng.uniform(0.5, 0.95)
        if np.min(np.abs(np.linalg.eigvals(A))) > 0.05:
            break
    B = rng.normal(size=(n, m))
    C = rng.normal(size=(p, n))
    D = rng.normal(size=(p, m)) * 0.5
    L = rng.normal(size=(n, n)) * 0.3
    Q = L @ L.T + 0.05 * np.eye(n)
    R = np.diag(rng.uniform(0.05, 0.3, size=p))
    u = rng.normal(size=(T, m))
    x = np.zeros(n)
    # start in the stationary law (no input before the record)
    P = Q.copy()
    for _ in range(2000):
        P = A @ P @ A.T + Q
    x = np.linalg.cholesky(P) @ rng.normal(size=n)
    y = np.zeros((T, p))
    for t in range(T):
        y[t] = C @ x + D @ u[t] + np.linalg.cholesky(R) @ rng.normal(size=p)
        x = A @ x + B @ u[t] + np.linalg.cholesky(Q) @ rng.normal(size=n)
    with open(f"./sys{k:02d}.csv", "w") as f:
        f.write("t," + ",".join(f"u{i+1}" for i in range(m)) + "," + ",".join(f"y{i+1}" for i in range(p)) + "\n")
        for t in range(T):
            f.write(f"{t+1}," + ",".join(f"{v:.7g}" for v in u[t]) + "," + ",".join(f"{v:.7g}" for v in y[t]) + "\n")
    json.dump({"n": n, "m": m, "p": p, "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D.tolist(), "Q": Q.tolist(), "R": R.tolist()}, open(f"./sys{k:02d}.truth.json", "w"))
print("ok")
