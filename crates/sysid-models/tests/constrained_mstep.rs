//! The constrained M-step of affine EM (a coefficient shared by two rows, bounds, a
//! noise variance held inside an estimated block) against references computed from the
//! raw simulated data by other routes: a weighted least-squares solve of the stacked
//! rows (QR), a golden-section search of the profile likelihood, and the unconstrained
//! M-step where the constraints are void.
//!
//! The statistics are the exact second moments of one known path (what the smoother's
//! statistics are when every particle sits on the truth), so the M-step's answer is a
//! regression on the data and the references need no particle method.

use nalgebra::{DMatrix, DVector};
use sysid_em::affine::{
    AffineConstraints, AffineEmError, AffineEmSpec, AffineModel, AffineParams, AffineStatistics,
    CoefficientSlot, TiedCoefficient, m_step,
};
use sysid_em::linear::Covariance;
use sysid_models::GaussianAffineSmc;
use sysid_smc::stream;

/// Two tanks: `h1' = h1 + k u - a1 s1`, `h2' = h2 + a1 s1 - a2 s2` with `s = sqrt(h+)`,
/// `y = h2`; regressors `[h1, h2, u, -s1, s1, -s2]`, the level terms held at 1.
#[derive(Clone)]
struct Tanks {
    constraints: Option<AffineConstraints>,
}

const R: usize = 6;

impl AffineModel for Tanks {
    type Smc = GaussianAffineSmc<Tanks>;
    fn state_dim(&self) -> usize {
        2
    }
    fn output_dim(&self) -> usize {
        1
    }
    fn regressor_dim(&self) -> usize {
        R
    }
    fn regressors(&self, _t: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
        let (s1, s2) = (x[0].max(0.0).sqrt(), x[1].max(0.0).sqrt());
        out.copy_from_slice(&[x[0], x[1], u[0], -s1, s1, -s2]);
    }
    fn state_structure(&self) -> Vec<Vec<usize>> {
        vec![vec![0, 2, 3], vec![1, 4, 5]]
    }
    fn output_structure(&self) -> Vec<Vec<usize>> {
        vec![vec![1]]
    }
    fn held_state_coefficients(&self) -> Vec<Vec<usize>> {
        vec![vec![0], vec![1]]
    }
    fn held_output_coefficients(&self) -> Vec<Vec<usize>> {
        vec![vec![1]]
    }
    fn constraints(&self) -> Option<AffineConstraints> {
        self.constraints.clone()
    }
    fn smc_model(&self, params: &AffineParams) -> Result<Self::Smc, AffineEmError> {
        GaussianAffineSmc::new(self.clone(), params)
    }
}

fn state(row: usize, col: usize) -> CoefficientSlot {
    CoefficientSlot::State { row, col }
}

fn tie(slots: Vec<CoefficientSlot>, lower: f64, upper: f64) -> TiedCoefficient {
    TiedCoefficient {
        slots,
        lower,
        upper,
    }
}

/// `k`, `a1` (both rows), `a2` with the given bounds on `a1`.
fn tied(a1_lower: f64, a1_upper: f64, held_process: Vec<usize>) -> Tanks {
    let inf = f64::INFINITY;
    Tanks {
        constraints: Some(AffineConstraints {
            coefficients: vec![
                tie(vec![state(0, 2)], 0.0, inf),
                tie(vec![state(0, 3), state(1, 4)], a1_lower, a1_upper),
                tie(vec![state(1, 5)], 0.0, inf),
            ],
            held_process_variances: held_process,
            held_measurement_variances: Vec::new(),
        }),
    }
}

struct Record {
    x: Vec<[f64; 2]>,
    u: Vec<f64>,
    y: Vec<f64>,
}

/// `T` steps of the tanks at k 0.5, a1 0.3, a2 0.25, process variances `q`, r 0.01.
fn simulate(steps: usize, q: [f64; 2]) -> Record {
    use rand::RngExt;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = stream(11, 0);
    let (k, a1, a2) = (0.5, 0.3, 0.25);
    let mut x = [2.8, 4.0];
    let mut record = Record {
        x: Vec::new(),
        u: Vec::new(),
        y: Vec::new(),
    };
    for _ in 0..steps {
        let u: f64 = if rng.random_bool(0.05) { 0.2 } else { 1.0 } * rng.random_range(0.5..1.5);
        let e: f64 = StandardNormal.sample(&mut rng);
        record.x.push(x);
        record.u.push(u);
        record.y.push(x[1] + 0.1 * e);
        let (s1, s2) = (x[0].max(0.0).sqrt(), x[1].max(0.0).sqrt());
        let w: [f64; 2] = [
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        ];
        x = [
            x[0] + k * u - a1 * s1 + q[0].sqrt() * w[0],
            x[1] + a1 * s1 - a2 * s2 + q[1].sqrt() * w[1],
        ];
    }
    record
}

