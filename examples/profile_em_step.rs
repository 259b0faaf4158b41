//! Repeats one linear EM iteration (E-step + M-step) on lti2x2, T = 200, from the
//! N4SID start: a fixed workload for profiling the `em` runner's T = 200 case, e.g.
//! `perf record -g target/release/examples/profile_em_step`.

use sysid::em::EmAlgorithm;
use sysid::em::linear::LinearEm;
use sysid::prelude::*;
use sysid::subspace::{N4sidOptions, Order, n4sid};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let steps: usize = std::env::args().nth(1).map_or(Ok(200), |s| s.parse())?;
    let iterations: usize = std::env::args().nth(2).map_or(Ok(5000), |s| s.parse())?;
    let sim = System::Lti2x2.simulate(steps, 1)?;
    let options = N4sidOptions {
        order: Order::Fixed(8),
        block_rows: None,
        ..Default::default()
    };
    let start = n4sid(&sim.record, &options)?
        .model
        .without_cross_covariance();
    let records = [sim.record];
    let mut em = LinearEm::new(&records, sysid::models::lti2x2_em_spec());
    let clock = std::time::Instant::now();
    for _ in 0..iterations {
        std::hint::black_box(em.step(&start)?);
    }
    let ms = clock.elapsed().as_secs_f64() * 1e3 / iterations as f64;
    println!("T = {steps}: {ms:.4} ms per iteration (mean of {iterations})");
    Ok(())
}
