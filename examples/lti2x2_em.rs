//! Seed 004 on one data set: N4SID gives the start, exact EM refines it.
//!
//! `cargo run --release --example lti2x2_em [seed]`
//!
//! The whole 100-data-set study is `cargo run --release -p sysid-bench -- lti2x2`.

use sysid::em::EmOptions;
use sysid::em::linear::fit;
use sysid::prelude::*;
use sysid::subspace::{N4sidOptions, Order, n4sid};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seed = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(1);
    let truth = System::Lti2x2.model();
    let sim = System::Lti2x2.simulate(200, seed)?;
    let records = [sim.record];
    let mut ws = KalmanWorkspace::new();
    println!("lti2x2, T = 200, seed {seed}");
    println!(
        "  log-likelihood at the true parameters: {:.3}",
        ws.loglik(&truth, &records[0])?
    );

    let subspace = n4sid(
        &records[0],
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        },
    )?;
    let s = &subspace.singular_values;
    println!("  N4SID singular values: {:.3?} ...", &s[..10]);
    // known: no offset, system at rest; linear EM holds S (set to zero)
    let start = sysid::models::lti2x2_experiment_start(&subspace.model);
    println!(
        "  N4SID: log-likelihood {:.3}, response error {:.4}",
        ws.loglik(&start, &records[0])?,
        start
            .relative_response_error(&truth, 512)
            .unwrap_or(f64::NAN)
    );
    let spec = sysid::models::lti2x2_em_spec();
    let options = EmOptions {
        max_iterations: 1000,
        tol: 1e-7,
        ..EmOptions::default()
    }
    .check()?;
    let result = fit(start, &records, spec, &options, &mut ());
    println!(
        "  EM:    log-likelihood {:.3}, response error {:.4} after {} iterations ({:?}, {:.2} s)",
        result.loglik.unwrap_or(f64::NAN),
        result
            .estimate
            .relative_response_error(&truth, 512)
            .unwrap_or(f64::NAN),
        result.iterations,
        result.termination,
        result.elapsed.as_secs_f64()
    );
    Ok(())
}
