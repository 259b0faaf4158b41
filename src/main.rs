//! The demo (`cargo run --release`): simulate the canonical systems, filter and smooth
//! them, and report log-likelihoods and state errors.

use std::time::Instant;
use sysid::prelude::*;

fn rms(est: impl Fn(usize) -> f64, truth: impl Fn(usize) -> f64, count: usize) -> f64 {
    ((0..count).map(|k| (est(k) - truth(k)).powi(2)).sum::<f64>() / count as f64).sqrt()
}

fn main() -> Result<(), KalmanError> {
    println!("sysid demo: square-root Kalman filter and RTS smoother\n");
    let mut ws = KalmanWorkspace::new();

    // lti2x2: the 2x2, 8-state system of Gibson and Ninness, T = 2000
    let (steps, seed) = (2000, 1);
    let sim = System::Lti2x2.simulate(steps, seed)?;
    let model = System::Lti2x2.model();
    let start = Instant::now();
    let smoothed = ws.smooth(&model, &sim.record)?;
    let elapsed = start.elapsed();
    let n = model.n();
    let state_rms = rms(
        |k| smoothed.mean(k / n)[k % n],
        |k| sim.x[(k % n, k / n)],
        steps * n,
    );
    println!("lti2x2 (n = 8, m = 2, p = 2), T = {steps}, seed {seed}");
    println!(
        "  log-likelihood at the true parameters : {:.3}",
        smoothed.loglik()
    );
    println!(
        "  RMS error of the smoothed states     : {state_rms:.2e}  (no process noise: states are determined by the inputs)"
    );
    println!(
        "  filter + smoother time               : {:.2} ms",
        elapsed.as_secs_f64() * 1e3
    );
    let guess = sysid::models::lti2x2_initial_guess();
    println!(
        "  log-likelihood at the paper's initial model (6 states): {:.3}\n",
        ws.loglik(&guess, &sim.record)?
    );

    // lgss: scalar, with process noise, and with 20 % of the outputs missing
    let (steps, seed) = (1000, 2);
    let sim = System::Lgss.simulate(steps, seed)?;
    let model = System::Lgss.model();
    let filtered = ws.filter(&model, &sim.record)?.clone();
    let smoothed = ws.smooth(&model, &sim.record)?.clone();
    let truth = |k: usize| sim.x[(0, k)];
    println!("lgss (x' = 0.9 x + w, y = x + e), T = {steps}, seed {seed}");
    println!(
        "  log-likelihood                       : {:.3}",
        smoothed.loglik()
    );
    println!(
        "  RMS error: measurements {:.3}, filtered {:.3}, smoothed {:.3}",
        rms(|k| sim.record.y[(0, k)], truth, steps),
        rms(|k| filtered.filtered_mean(k)[0], truth, steps),
        rms(|k| smoothed.mean(k)[0], truth, steps)
    );
    let mut gappy = sim.record.clone();
    for k in (0..steps).filter(|k| k % 5 == 2) {
        gappy.y[(0, k)] = f64::NAN;
    }
    let smoothed_gappy = ws.smooth(&model, &gappy)?;
    println!(
        "  with every 5th output missing        : log-likelihood {:.3}, smoothed RMS {:.3}",
        smoothed_gappy.loglik(),
        rms(|k| smoothed_gappy.mean(k)[0], truth, steps)
    );
    Ok(())
}
