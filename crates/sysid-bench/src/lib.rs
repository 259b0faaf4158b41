//! Experiment and benchmark runners (the `sysid-bench` binary and `sysid bench`). Output contract (DESIGN.md section 4): one JSON
//! object per line with `"task"`, `"params"` and figures whose keys carry their units;
//! a study ends with a `"<runner>_summary"` line.
//!
//! ```text
//! cargo run --release -p sysid-bench -- kalman [--reps 21]
//! cargo run --release -p sysid-bench -- smc [--reps 21]
//! cargo run --release -p sysid-bench -- nlbench-em [--runs 200 --iters 1000 --particles 50 --shard 0/2]
//! cargo run --release -p sysid-bench -- pendulum-em [--runs 50 --method robust]
//! cargo run --release -p sysid-bench -- modelfile-em [--runs 20 --iters 200]
//! cargo run --release -p sysid-bench -- pmcmc [--reps 11]
//! cargo run --release -p sysid-bench -- loglik-variance [--runs 200 --reps 11]
//! cargo run --release -p sysid-bench -- wiener [--runs 100 --iters 100 --particles 100 --csv-dir out/]
//! ```

mod em;
mod kalman;
pub mod loglik_variance;
mod lti2x2;
mod modelfile_em;
pub mod nlbench_em;
pub mod nlbench_study;
mod pendulum_em;
mod pmcmc;
pub mod report;
mod smc;
mod wiener;

use clap::Subcommand;
use std::sync::Mutex;

/// The runners, as subcommands.
#[derive(Subcommand, Debug)]
pub enum Runner {
    /// Square-root Kalman filter and smoother timings (ns per time step).
    Kalman {
        /// Repetitions per task; medians are reported.
        #[arg(long, default_value_t = 21)]
        reps: usize,
        /// Only run the cases of this system (lgss or lti2x2).
        #[arg(long)]
        system: Option<String>,
    },
    /// One linear EM iteration and N4SID on lti2x2 (ms).
    Em {
        /// Repetitions; medians are reported.
        #[arg(long, default_value_t = 21)]
        reps: usize,
    },
    /// Particle filter and smoothers on nlbench (ms; targets of the SMC issue).
    Smc {
        /// Repetitions; medians are reported.
        #[arg(long, default_value_t = 21)]
        reps: usize,
    },
    /// PMMH and particle Gibbs: iteration times, chain throughput, and the lgss
    /// posterior against an exact-likelihood chain.
    Pmcmc {
        /// Repetitions of the timings; medians are reported.
        #[arg(long, default_value_t = 11)]
        reps: usize,
    },
    /// The single-run sd of the particle log-likelihood against the sd over independent
    /// runs (lgss at M = 100 and 1000, nlbench at 10 000), and its cost.
    LoglikVariance(loglik_variance::Args),
    /// Seed-001 blind Wiener identification by gradient EM (one JSON line per
    /// realisation, then a summary).
    Wiener(wiener::Args),
    /// Seed-000 particle-EM study on nlbench (one JSON line per run, then a summary).
    NlbenchEm(nlbench_em::Args),
    /// Particle EM beyond nlbench: the driven pendulum (two states, three physical coefficients)
    /// from starts at +-50 %, robust driver or the paper's algorithm.
    PendulumEm(pendulum_em::Args),
    /// nlbench as a model file against the built-in nlbench under the same particle EM
    /// (same data, starts and seeds; medians of a, b, c, d with bootstrap standard
    /// errors).
    ModelfileEm(modelfile_em::Args),
    /// Merges the outputs of `nlbench-em` shards into one set of run lines and summary.
    NlbenchEmMerge {
        /// JSON-lines files written by `nlbench-em --shard i/n`.
        files: Vec<std::path::PathBuf>,
    },
    /// Draws seed 000's Figure 1 (a, b, c, d against the iteration, one line per run,
    /// the truth dashed) from an `nlbench-em` output and its `--trace-out` file.
    NlbenchEmFigure {
        /// The runner's JSON lines (for each run's start).
        #[arg(long)]
        runs: std::path::PathBuf,
        /// The runner's trajectories (`--trace-out`).
        #[arg(long)]
        trace: std::path::PathBuf,
        /// Directory of the figure (STEM.svg, STEM.png).
        #[arg(long)]
        out_dir: std::path::PathBuf,
        /// File stem.
        #[arg(long, default_value = "nlbench-em")]
        stem: String,
        /// Title of the panels.
        #[arg(long, default_value = "particle EM")]
        title: String,
        /// Draw the first this many runs.
        #[arg(long, default_value_t = 50)]
        max_runs: usize,
        /// Replace an existing figure.
        #[arg(long)]
        force: bool,
    },
    /// Runs every runner at a chosen scale and writes docs/benchmarks.md (tables,
    /// targets, floors, reproduction accuracy) and its figures.
    Report(report::Args),
    /// Seed-004 reproduction: EM from the paper's initial model and from N4SID on
    /// lti2x2 data sets.
    Lti2x2 {
        /// Number of seeded data sets.
        #[arg(long, default_value_t = 100)]
        datasets: usize,
        /// Time steps per data set.
        #[arg(long, default_value_t = 200)]
        steps: usize,
        /// Seed of the first data set (data set d uses seed + d).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// EM iteration limit.
        #[arg(long, default_value_t = 1000)]
        max_iter: usize,
        /// EM stopping tolerance (seed-002 relative rule).
        #[arg(long, default_value_t = 1e-7)]
        tol: f64,
    },
}

