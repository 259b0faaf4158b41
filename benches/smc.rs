//! Criterion group `smc`: bootstrap filter and particle smoothers on `nlbench`
//! (T = 1000), with throughput in particle-steps (filter) or transition-density
//! evaluations (smoothers) per second; the M = 10 000 filter also on two threads.
//!
//! `cargo bench --bench smc`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use sysid::models::Nlbench;
use sysid::smc::{Ffbsi, FfbsiReject, FilterOptions, ParticleFilter, Series, Smoother, Tanizaki};

const STEPS: usize = 1000;

fn smc(c: &mut Criterion) {
    let model = Nlbench::truth();
    let sim = model.simulate(STEPS, 1);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let mut group = c.benchmark_group("smc");
    group.sample_size(20);
    for particles in [1000usize, 10_000] {
        let mut pf = ParticleFilter::new(FilterOptions {
            particles,
            ..Default::default()
        })
        .unwrap();
        group.throughput(Throughput::Elements((STEPS * particles) as u64));
        group.bench_function(format!("pf/nlbench/T{STEPS}/M{particles}"), |b| {
            b.iter(|| black_box(pf.run(&model, &data, 1).unwrap()))
        });
    }
    // the same M = 10 000 filter with its chunks shared by a team of two threads
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 10_000,
        parallel: true,
        ..Default::default()
    })
    .unwrap();
    group.throughput(Throughput::Elements((STEPS * 10_000) as u64));
    group.bench_function(format!("pf/nlbench/T{STEPS}/M10000/threads2"), |b| {
        pool.install(|| b.iter(|| black_box(pf.run(&model, &data, 1).unwrap())))
    });
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 50,
        store_history: true,
        ..Default::default()
    })
    .unwrap();
    pf.run(&model, &data, 1).unwrap();
    let history = pf.history().unwrap().clone();
    group.throughput(Throughput::Elements((STEPS * 50 * 50) as u64));
    group.bench_function(format!("tanizaki/nlbench/T{STEPS}/M50"), |b| {
        b.iter(|| {
            black_box(
                Tanizaki::default()
                    .trajectories(&model, &history, &data, 2)
                    .unwrap(),
            )
        })
    });
    pf = ParticleFilter::new(FilterOptions {
        particles: 1000,
        store_history: true,
        ..Default::default()
    })
    .unwrap();
    pf.run(&model, &data, 1).unwrap();
    let history = pf.history().unwrap().clone();
    let reject = FfbsiReject {
        paths: 100,
        max_trials: None,
        parallel: false,
    };
    group.throughput(Throughput::Elements((STEPS * 100) as u64));
    group.bench_function(format!("ffbsi_reject/nlbench/T{STEPS}/M1000/K100"), |b| {
        b.iter(|| black_box(reject.trajectories(&model, &history, &data, 3).unwrap()))
    });
    group.sample_size(10);
    group.throughput(Throughput::Elements((STEPS * 100 * 1000) as u64));
    let exact = Ffbsi {
        paths: 100,
        parallel: false,
    };
    group.bench_function(format!("ffbsi/nlbench/T{STEPS}/M1000/K100"), |b| {
        b.iter(|| black_box(exact.trajectories(&model, &history, &data, 4).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, smc);
criterion_main!(benches);
