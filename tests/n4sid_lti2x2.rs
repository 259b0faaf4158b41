//! N4SID on the lti2x2 system of seed 004 (ALGORITHMS.md 1.5).

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use sysid::kalman::{LinearGaussianModel, Record};
use sysid::models::lti2x2;
use sysid::subspace::{N4sidOptions, Order, SubspaceError, n4sid};

/// lti2x2 with output noise variance `r`, driven by white N(0, I) inputs.
fn data(steps: usize, r: f64, seed: u64) -> (LinearGaussianModel, Record, DMatrix<f64>) {
    let truth = lti2x2()
        .to_builder()
        .r(DMatrix::identity(2, 2) * r)
        .build()
        .unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let u = DMatrix::from_fn(2, steps, |_, _| StandardNormal.sample(&mut rng));
    let sim = truth.simulate(&u, &mut rng).unwrap();
    let noise_free = truth.c() * &sim.x + truth.d() * &sim.record.u;
    (truth, sim.record, noise_free)
}

/// Deterministic simulation from rest: x' = A x + B u, y = C x + D u + h.
fn simulate_deterministic(model: &LinearGaussianModel, u: &DMatrix<f64>) -> DMatrix<f64> {
    let mut x = nalgebra::DVector::zeros(model.n());
    let mut y = DMatrix::zeros(model.p(), u.ncols());
    for t in 0..u.ncols() {
        let ut = u.column(t);
        y.set_column(t, &(model.c() * &x + model.d() * ut + model.h()));
        x = model.a() * &x + model.b() * ut;
    }
    y
}

/// 100 (1 - |y - yhat| / |y - mean y|) per output.
fn fit_percent(y: &DMatrix<f64>, yhat: &DMatrix<f64>) -> Vec<f64> {
    (0..y.nrows())
        .map(|i| {
            let row = y.row(i);
            let mean = row.mean();
            let err = (row - yhat.row(i)).norm();
            let spread = row.map(|v| v - mean).norm();
            100.0 * (1.0 - err / spread)
        })
        .collect()
}

#[test]
fn order_five_reaches_95_percent_fit_on_both_outputs() {
    let (_, record, noise_free) = data(5000, 1e-4, 2026);
    let result = n4sid(
        &record,
        &N4sidOptions {
            order: Order::Fixed(5),
            block_rows: None,
            ..Default::default()
        },
    )
    .unwrap();
    let fit = fit_percent(
        &noise_free,
        &simulate_deterministic(&result.model, &record.u),
    );
    eprintln!(
        "order 5 fit: {fit:?}, spectral radius {}",
        result.spectral_radius
    );
    assert!(fit.iter().all(|&f| f >= 95.0), "fit {fit:?}");
    assert!(result.spectral_radius < 1.0);
}

#[test]
fn order_eight_singular_values_show_the_order() {
    let (_, record, noise_free) = data(5000, 1e-4, 7);
    let result = n4sid(
        &record,
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        },
    )
    .unwrap();
    let s = &result.singular_values;
    eprintln!("singular values: {:?}", s);
    // Five dominant values (the largest drop, which the default rule picks), then three
    // weak modes above a slowly decaying noise floor: after the dominant gap, the
    // largest drop s_k / s_{k+1} is at k = 8, which is what a user reads off the values.
    let drop = |k: usize| s[k - 1] / s[k];
    let dominant = (1..20)
        .max_by(|&a, &b| drop(a).total_cmp(&drop(b)))
        .unwrap();
    assert_eq!(dominant, 5);
    assert_eq!(sysid::subspace::auto_order(s, 20), 5);
    let next = (dominant + 1..20)
        .max_by(|&a, &b| drop(a).total_cmp(&drop(b)))
        .unwrap();
    assert_eq!(
        next,
        8,
        "drops after the dominant gap: {:?}",
        (6..20).map(drop).collect::<Vec<_>>()
    );
    let fit = fit_percent(
        &noise_free,
        &simulate_deterministic(&result.model, &record.u),
    );
    eprintln!("order 8 fit: {fit:?}");
    assert!(fit.iter().all(|&f| f >= 99.0), "fit {fit:?}");
}

#[test]
fn bad_input_is_reported() {
    let (_, record, _) = data(300, 1e-2, 1);
    let too_large = n4sid(
        &record,
        &N4sidOptions {
            order: Order::Fixed(25),
            block_rows: Some(10),
            ..Default::default()
        },
    );
    assert!(
        matches!(
            too_large,
            Err(SubspaceError::OrderTooLarge {
                order: 25,
                max: 19,
                ..
            })
        ),
        "{too_large:?}"
    );
    let short = Record::new(
        record.u.columns(0, 60).clone_owned(),
        record.y.columns(0, 60).clone_owned(),
    );
    let too_few = n4sid(
        &short,
        &N4sidOptions {
            order: Order::Fixed(4),
            block_rows: Some(10),
            ..Default::default()
        },
    );
    assert!(
        matches!(
            too_few,
            Err(SubspaceError::TooFewSamples {
                needed: 99,
                got: 60,
                ..
            })
        ),
        "{too_few:?}"
    );
    let mut gappy = record.clone();
    gappy.y[(1, 41)] = f64::NAN;
    assert_eq!(
        n4sid(&gappy, &N4sidOptions::default()).unwrap_err(),
        SubspaceError::MissingData {
            time: 42,
            output: 2
        }
    );
}

/// The purely stochastic case (no inputs): lgss, x' = 0.9 x + w, y = x + e.
#[test]
fn purely_stochastic_case_recovers_the_pole() {
    let sim = sysid::models::System::Lgss.simulate(5000, 11).unwrap();
    let result = n4sid(&sim.record, &N4sidOptions::default()).unwrap();
    assert_eq!(
        result.order,
        1,
        "singular values {:?}",
        &result.singular_values[..4]
    );
    let a = result.model.a()[(0, 0)];
    eprintln!("stochastic N4SID: a = {a}, h = {}", result.model.h()[0]);
    assert!((a - 0.9).abs() < 0.03, "a = {a}");
    // the innovation variance implied by the model matches the data's one-step errors:
    // the model's log-likelihood is within a few nats per thousand steps of the truth's
    let mut ws = sysid::kalman::KalmanWorkspace::new();
    let ll_fit = ws.loglik(&result.model, &sim.record).unwrap();
    let ll_true = ws.loglik(&sysid::models::lgss(), &sim.record).unwrap();
    eprintln!("loglik: n4sid model {ll_fit}, truth {ll_true}");
    assert!(ll_fit > ll_true - 10.0, "{ll_fit} vs {ll_true}");
}
