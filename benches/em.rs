//! Criterion group `em`: one linear EM iteration on lti2x2 (T = 200, 2000) and N4SID.
//!
//! `cargo bench --bench em`

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use sysid::em::EmAlgorithm;
use sysid::em::linear::LinearEm;
use sysid::prelude::*;
use sysid::subspace::{N4sidOptions, Order, n4sid};

fn em(c: &mut Criterion) {
    let mut group = c.benchmark_group("em");
    for steps in [200, 2000] {
        let sim = System::Lti2x2.simulate(steps, 1).unwrap();
        let options = N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        };
        let start = n4sid(&sim.record, &options).unwrap().model;
        let start = start.without_cross_covariance();
        let records = [sim.record];
        let spec = sysid::models::lti2x2_em_spec();
        let mut em = LinearEm::new(&records, spec);
        group.bench_function(format!("iteration/lti2x2/T{steps}"), |b| {
            b.iter(|| black_box(em.step(black_box(&start)).unwrap()))
        });
        group.bench_function(format!("n4sid/lti2x2/T{steps}/order8"), |b| {
            b.iter(|| black_box(n4sid(black_box(&records[0]), &options).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, em);
criterion_main!(benches);
