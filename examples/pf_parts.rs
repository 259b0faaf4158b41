//! Per-particle cost of the bootstrap filter's parts on `nlbench` (default M = 10 000), to
//! see which one bounds the filter. `cargo run --release --example pf_parts [M]`
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use std::hint::black_box;
use std::time::Instant;
use sysid::models::Nlbench;
use sysid::smc::resample::systematic;
use sysid::smc::weights::effective_sample_size;
use sysid::smc::{
    ObservationDensity, TransitionSampler, fill_standard_normals, normalise_log_weights, stream,
};

fn ns_per(m: usize, reps: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let s = Instant::now();
        for _ in 0..reps {
            f();
        }
        best = best.min(s.elapsed().as_secs_f64() / (reps * m) as f64 * 1e9);
    }
    best
}

fn main() {
    let m: usize = std::env::args()
        .nth(1)
        .map_or(10_000, |v| v.parse().expect("M"));
    let reps = 2_000_000 / m;
    let model = Nlbench::truth();
    let mut rng = stream(1, 1);
    let from: Vec<f64> = (0..m).map(|_| rng.random::<f64>() * 20.0 - 10.0).collect();
    let parents: Vec<usize> = (0..m).map(|i| (i * 7) % m).collect();
    let mut next = vec![0.0; m];
    let mut lg = vec![0.0; m];
    let mut w = vec![0.0; m];
    let mut anc = vec![0usize; m];
    println!(
        "normal draw: {:.2} ns",
        ns_per(m, reps, || for x in next.iter_mut() {
            *x = StandardNormal.sample(&mut rng);
        })
    );
    println!(
        "normal draws in bulk (1024 per call): {:.2} ns",
        ns_per(m, reps, || for block in next.chunks_mut(1024) {
            fill_standard_normals(&mut rng, block);
        })
    );
    println!(
        "uniform draw: {:.2} ns",
        ns_per(m, reps, || for x in next.iter_mut() {
            *x = rng.random::<f64>();
        })
    );
    println!(
        "sample_transitions: {:.2} ns",
        ns_per(m, reps, || model.sample_transitions(
            5,
            &[],
            &from,
            &parents,
            &mut next,
            &mut rng
        ))
    );
    println!(
        "log_observations: {:.2} ns",
        ns_per(m, reps, || model.log_observations(
            5,
            &[],
            &[3.0],
            &next,
            &mut lg
        ))
    );
    println!(
        "normalise: {:.2} ns",
        ns_per(m, reps, || {
            black_box(normalise_log_weights(&lg, &mut w));
        })
    );
    println!(
        "ess: {:.2} ns",
        ns_per(m, reps, || {
            black_box(effective_sample_size(&w));
        })
    );
    println!(
        "systematic: {:.2} ns",
        ns_per(m, reps, || systematic(&w, 0.3, &mut anc))
    );
}
