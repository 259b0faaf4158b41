"""Reference values for tests/statsmodels_reference.rs, made with statsmodels 0.15.0 and
numpy 2.4.6 (run: python statsmodels_kalman.py). Prints the values pinned in the test."""
import numpy as np, statsmodels.api as sm, json
np.set_printoptions(precision=17)

def run(A,B,C,D,h,Q,R,mu,P1,u,y):
    p, T = y.shape
    n = A.shape[0]
    mod = sm.tsa.statespace.MLEModel(y.T, k_states=n)
    mod['design'] = C
    mod['transition'] = A
    mod['selection'] = np.eye(n)
    mod['state_cov'] = Q
    mod['obs_cov'] = R
    mod['state_intercept'] = B @ u          # c_t enters x_{t+1}
    mod['obs_intercept'] = D @ u + h[:, None]
    mod.ssm.initialize_known(mu, P1)
    res = mod.ssm.smooth()
    return float(res.llf), res.smoothed_state, res.smoothed_state_cov

t = np.arange(1, 51)
y = (2*np.sin(0.37*t) + 0.3*np.cos(2.1*t))[None, :].copy()
y[0, [9, 10, 29]] = np.nan
ll_a, xs_a, ps_a = run(np.array([[0.9]]), np.zeros((1,0)), np.array([[1.0]]), np.zeros((1,0)), np.zeros(1),
                       np.array([[1.0]]), np.array([[0.5]]), np.zeros(1), np.array([[1.0]]), np.zeros((0,50)), y)

t = np.arange(1, 41)
A = np.array([[0.7, 0.2], [-0.1, 0.5]]); B = np.array([[1.0], [0.5]])
C = np.array([[1.0, 0.0], [0.5, 1.0]]); D = np.array([[0.2], [0.0]]); h = np.array([0.3, -0.1])
Q = np.array([[0.5, 0.1], [0.1, 0.3]]); R = np.array([[0.2, 0.05], [0.05, 0.1]])
mu = np.array([0.1, -0.2]); P1 = np.array([[1.0, 0.2], [0.2, 2.0]])
u = np.cos(0.5*t)[None, :]
y = np.vstack([np.sin(0.2*t) + 0.4*np.cos(0.9*t), 0.5*np.cos(0.3*t) - 0.2*np.sin(1.3*t)])
y[1, 4:8] = np.nan; y[0, 19] = np.nan; y[:, 32] = np.nan
ll_b, xs_b, ps_b = run(A,B,C,D,h,Q,R,mu,P1,u,y)
print(json.dumps({"lgss_loglik": ll_a, "lgss_x": [xs_a[0,0], xs_a[0,9], xs_a[0,49]], "lgss_p": [ps_a[0,0,0], ps_a[0,0,9], ps_a[0,0,49]],
  "b_loglik": ll_b, "b_x1": list(xs_b[:,0]), "b_x20": list(xs_b[:,19]), "b_x33": list(xs_b[:,32]), "b_x40": list(xs_b[:,39]),
  "b_p33": [ps_b[0,0,32], ps_b[0,1,32], ps_b[1,1,32]]}, indent=1))