/// Runs one runner; its JSON lines go to stdout (or to the capture of [`capture`]).
/// A bad option is an `Err` with a one-line message.
pub fn run(runner: Runner) -> Result<(), String> {
    match runner {
        Runner::Kalman { reps, system } => kalman::run(reps.max(1), system.as_deref()),
        Runner::Em { reps } => em::run(reps.max(1)),
        Runner::Smc { reps } => smc::run(reps.max(1)),
        Runner::Pmcmc { reps } => pmcmc::run(reps.max(1)),
        Runner::Wiener(args) => wiener::run(&args)?,
        Runner::LoglikVariance(args) => loglik_variance::run(&args)?,
        Runner::NlbenchEm(args) => nlbench_em::run(&args)?,
        Runner::PendulumEm(args) => pendulum_em::run(&args)?,
        Runner::ModelfileEm(args) => modelfile_em::run(&args)?,
        Runner::NlbenchEmMerge { files } => nlbench_em::merge(&files)?,
        Runner::NlbenchEmFigure {
            runs,
            trace,
            out_dir,
            stem,
            title,
            max_runs,
            force,
        } => nlbench_em::figure(&runs, &trace, &out_dir, &stem, &title, max_runs, force)?,
        Runner::Report(args) => report::run(&args)?,
        Runner::Lti2x2 {
            datasets,
            steps,
            seed,
            max_iter,
            tol,
        } => lti2x2::run(&lti2x2::Args {
            datasets,
            steps,
            seed,
            max_iter,
            tol,
        }),
    }
    Ok(())
}

/// Prints one JSON line (or, inside [`capture`], records it); a closed stdout (e.g. `| head -1`) ends the program quietly,
/// as for any Unix filter, instead of panicking.
pub fn emit(value: &serde_json::Value) {
    use std::io::Write;
    if let Some(lines) = CAPTURE.lock().unwrap_or_else(|e| e.into_inner()).as_mut() {
        lines.push(value.clone());
        return;
    }
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{value}").and_then(|_| out.flush()).is_err() {
        std::process::exit(0);
    }
}

/// Median, minimum and maximum of a sample (sorted in place).
pub fn summary(samples: &mut [f64]) -> (f64, f64, f64) {
    samples.sort_by(f64::total_cmp);
    let k = samples.len();
    let median = if k % 2 == 1 {
        samples[k / 2]
    } else {
        0.5 * (samples[k / 2 - 1] + samples[k / 2])
    };
    (median, samples[0], samples[k - 1])
}

/// JSON lines recorded instead of printed, while [`capture`] runs.
static CAPTURE: Mutex<Option<Vec<serde_json::Value>>> = Mutex::new(None);

/// Runs `f` with the runners' JSON lines recorded instead of printed; returns them.
pub fn capture(f: impl FnOnce() -> Result<(), String>) -> Result<Vec<serde_json::Value>, String> {
    *CAPTURE.lock().unwrap_or_else(|e| e.into_inner()) = Some(Vec::new());
    let result = f();
    let lines = CAPTURE
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take()
        .unwrap_or_default();
    result.map(|()| lines)
}
