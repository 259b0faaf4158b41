//! `wiener` runner: blind Wiener identification by gradient EM (seed 001,
//! ALGORITHMS.md 4).
//!
//! Realisation `k` simulates its record from seed `stream(seed, 2k)` and runs EM with
//! the streams of `stream(seed, 2k + 1)`; realisations run in parallel (any order, any
//! thread count, same lines). Each starts as the lecture does (N4SID on y1 for the
//! linear part, r = 0.1, each breakpoint at a tenth of its true value).

use crate::emit;
use rand::RngExt;
use rayon::prelude::*;
use serde_json::json;
use std::io::Write;
use sysid::em::gradient::{GradientEm, MStepOptions};
use sysid::em::{EmOptions, run_em};
use sysid::models::{
    BlindWiener, WienerEstimate, WienerModel, dead_zone, normalised_magnitude_error, saturation,
    wiener_frequency_grid, wiener_start,
};
use sysid::smc::{FfbsiReject, Series, stream};

/// The runner's settings.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Realisations (data sets).
    #[arg(long, default_value_t = 100)]
    pub runs: usize,
    /// EM iterations per realisation.
    #[arg(long, default_value_t = 100)]
    pub iters: usize,
    /// Particles M (and backward trajectories).
    #[arg(long, default_value_t = 100)]
    pub particles: usize,
    /// Data length T.
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// The M-step for the breakpoints and noise variances: `exact` (the sorted-sum
    /// search, global for ordered breakpoints) or `bfgs` (BFGS on I3). The linear
    /// part is closed form either way.
    #[arg(long, default_value = "exact", value_parser = ["exact", "bfgs"])]
    pub m_step: String,
    /// The E-step's filter: `guided` (fully adapted: particles drawn from
    /// `p(x_t | x_{t-1}, y_t)`, exact for the piecewise-linear outputs) or `bootstrap`.
    #[arg(long, default_value = "guided", value_parser = ["guided", "bootstrap"])]
    pub filter: String,
    /// Hold the linear part at its start (N4SID's) for the first this many M-steps,
    /// while the breakpoints and noise variances move from the lecture's start.
    #[arg(long, default_value_t = 0)]
    pub hold: usize,
    /// BFGS iterations per M-step at most (with `--m-step bfgs`, or when the exact
    /// search does not apply).
    #[arg(long, default_value_t = 50)]
    pub bfgs_iters: u64,
    /// Study seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write `nonlinearities.csv` and `magnitudes.csv` (every realisation's estimate
    /// and the truth) into this folder, to redraw the lecture's figures.
    #[arg(long)]
    pub csv_dir: Option<std::path::PathBuf>,
    /// Replace existing CSV files.
    #[arg(long)]
    pub force: bool,
}

struct Outcome {
    run: usize,
    estimate: WienerEstimate,
    start_error: f64,
    seconds: f64,
    loglik: Option<f64>,
}

fn realisation(a: &Args, run: usize) -> Result<Outcome, String> {
    let data_seed: u64 = stream(a.seed, 2 * run as u64).random();
    let em_seed: u64 = stream(a.seed, 2 * run as u64 + 1).random();
    let sim = BlindWiener::simulate(a.steps, data_seed);
    let data = Series::new(&sim.outputs, 2).map_err(|e| e.to_string())?;
    let start = wiener_start(&sim.outputs).map_err(|e| e.reason)?;
    let model = WienerModel::default();
    let smoother = FfbsiReject {
        paths: a.particles,
        max_trials: None,
        parallel: false,
    };
    let m_step = MStepOptions {
        max_iterations: a.bfgs_iters,
        exact_observations: a.m_step == "exact",
        ..MStepOptions::default()
    };
    let mut em = GradientEm::new(&model, data, a.particles, smoother, m_step, em_seed)
        .map_err(|e| e.to_string())?
        .hold_dynamics_for(a.hold);
    if a.filter == "guided" {
        em = em.with_guided_filter();
    }
    let options = EmOptions {
        max_iterations: a.iters,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| e.to_string())?;
    let started = std::time::Instant::now();
    let theta = start.theta().map_err(|e| e.reason)?;
    let fit = run_em(&mut em, theta, &options, &mut ());
    Ok(Outcome {
        run,
        estimate: WienerEstimate::from_theta(&fit.estimate),
        start_error: normalised_magnitude_error(&start),
        seconds: started.elapsed().as_secs_f64(),
        loglik: fit.loglik,
    })
}

/// A number for JSON: non-finite values (a breakpoint that ran off to infinity) as the
/// strings "inf", "-inf" or "NaN" instead of serde's silent null.
fn number(v: f64) -> serde_json::Value {
    if v.is_finite() {
        json!(v)
    } else {
        json!(v.to_string())
    }
}

fn numbers(values: &[f64]) -> Vec<serde_json::Value> {
    values.iter().map(|&v| number(v)).collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    crate::summary(&mut v).0
}

