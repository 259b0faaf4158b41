//! The warnings of a subspace result: an order chosen at the edge of the candidates.

use nalgebra::{DMatrix, dmatrix};
use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
use rand_distr::{Distribution, StandardNormal};
use sysid_kalman::{LinearGaussianModel, Record};
use sysid_subspace::{N4sidOptions, Order, SubspaceWarning, n4sid};

/// A fourth-order system with one input and two outputs, 1000 steps.
fn record() -> Record {
    let a = DMatrix::from_diagonal(&nalgebra::dvector![0.9, -0.7, 0.5, 0.3]);
    let model = LinearGaussianModel::builder(
        a,
        dmatrix![1.0, 1.0, 0.0, 1.0; 0.0, 1.0, 1.0, -1.0],
        DMatrix::identity(4, 4) * 0.01,
        DMatrix::identity(2, 2) * 0.01,
    )
    .b(dmatrix![1.0; 1.0; 1.0; 1.0])
    .build()
    .unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
    let u = DMatrix::from_fn(1, 1000, |_, _| StandardNormal.sample(&mut rng));
    model.simulate(&u, &mut rng).unwrap().record
}

#[test]
fn an_automatic_order_at_the_last_candidate_is_flagged_and_an_interior_one_is_not() {
    let record = record();
    // two block rows and two outputs: the candidates are orders 1 to 3, below the truth
    let cramped = N4sidOptions {
        order: Order::Auto,
        block_rows: Some(2),
        ..Default::default()
    };
    let result = n4sid(&record, &cramped).unwrap();
    assert_eq!(result.order, 3);
    let warnings = result.warnings(&cramped);
    assert!(
        warnings.contains(&SubspaceWarning::OrderAtEdge {
            order: 3,
            block_rows: 2,
            capped: false
        }),
        "{warnings:?}"
    );
    assert!(warnings[0].to_string().contains("--block-rows"));
    // with the default block rows the truth (4) is inside the candidates
    let roomy = N4sidOptions {
        order: Order::Auto,
        ..Default::default()
    };
    let result = n4sid(&record, &roomy).unwrap();
    assert_eq!(result.order, 4);
    assert!(
        !result
            .warnings(&roomy)
            .iter()
            .any(|w| matches!(w, SubspaceWarning::OrderAtEdge { .. })),
    );
    // a fixed order is the user's choice: never flagged
    let fixed = N4sidOptions {
        order: Order::Fixed(3),
        block_rows: Some(2),
        ..Default::default()
    };
    assert!(n4sid(&record, &fixed).unwrap().warnings(&fixed).is_empty());
}
