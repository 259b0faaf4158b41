//! One realisation of blind Wiener identification (seed 001, ALGORITHMS.md 4): N4SID on
//! y1 for the linear part, then gradient EM with FFBSi-reject trajectories.
//! Usage: `cargo run --release --example wiener_em [seed] [iterations] [bfgs iterations]`.
use sysid::em::gradient::{GradientEm, GradientModel, MStepOptions};
use sysid::em::{EmOptions, run_em};
use sysid::models::{
    BlindWiener, WienerEstimate, WienerModel, normalised_magnitude_error, wiener_start,
};
use sysid::smc::{FfbsiReject, Series};

fn main() {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(1, |v| v.parse().expect("seed"));
    let iterations: usize = args.next().map_or(100, |v| v.parse().expect("iterations"));
    let bfgs: u64 = args
        .next()
        .map_or(50, |v| v.parse().expect("BFGS iterations"));
    let sim = BlindWiener::simulate(1000, seed);
    let data = Series::new(&sim.outputs, 2).expect("finite");
    let start = wiener_start(&sim.outputs).expect("N4SID");
    let model = WienerModel::default();
    let smoother = FfbsiReject {
        paths: 100,
        max_trials: None,
        parallel: false,
    };
    let m_step = MStepOptions {
        max_iterations: bfgs,
        ..MStepOptions::default()
    };
    let mut em = GradientEm::new(&model, data, 100, smoother, m_step, seed).expect("options");
    let options = EmOptions {
        max_iterations: iterations,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .expect("options");
    let t = std::time::Instant::now();
    let fit = run_em(&mut em, start.theta().expect("start"), &options, &mut ());
    if let Some(m) = em.last_m_step() {
        println!("last M-step: {} evaluations, {}", m.evaluations, m.status);
    }
    let seconds = t.elapsed().as_secs_f64();
    let estimate = WienerEstimate::from_theta(&fit.estimate);
    println!(
        "{:?} after {} iterations in {seconds:.1} s",
        fit.termination, fit.iterations
    );
    println!("names {:?}", model.parameter_names());
    println!("estimate {:?}", model.constrained(&fit.estimate));
    println!(
        "beta {:?} (truth {:?}), r {:?}",
        estimate.beta,
        BlindWiener::BETA,
        estimate.r
    );
    println!(
        "normalised magnitude error: start {:.4}, estimate {:.4}",
        normalised_magnitude_error(&start),
        normalised_magnitude_error(&estimate)
    );
    println!(
        "loglik trace: first {:?} last {:?}",
        fit.trace.first(),
        fit.trace.last()
    );
}