/// The exact statistics of the record's path.
fn statistics(model: &Tanks, record: &Record) -> AffineStatistics {
    let mut stats = AffineStatistics::zeros(R, 2, 1);
    let mut alpha = [0.0; R];
    for t in 0..record.x.len() {
        model.regressors(t, &record.x[t], &[record.u[t]], &mut alpha);
        let outer = |v: &[f64]| DMatrix::from_fn(v.len(), v.len(), |i, j| v[i] * v[j]);
        if t + 1 < record.x.len() {
            let mut v = alpha.to_vec();
            v.extend_from_slice(&record.x[t + 1]);
            stats.state += outer(&v);
            stats.state_steps += 1.0;
        }
        let mut v = alpha.to_vec();
        v.push(record.y[t]);
        stats.output += outer(&v);
        stats.output_steps += 1.0;
    }
    stats.initial_mean = DVector::from_row_slice(&record.x[0]);
    stats.initial_second_moment = &stats.initial_mean * stats.initial_mean.transpose();
    stats
}

fn start(q: [f64; 2]) -> AffineParams {
    let mut beta_x = DMatrix::zeros(2, R);
    beta_x[(0, 0)] = 1.0;
    beta_x[(1, 1)] = 1.0;
    for (col, v) in [(2, 0.8), (3, 0.15)] {
        beta_x[(0, col)] = v;
    }
    for (col, v) in [(4, 0.15), (5, 0.4)] {
        beta_x[(1, col)] = v;
    }
    let mut beta_y = DMatrix::zeros(1, R);
    beta_y[(0, 1)] = 1.0;
    AffineParams {
        beta_x,
        beta_y,
        pi_x: DMatrix::from_diagonal(&DVector::from_row_slice(&q)),
        pi_y: DMatrix::from_element(1, 1, 0.05),
        mu: DVector::from_row_slice(&[2.8, 4.0]),
        p1: DMatrix::identity(2, 2) * 0.1,
    }
}

fn spec(pi_x: Covariance) -> AffineEmSpec {
    AffineEmSpec {
        pi_x,
        pi_y: Covariance::Diagonal,
        ..AffineEmSpec::default()
    }
}

/// Row `i`'s residuals `x_{t+1,i} - h_i - coefficients . regressors` on the raw data
/// at `(k, a1, a2)`.
fn residuals(record: &Record, theta: [f64; 3], row: usize) -> Vec<f64> {
    let [k, a1, a2] = theta;
    (0..record.x.len() - 1)
        .map(|t| {
            let (x, u, next) = (record.x[t], record.u[t], record.x[t + 1]);
            let (s1, s2) = (x[0].max(0.0).sqrt(), x[1].max(0.0).sqrt());
            if row == 0 {
                next[0] - x[0] - k * u + a1 * s1
            } else {
                next[1] - x[1] - a1 * s1 + a2 * s2
            }
        })
        .collect()
}

fn mean_square(v: &[f64]) -> f64 {
    v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64
}

/// Weighted least squares of the stacked rows with known variances, by QR of the
/// raw design (no moment matrix).
fn weighted_least_squares(record: &Record, q: [f64; 2]) -> [f64; 3] {
    let steps = record.x.len() - 1;
    let mut design = DMatrix::zeros(2 * steps, 3);
    let mut target = DVector::zeros(2 * steps);
    for t in 0..steps {
        let (x, u, next) = (record.x[t], record.u[t], record.x[t + 1]);
        let (s1, s2) = (x[0].max(0.0).sqrt(), x[1].max(0.0).sqrt());
        let (w0, w1) = (1.0 / q[0].sqrt(), 1.0 / q[1].sqrt());
        design[(t, 0)] = u * w0;
        design[(t, 1)] = -s1 * w0;
        target[t] = (next[0] - x[0]) * w0;
        design[(steps + t, 1)] = s1 * w1;
        design[(steps + t, 2)] = -s2 * w1;
        target[steps + t] = (next[1] - x[1]) * w1;
    }
    let qr = design.qr();
    let rhs = qr.q().transpose() * target;
    let solved = qr.r().solve_upper_triangular(&rhs).unwrap();
    [solved[0], solved[1], solved[2]]
}

