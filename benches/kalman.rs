//! Criterion group `kalman`: square-root filter (log-likelihood) and filter + smoother +
//! EM statistics on the canonical systems; throughput in time steps.
//!
//! `cargo bench --bench kalman`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use sysid::prelude::*;

fn kalman(c: &mut Criterion) {
    let mut group = c.benchmark_group("kalman");
    for (system, steps) in [(System::Lgss, 10_000), (System::Lti2x2, 2000)] {
        let model = system.model();
        let sim = system.simulate(steps, 1).unwrap();
        let mut ws = KalmanWorkspace::new();
        group.throughput(Throughput::Elements(steps as u64));
        group.bench_function(format!("loglik/{}", system.name()), |b| {
            b.iter(|| black_box(ws.loglik(&model, black_box(&sim.record)).unwrap()))
        });
        let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
        group.bench_function(format!("smooth_stats/{}", system.name()), |b| {
            b.iter(|| {
                black_box(
                    ws.accumulate_statistics(&model, black_box(&sim.record), 0, &mut stats)
                        .unwrap(),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, kalman);
criterion_main!(benches);
