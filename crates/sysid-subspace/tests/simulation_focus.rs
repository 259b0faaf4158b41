//! `Focus::Simulation`: B and D are the least-squares refit given N4SID's A and C,
//! checked against an independent dense solve, on a system with a slow pole driven by
//! a strongly coloured input.

use nalgebra::{DMatrix, DVector, dmatrix};
use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
use rand_distr::{Distribution, StandardNormal};
use sysid_kalman::{LinearGaussianModel, Record};
use sysid_subspace::{Focus, InputMethod, N4sidOptions, Order, n4sid};

fn coloured_record() -> Record {
    let truth = LinearGaussianModel::builder(
        dmatrix![0.995, 0.0; 0.1, 0.6],
        dmatrix![1.0, 1.0],
        dmatrix![1e-4, 0.0; 0.0, 1e-4],
        dmatrix![0.05],
    )
    .b(dmatrix![0.01; 1.0])
    .build()
    .unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    let mut u = DMatrix::zeros(1, 3000);
    let mut state = 0.0;
    for t in 0..3000 {
        let e: f64 = StandardNormal.sample(&mut rng);
        state = 0.97 * state + e;
        u[(0, t)] = state;
    }
    truth.simulate(&u, &mut rng).unwrap().record
}

/// Dense least squares of the simulated output on (x0, B, D), with regressors built
/// from explicit powers of A and solved by nalgebra's SVD: an independent computation.
fn dense_refit(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    u: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> DVector<f64> {
    let (n, t_len) = (a.nrows(), y.ncols());
    let powers: Vec<DMatrix<f64>> =
        std::iter::successors(Some(DMatrix::identity(n, n)), |p| Some(a * p))
            .take(t_len)
            .collect();
    let mut x = DMatrix::zeros(t_len, 2 * n + 1);
    for t in 0..t_len {
        let ca = c * &powers[t];
        for j in 0..n {
            x[(t, j)] = ca[(0, j)];
        }
        for s in 0..t {
            let g = c * &powers[t - 1 - s];
            for j in 0..n {
                x[(t, n + j)] += g[(0, j)] * u[(0, s)];
            }
        }
        x[(t, 2 * n)] = u[(0, t)];
    }
    let rhs = DVector::from_fn(t_len, |t, _| y[(0, t)]);
    x.svd(true, true).solve(&rhs, 1e-14).unwrap()
}

#[test]
fn simulation_focus_is_the_least_squares_refit_given_a_and_c() {
    let record = coloured_record();
    let result = n4sid(
        &record,
        &N4sidOptions {
            order: Order::Fixed(2),
            focus: Focus::Simulation,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(result.input_method, InputMethod::Simulation);
    let model = &result.model;
    // n4sid centres the record; the refit sees the same centred signals
    let centre = |m: &DMatrix<f64>| {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, t| m[(i, t)] - m.row(i).mean())
    };
    let (u, y) = (centre(&record.u), centre(&record.y));
    let theta = dense_refit(model.a(), model.c(), &u, &y);
    let (b, d) = (theta.rows(2, 2), theta[4]);
    let scale = b.amax().max(d.abs());
    assert!(
        (model.b().column(0) - b).amax() < 1e-6 * scale,
        "{} vs {b}",
        model.b()
    );
    assert!((model.d()[(0, 0)] - d).abs() < 1e-6 * scale);
    // and the input gain is right: the steady-state gain of the truth is
    // C (I - A)^-1 B = 0.01 / 0.005 + (0.1 * 2 + 1) / 0.4 = 5
    let gain = (model.c()
        * (DMatrix::identity(2, 2) - model.a()).try_inverse().unwrap()
        * model.b())[(0, 0)]
        + model.d()[(0, 0)];
    assert!((gain - 5.0).abs() < 0.5, "gain {gain}");
}