/// Runs the study and prints one line per realisation, then the summary.
pub fn run(a: &Args) -> Result<(), String> {
    if a.runs == 0 || a.iters == 0 || a.particles < 2 || a.steps < 50 {
        return Err("--runs, --iters >= 1, --particles >= 2 and --steps >= 50".into());
    }
    if let Some(dir) = &a.csv_dir {
        for name in ["nonlinearities.csv", "magnitudes.csv"] {
            if dir.join(name).exists() && !a.force {
                return Err(format!(
                    "{}: refusing to overwrite (use --force)",
                    dir.join(name).display()
                ));
            }
        }
    }
    let outcomes: Vec<Outcome> = (0..a.runs)
        .into_par_iter()
        .map(|run| {
            let o = realisation(a, run);
            if let Ok(o) = &o {
                eprintln!("wiener: realisation {run} done in {:.1} s", o.seconds);
            }
            o
        })
        .collect::<Result<_, _>>()?;
    let truth = BlindWiener::BETA;
    let mut breakpoint_errors = vec![Vec::new(); 4];
    let (mut r_errors, mut magnitude_errors, mut seconds) = (Vec::new(), Vec::new(), Vec::new());
    for o in &outcomes {
        let e = &o.estimate;
        let errors: Vec<f64> = e
            .beta
            .iter()
            .zip(truth)
            .map(|(b, t)| (b - t).abs())
            .collect();
        let magnitude = normalised_magnitude_error(e);
        for (all, &err) in breakpoint_errors.iter_mut().zip(&errors) {
            all.push(err);
        }
        r_errors.push(
            (e.r[0] - BlindWiener::R[0])
                .abs()
                .max((e.r[1] - BlindWiener::R[1]).abs()),
        );
        magnitude_errors.push(magnitude);
        seconds.push(o.seconds);
        emit(
            &json!({"task": "wiener_run", "params": {"run": o.run, "T": a.steps, "M": a.particles, "iterations": a.iters},
            "beta": numbers(&e.beta), "beta_abs_error": numbers(&errors), "r": numbers(&e.r),
            "a": e.a.iter().map(|row| numbers(row)).collect::<Vec<_>>(),
            "q": e.q.iter().map(|row| numbers(row)).collect::<Vec<_>>(),
            "magnitude_error_start": number(o.start_error), "magnitude_error": number(magnitude),
            "loglik_estimate": o.loglik, "seconds": o.seconds}),
        );
    }
    let relative: Vec<f64> = breakpoint_errors
        .iter()
        .zip(truth)
        .map(|(e, t)| median(e.clone()) / t.abs())
        .collect();
    emit(
        &json!({"task": "wiener_summary", "params": {"runs": a.runs, "T": a.steps, "M": a.particles,
            "iterations": a.iters, "m_step": a.m_step, "filter": a.filter, "hold": a.hold, "bfgs_iters": a.bfgs_iters, "seed": a.seed},
        "breakpoint_median_abs_error_relative": numbers(&relative),
        "breakpoints_met": relative.iter().all(|&r| r <= 0.1),
        "r_median_max_abs_error": number(median(r_errors)),
        "magnitude_error_median": number(median(magnitude_errors.clone())),
        "magnitude_met": median(magnitude_errors) <= 0.1,
        "seconds_per_realisation_median": median(seconds)}),
    );
    if let Some(dir) = &a.csv_dir {
        write_csv(dir, &outcomes).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    Ok(())
}

/// The estimated nonlinearities on a grid of z and the normalised magnitudes on the
/// frequency grid, with the truth as run -1.
fn write_csv(dir: &std::path::Path, outcomes: &[Outcome]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let truth = WienerEstimate {
        a: BlindWiener::A,
        q: [[1.0, 0.0], [0.0, 0.0]],
        beta: BlindWiener::BETA,
        r: BlindWiener::R,
    };
    let mut nl = std::io::BufWriter::new(std::fs::File::create(dir.join("nonlinearities.csv"))?);
    writeln!(nl, "run,z,h1,h2")?;
    let rows = std::iter::once((-1i64, &truth))
        .chain(outcomes.iter().map(|o| (o.run as i64, &o.estimate)));
    for (run, e) in rows.clone() {
        for k in 0..=120 {
            let z = -6.0 + 0.1 * k as f64;
            let b = e.beta;
            writeln!(
                nl,
                "{run},{z},{},{}",
                saturation(z, b[0], b[1]),
                dead_zone(z, b[2], b[3])
            )?;
        }
    }
    nl.flush()?;
    let mut mag = std::io::BufWriter::new(std::fs::File::create(dir.join("magnitudes.csv"))?);
    writeln!(mag, "run,omega,magnitude_normalised")?;
    let grid = wiener_frequency_grid();
    for (run, e) in rows {
        let values: Vec<f64> = if run < 0 {
            grid.iter().map(|&w| BlindWiener::magnitude(w)).collect()
        } else {
            grid.iter().map(|&w| e.magnitude(w)).collect()
        };
        let rms = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
        for (w, v) in grid.iter().zip(values) {
            writeln!(mag, "{run},{w},{}", v / rms)?;
        }
    }
    mag.flush()
}
