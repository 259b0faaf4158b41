//! Order selection by BIC over N4SID candidates scored by their exact log-likelihood
//! (`Order::Auto`, `sysid n4sid --order auto`, `sysid fit lti --order auto`).

use nalgebra::{DMatrix, dmatrix};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use sysid::kalman::LinearGaussianModel;
use sysid::models::lti2x2;
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Three states (a real pole 0.9, a complex pair 0.5 +- 0.3i), one input, two
/// outputs, process and measurement noise at a tenth of the signal.
fn three_states() -> LinearGaussianModel {
    LinearGaussianModel::builder(
        dmatrix![0.9, 0.0, 0.0; 0.0, 0.5, 0.3; 0.0, -0.3, 0.5],
        dmatrix![1.0, 0.5, 0.0; 0.0, 1.0, 1.0],
        DMatrix::identity(3, 3) * 0.05,
        DMatrix::identity(2, 2) * 0.1,
    )
    .b(dmatrix![1.0; 0.5; -0.7])
    .build()
    .unwrap()
}

/// The order chosen on a T-step record of `truth` driven by white inputs.
fn chosen(truth: &LinearGaussianModel, steps: usize, seed: u64) -> usize {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let u = DMatrix::from_fn(truth.m(), steps, |_, _| StandardNormal.sample(&mut rng));
    let record = truth.simulate(&u, &mut rng).unwrap().record;
    let options = N4sidOptions {
        order: Order::Auto,
        ..Default::default()
    };
    n4sid(&record, &options).unwrap().order
}

/// BIC picks the true order in at least 90 % of 50 data sets of T = 2000 (measured:
/// 50 of 50).
#[test]
fn bic_picks_the_true_order_of_a_well_excited_system() {
    let truth = three_states();
    let hits = (0..50)
        .filter(|&seed| chosen(&truth, 2000, seed) == 3)
        .count();
    assert!(hits >= 45, "the true order 3 in {hits} of 50");
}

/// On seed 004's lti2x2 (McMillan degree 8) the data of T = 2000 do not support order
/// 8: BIC picks 5 (measured: in 50 of 50 data sets of `sysid simulate lti2x2 --steps
/// 2000 --seed 1..50`), whose log-likelihood is within a few nats of order 8's with 18
/// fewer parameters (seed 1: 3476.8 against 3483.5). A property of the system at this
/// noise level, not of the rule.
#[test]
fn on_lti2x2_bic_stops_where_the_likelihood_stops_rising() {
    let truth = lti2x2();
    for seed in 0..5 {
        let order = chosen(&truth, 2000, seed);
        assert!((4..=8).contains(&order), "seed {seed}: order {order}");
    }
}
