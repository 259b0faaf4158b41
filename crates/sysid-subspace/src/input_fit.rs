//! `B`, `D` and the initial state by linear least squares on the simulated output, for
//! given `A` and `C`.

use nalgebra::{DMatrix, DVector};

/// The least-squares input matrices and initial state.
#[derive(Debug, Clone)]
pub(crate) struct InputFit {
    pub b: DMatrix<f64>,
    pub d: DMatrix<f64>,
    /// The initial state of the record (a nuisance parameter of the fit).
    #[cfg_attr(
        not(test),
        expect(
            dead_code,
            reason = "the model's mu describes a new record, not this one"
        )
    )]
    pub x0: DVector<f64>,
    /// The regressors were numerically collinear (e.g. two identical inputs): the
    /// minimum-norm solution was taken.
    pub rank_deficient: bool,
}

/// Time steps whose regressor rows are factored together.
const CHUNK: usize = 512;

/// Minimises `sum_t ||y_t - C x_t - D u_t||^2` over `B`, `D` and `x_0`, where
/// `x_{t+1} = A x_t + B u_t` (the noise-free simulation). The simulated output is linear
/// in `(x_0, B, D)`: `y_t = C A^t x_0 + sum_{k<t} C A^{t-1-k} B u_k + D u_t`; its
/// regressors are propagated step by step and their rows are absorbed into a running
/// QR factor, a chunk at a time, so memory does not grow with `T`. The solution is the
/// minimum-norm one when the regressors are collinear.
///
/// `u` (`m x T`) and `y` (`p x T`) are the record with its means removed. `A` must be
/// stable: the regressors of an unstable `A` grow without bound.
pub(crate) fn fit_inputs(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    u: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> InputFit {
    let (n, m, p, t_len) = (a.nrows(), u.nrows(), c.nrows(), y.ncols());
    let k = n + n * m + p * m;
    // running upper-triangular factor of [regressors | y]
    let mut r_factor = faer::Mat::<f64>::zeros(0, k + 1);
    // S_b(t) = sum_{s<t} A^{t-1-s} u_b(s), whose column a is the state response to B[a, b]
    let mut responses = vec![DMatrix::<f64>::zeros(n, n); m];
    let mut observability = c.clone();
    let mut t0 = 0;
    while t0 < t_len {
        let steps = CHUNK.min(t_len - t0);
        let mut block = faer::Mat::<f64>::zeros(r_factor.nrows() + steps * p, k + 1);
        for row in 0..r_factor.nrows() {
            for col in row..k + 1 {
                block[(row, col)] = r_factor[(row, col)];
            }
        }
        let base = r_factor.nrows();
        for step in 0..steps {
            let t = t0 + step;
            let outputs: Vec<DMatrix<f64>> = responses.iter().map(|s| c * s).collect();
            for out in 0..p {
                let row = base + step * p + out;
                for col in 0..n {
                    block[(row, col)] = observability[(out, col)];
                }
                for (input, response) in outputs.iter().enumerate() {
                    for state in 0..n {
                        block[(row, n + input * n + state)] = response[(out, state)];
                    }
                    block[(row, n + n * m + input * p + out)] = u[(input, t)];
                }
                block[(row, k)] = y[(out, t)];
            }
            for (input, response) in responses.iter_mut().enumerate() {
                let mut next = a * &*response;
                for state in 0..n {
                    next[(state, state)] += u[(input, t)];
                }
                *response = next;
            }
            observability = &observability * a;
        }
        r_factor = block.qr().thin_R().to_owned();
        t0 += steps;
    }
    let rows = r_factor.nrows().min(k);
    let r_theta = DMatrix::from_fn(rows, k, |i, j| if j >= i { r_factor[(i, j)] } else { 0.0 });
    let rhs = DVector::from_fn(rows, |i, _| r_factor[(i, k)]);
    let svd = r_theta.svd(true, true);
    let s_max = svd.singular_values.max();
    let tol = k as f64 * f64::EPSILON * s_max * 1e3;
    let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
    let theta = svd.solve(&rhs, tol).unwrap_or_else(|_| DVector::zeros(k));
    InputFit {
        x0: theta.rows(0, n).clone_owned(),
        b: DMatrix::from_fn(n, m, |state, input| theta[n + input * n + state]),
        d: DMatrix::from_fn(p, m, |out, input| theta[n + n * m + input * p + out]),
        rank_deficient: rank < k,
    }
}

#[cfg(test)]
mod tests {
    use super::fit_inputs;
    use nalgebra::{DMatrix, dmatrix};

    /// The fit recovers a noise-free simulation's B, D and x0 exactly, across chunk
    /// boundaries (T > CHUNK).
    #[test]
    fn recovers_a_noise_free_system() {
        let a = dmatrix![0.9, 0.2; -0.1, 0.7];
        let b = dmatrix![1.0, 0.0; 0.5, -1.0];
        let c = dmatrix![1.0, 0.0; 0.3, 1.0; 0.0, 2.0];
        let d = dmatrix![0.0, 0.1; 0.2, 0.0; 0.0, 0.0];
        let t_len = 1300;
        let u = DMatrix::from_fn(2, t_len, |i, t| ((t * (3 + i)) as f64 * 0.7).sin());
        let mut x = nalgebra::dvector![1.0, -2.0];
        let mut y = DMatrix::zeros(3, t_len);
        for t in 0..t_len {
            let ut = u.column(t);
            y.set_column(t, &(&c * &x + &d * ut));
            x = &a * &x + &b * ut;
        }
        let fit = fit_inputs(&a, &c, &u, &y);
        assert!((fit.b - b).amax() < 1e-9);
        assert!((fit.d - d).amax() < 1e-9);
        assert!((fit.x0 - nalgebra::dvector![1.0, -2.0]).amax() < 1e-9);
        assert!(!fit.rank_deficient);
    }

    #[test]
    fn collinear_inputs_are_flagged() {
        let a = dmatrix![0.5];
        let c = dmatrix![1.0];
        let row = DMatrix::from_fn(1, 200, |_, t| (t as f64 * 0.3).sin());
        let u = DMatrix::from_fn(2, 200, |_, t| row[(0, t)]);
        let y = DMatrix::from_fn(1, 200, |_, t| (t as f64 * 0.3).cos());
        let fit = fit_inputs(&a, &c, &u, &y);
        assert!(fit.rank_deficient);
        assert!(fit.b.iter().all(|v| v.is_finite()));
        // minimum norm: the two identical inputs share the gain equally
        assert!((fit.b[(0, 0)] - fit.b[(0, 1)]).abs() < 1e-8);
    }
}
