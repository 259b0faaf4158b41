//! One realisation of blind Wiener identification (seed 001, ALGORITHMS.md 4): N4SID on
//! y1 for the linear part, then gradient EM with FFBSi-reject trajectories.
//! Usage: `cargo run --release --example wiener_em [seed] [iterations] [bfgs iterations]`.
//! Diagnostics of the start: `WIENER_START=truth` (start at the true system),
//! `WIENER_START=truth-linear` (the true linear part, the lecture's nonlinearity and r),
//! `WIENER_BETA=truth` (true breakpoints, the rest as the lecture), `WIENER_R0=v` (both
//! noise variances start at v), `WIENER_PARTICLES=m` (the E-step's filter particles,
//! default 100; the smoother draws 100 paths), `WIENER_HOLD=n` (hold the linear part
//! for the first n M-steps), `WIENER_FILTER=bootstrap` (the E-step's filter; default
//! `guided`, the fully adapted one), `WIENER_EVERY=1` (trace every iteration, not only
//! 1-10 and every tenth). Prints the filter's log-likelihood at
//! the start with M = 100 and M = 10 000.
use sysid::em::gradient::{GradientEm, GradientModel, MStepOptions};
use sysid::em::{EmObserver, EmOptions, IterationInfo, run_em};
use sysid::models::{
    BlindWiener, WienerEstimate, WienerModel, normalised_magnitude_error, wiener_start,
};
use sysid::smc::{FfbsiReject, Series};

/// Prints the breakpoints, noise variances and magnitude error at iterations 1-10
/// and every tenth.
struct Trace;

impl EmObserver<Vec<f64>> for Trace {
    fn iteration(&mut self, info: &IterationInfo<'_, Vec<f64>>) {
        if info.iteration <= 10
            || info.iteration.is_multiple_of(10)
            || std::env::var("WIENER_EVERY").is_ok()
        {
            let e = WienerEstimate::from_theta(info.estimate);
            println!(
                "{:4}  loglik {:10.1}  beta {:7.3} {:7.3} {:7.3} {:7.3}  r {:.4} {:.4}  A2 {:.3} {:.3} Q {:.2e} {:.2e} {:.2e}  magnitude error {:.3}",
                info.iteration,
                info.loglik,
                e.beta[0],
                e.beta[1],
                e.beta[2],
                e.beta[3],
                e.r[0],
                e.r[1],
                e.a[1][0],
                e.a[1][1],
                e.q[0][0],
                e.q[0][1],
                e.q[1][1],
                normalised_magnitude_error(&e)
            );
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(1, |v| v.parse().expect("seed"));
    let iterations: usize = args.next().map_or(100, |v| v.parse().expect("iterations"));
    let bfgs: u64 = args
        .next()
        .map_or(50, |v| v.parse().expect("BFGS iterations"));
    let sim = BlindWiener::simulate(1000, seed);
    let data = Series::new(&sim.outputs, 2).expect("finite");
    // `WIENER_START=truth` starts at the true system (in the basis C = [1, 0], with a
    // small noise on x2 so that Q is positive definite), to tell a poor start from a
    // drift of EM itself.
    let which_start = std::env::var("WIENER_START").unwrap_or_default();
    let start = if which_start == "truth" || which_start == "truth-linear" {
        let a = BlindWiener::A;
        // T = [[1, 0.3], [0, 1]]: A' = T A T^{-1}
        let a2 = [
            [
                a[0][0] + 0.3 * a[1][0],
                -0.3 * (a[0][0] + 0.3 * a[1][0]) + a[0][1] + 0.3 * a[1][1],
            ],
            [a[1][0], -0.3 * a[1][0] + a[1][1]],
        ];
        let lecture = wiener_start(&sim.outputs).expect("N4SID");
        let linear_only = which_start == "truth-linear";
        WienerEstimate {
            a: a2,
            q: [[1.0, 0.0], [0.0, 1e-4]],
            beta: if linear_only {
                lecture.beta
            } else {
                BlindWiener::BETA
            },
            r: if linear_only {
                lecture.r
            } else {
                BlindWiener::R
            },
        }
    } else {
        let mut start = wiener_start(&sim.outputs).expect("N4SID");
        // `WIENER_R0=v` starts both noise variances at v; `WIENER_BETA=truth` starts the
        // breakpoints at the truth (diagnostics of the lecture's start)
        if let Some(r0) = std::env::var("WIENER_R0").ok().and_then(|v| v.parse().ok()) {
            start.r = [r0, r0];
        }
        if let Some(scale) = std::env::var("WIENER_QSCALE")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
        {
            start.q.iter_mut().flatten().for_each(|v| *v *= scale);
        }
        if std::env::var("WIENER_BETA").as_deref() == Ok("truth") {
            start.beta = BlindWiener::BETA;
        }
        start
    };
    let filter_logliks = |label: &str, theta: &[f64]| {
        use sysid::smc::{FilterOptions, ParticleFilter};
        let smc = WienerModel::default().smc_model(theta).expect("model");
        for m in [100, 10_000] {
            let mut pf = ParticleFilter::new(FilterOptions {
                particles: m,
                ..Default::default()
            })
            .expect("pf");
            let l: Vec<f64> = (0..3)
                .map(|r| pf.run(&smc, &data, r).expect("pf").loglik)
                .collect();
            println!("filter log-likelihood at the {label}, M = {m}: {l:?}");
        }
    };
    println!(
        "start {:?}",
        WienerModel::default().constrained(&start.theta().expect("start"))
    );
    filter_logliks("start", &start.theta().expect("start"));
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
    let particles = std::env::var("WIENER_PARTICLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    let hold: usize = std::env::var("WIENER_HOLD")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let mut em = GradientEm::new(&model, data, particles, smoother, m_step, seed)
        .expect("options")
        .hold_dynamics_for(hold);
    if std::env::var("WIENER_FILTER").as_deref() != Ok("bootstrap") {
        em = em.with_guided_filter();
    }
    let options = EmOptions {
        max_iterations: iterations,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .expect("options");
    let t = std::time::Instant::now();
    let fit = run_em(&mut em, start.theta().expect("start"), &options, &mut Trace);
    if let Some(m) = em.last_m_step() {
        println!("last M-step: {} evaluations, {}", m.evaluations, m.status);
    }
    let seconds = t.elapsed().as_secs_f64();
    filter_logliks("estimate", &fit.estimate);
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