/// Each row's own coefficient given `a1`: `k` and `a2` by one-regressor least squares.
fn given_a1(record: &Record, a1: f64) -> [f64; 3] {
    let (mut kuu, mut kuz, mut ass, mut asz) = (0.0, 0.0, 0.0, 0.0);
    for t in 0..record.x.len() - 1 {
        let (x, u, next) = (record.x[t], record.u[t], record.x[t + 1]);
        let (s1, s2) = (x[0].max(0.0).sqrt(), x[1].max(0.0).sqrt());
        let z0 = next[0] - x[0] + a1 * s1;
        let z1 = next[1] - x[1] - a1 * s1;
        kuu += u * u;
        kuz += u * z0;
        ass += s2 * s2;
        asz += -s2 * z1;
    }
    [kuz / kuu, a1, asz / ass]
}

fn golden(lo: f64, hi: f64, f: impl Fn(f64) -> f64) -> f64 {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    for _ in 0..200 {
        let (c, d) = (b - ratio * (b - a), a + ratio * (b - a));
        if f(c) < f(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

fn estimates(p: &AffineParams) -> [f64; 3] {
    [p.beta_x[(0, 2)], p.beta_x[(0, 3)], p.beta_x[(1, 5)]]
}

#[test]
fn void_constraints_give_the_unconstrained_m_step() {
    let record = simulate(2000, [1e-3, 4e-3]);
    let separate = Tanks {
        constraints: Some(AffineConstraints {
            coefficients: [(0, 2), (0, 3), (1, 4), (1, 5)]
                .into_iter()
                .map(|(row, col)| tie(vec![state(row, col)], f64::NEG_INFINITY, f64::INFINITY))
                .collect(),
            ..AffineConstraints::default()
        }),
    };
    let plain = Tanks { constraints: None };
    let stats = statistics(&plain, &record);
    let current = start([1e-3, 1e-3]);
    let a = m_step(&separate, &stats, &current, &spec(Covariance::Diagonal)).unwrap();
    let b = m_step(&plain, &stats, &current, &spec(Covariance::Diagonal)).unwrap();
    for (x, y) in [
        (&a.beta_x, &b.beta_x),
        (&a.pi_x, &b.pi_x),
        (&a.beta_y, &b.beta_y),
        (&a.pi_y, &b.pi_y),
    ] {
        assert!((x - y).amax() <= 1e-10 * y.amax(), "{x} against {y}");
    }
}

#[test]
fn a_shared_coefficient_with_known_variances_is_the_weighted_least_squares() {
    let q = [1e-3, 4e-3];
    let record = simulate(2000, q);
    let model = tied(0.0, f64::INFINITY, Vec::new());
    let stats = statistics(&model, &record);
    let next = m_step(&model, &stats, &start(q), &spec(Covariance::Fixed)).unwrap();
    let reference = weighted_least_squares(&record, q);
    let got = estimates(&next);
    for (g, r) in got.iter().zip(&reference) {
        assert!(
            (g - r).abs() < 1e-9 * r.abs(),
            "{got:?} against {reference:?}"
        );
    }
    // the tie holds, the known variances stay, the output variance is its residual
    assert_eq!(next.beta_x[(0, 3)], next.beta_x[(1, 4)]);
    assert_eq!(next.pi_x, start(q).pi_x);
    let y_residual: Vec<f64> = record
        .y
        .iter()
        .zip(&record.x)
        .map(|(y, x)| y - x[1])
        .collect();
    assert!((next.pi_y[(0, 0)] - mean_square(&y_residual)).abs() < 1e-9 * mean_square(&y_residual));
    // and it is the truth, roughly (2000 steps)
    assert!((got[1] - 0.3).abs() < 0.03, "{got:?}");
}

#[test]
fn a_shared_coefficient_with_free_variances_maximises_the_profile_likelihood() {
    let q = [1e-3, 4e-3];
    let record = simulate(2000, q);
    let model = tied(0.0, f64::INFINITY, Vec::new());
    let stats = statistics(&model, &record);
    let next = m_step(
        &model,
        &stats,
        &start([1e-2, 1e-4]),
        &spec(Covariance::Diagonal),
    )
    .unwrap();
    // the profile: with each row's variance its mean squared residual, the objective is
    // -N/2 (log RSS_0 + log RSS_1); k and a2 given a1 are each row's own regression
    let profile = |a1: f64| {
        let theta = given_a1(&record, a1);
        mean_square(&residuals(&record, theta, 0)).ln()
            + mean_square(&residuals(&record, theta, 1)).ln()
    };
    let a1 = golden(0.1, 0.5, profile);
    let reference = given_a1(&record, a1);
    let got = estimates(&next);
    for (g, r) in got.iter().zip(&reference) {
        assert!(
            (g - r).abs() < 1e-6 * r.abs(),
            "{got:?} against {reference:?}"
        );
    }
    for row in 0..2 {
        let ms = mean_square(&residuals(&record, got, row));
        assert!((next.pi_x[(row, row)] - ms).abs() < 1e-9 * ms);
    }
}

#[test]
fn a_binding_bound_gives_the_best_fit_at_the_bound() {
    let q = [1e-3, 4e-3];
    let record = simulate(2000, q);
    // a1 at most 0.2 (truth 0.3): the answer is a1 = 0.2 with k and a2 refitted
    let model = tied(0.0, 0.2, Vec::new());
    let stats = statistics(&model, &record);
    let next = m_step(&model, &stats, &start(q), &spec(Covariance::Fixed)).unwrap();
    let got = estimates(&next);
    let reference = given_a1(&record, 0.2);
    assert_eq!(got[1], 0.2);
    for (g, r) in got.iter().zip(&reference) {
        assert!(
            (g - r).abs() < 1e-9 * r.abs(),
            "{got:?} against {reference:?}"
        );
    }
    // a lower bound above the unconstrained answer binds the same way
    let model = tied(0.4, 1.0, Vec::new());
    let next = m_step(&model, &stats, &start(q), &spec(Covariance::Fixed)).unwrap();
    assert_eq!(estimates(&next)[1], 0.4);
}

#[test]
fn a_held_variance_in_an_estimated_block_stays_and_the_other_is_estimated() {
    let q = [1e-3, 4e-3];
    let record = simulate(2000, q);
    let model = tied(0.0, f64::INFINITY, vec![0]);
    let stats = statistics(&model, &record);
    let current = start([2e-3, 1e-2]);
    let next = m_step(&model, &stats, &current, &spec(Covariance::Diagonal)).unwrap();
    assert_eq!(next.pi_x[(0, 0)], 2e-3);
    let got = estimates(&next);
    let ms = mean_square(&residuals(&record, got, 1));
    assert!((next.pi_x[(1, 1)] - ms).abs() < 1e-9 * ms);
    // the coefficients are the weighted least squares at the final variances
    let reference = weighted_least_squares(&record, [2e-3, ms]);
    for (g, r) in got.iter().zip(&reference) {
        assert!(
            (g - r).abs() < 1e-6 * r.abs(),
            "{got:?} against {reference:?}"
        );
    }
}

#[test]
fn bad_constraints_are_typed_errors() {
    let record = simulate(200, [1e-3, 4e-3]);
    let mut model = tied(0.0, f64::INFINITY, Vec::new());
    let stats = statistics(&model, &record);
    let current = start([1e-3, 4e-3]);
    // a2's coefficient left out
    model.constraints.as_mut().unwrap().coefficients.pop();
    let e = m_step(&model, &stats, &current, &spec(Covariance::Fixed)).unwrap_err();
    assert!(e.to_string().contains("3 of the 4"), "{e}");
    let mut model = tied(0.5, 0.1, Vec::new());
    let e = m_step(&model, &stats, &current, &spec(Covariance::Fixed)).unwrap_err();
    assert!(e.to_string().contains("bounds"), "{e}");
    model = tied(0.0, 1.0, Vec::new());
    model.constraints.as_mut().unwrap().coefficients[0]
        .slots
        .push(state(0, 0));
    let e = m_step(&model, &stats, &current, &spec(Covariance::Fixed)).unwrap_err();
    assert!(e.to_string().contains("not an estimated"), "{e}");
    let mut zero = current.clone();
    zero.pi_x[(1, 1)] = 0.0;
    let model = tied(0.0, 1.0, Vec::new());
    let e = m_step(&model, &stats, &zero, &spec(Covariance::Fixed)).unwrap_err();
    assert!(e.to_string().contains("variance of row 1"), "{e}");
}
