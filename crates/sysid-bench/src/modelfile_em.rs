//! `modelfile-em` runner: nlbench written as a model file against the built-in nlbench
//! under the same particle EM (issue 35). Run `r` of both uses the seed-000 study's
//! data set, start and EM streams (`NlbenchStudy`, the paper's method: a, b, c, d from
//! U[0.5, 1.5] times the truth, q and r from 10 times theirs, Tanizaki's smoother);
//! the summary compares the medians of the final a, b, c, d with their bootstrap
//! standard errors.

use crate::emit;
use crate::nlbench_study::{NlbenchStudy, abcd};
use rand::RngExt;
use rayon::prelude::*;
use serde_json::json;
use sysid::em::affine::AffineEm;
use sysid::em::{EmOptions, run_em};
use sysid::models::{Nlbench, NlbenchAffine};
use sysid::smc::{Series, Tanizaki, stream};

/// Options of the runner.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of runs.
    #[arg(long, default_value_t = 20)]
    pub runs: usize,
    /// EM iterations per run.
    #[arg(long, default_value_t = 200)]
    pub iters: usize,
    /// Particles M.
    #[arg(long, default_value_t = 50)]
    pub particles: usize,
    /// Study seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// One run: the built-in's and the model file's final (a, b, c, d) and their seconds.
type RunPair = ([f64; 4], [f64; 4], f64, f64);

/// The median of `v`.
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    crate::summary(&mut s).0
}

/// The bootstrap standard error of the median (2000 resamples, fixed stream).
fn bootstrap_se(v: &[f64], seed: u64) -> f64 {
    let mut rng = stream(seed, 0);
    let medians: Vec<f64> = (0..2000)
        .map(|_| {
            let resample: Vec<f64> = (0..v.len())
                .map(|_| v[rng.random_range(0..v.len())])
                .collect();
            median(&resample)
        })
        .collect();
    let mean = medians.iter().sum::<f64>() / medians.len() as f64;
    (medians.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (medians.len() - 1) as f64).sqrt()
}

/// Runs the comparison.
pub fn run(a: &Args) -> Result<(), String> {
    if a.runs < 2 || a.iters == 0 || a.particles == 0 {
        return Err("--runs must be >= 2, --iters and --particles >= 1".into());
    }
    let file = sysid::modelfile::builtin::model("nlbench")
        .expect("shipped")
        .map_err(|e| e.to_string())?;
    let affine = file.affine().ok_or("nlbench is affine")?;
    let study = NlbenchStudy {
        seed: a.seed,
        particles: a.particles,
        iterations: a.iters,
        ..NlbenchStudy::default()
    };
    let options = EmOptions {
        max_iterations: a.iters,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| e.to_string())?;
    let results: Vec<Result<RunPair, String>> = (0..a.runs)
        .into_par_iter()
        .map(|run| {
            let began = std::time::Instant::now();
            let builtin = study
                .run(run, Tanizaki::default(), &mut ())
                .map_err(|e| e.to_string())?;
            let builtin_s = began.elapsed().as_secs_f64();
            // the same data set, start and EM seed, through the model file
            let sim = Nlbench::truth().simulate(study.steps, study.run_seed(run, 0));
            let data = Series::new(&sim.outputs, 1).map_err(|e| e.to_string())?;
            let start = NlbenchAffine::params(&study.start(run));
            let began = std::time::Instant::now();
            let mut em = AffineEm::new(
                &affine,
                data,
                a.particles,
                Tanizaki::default(),
                affine.em_spec(),
                study.run_seed(run, 2),
            )
            .map_err(|e| e.to_string())?;
            let result = run_em(&mut em, start, &options, &mut ());
            let theta = affine.theta(&result.estimate);
            let from_file = [theta[0], theta[1], theta[2], theta[3]];
            let b = abcd(&builtin.estimate);
            emit(&json!({"task": "modelfile_em_run", "params": {"run": run},
                "builtin": b, "model_file": from_file,
                "builtin_s": builtin_s, "model_file_s": began.elapsed().as_secs_f64()}));
            Ok((b, from_file, builtin_s, began.elapsed().as_secs_f64()))
        })
        .collect();
    let results: Vec<_> = results.into_iter().collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for (k, name) in ["a", "b", "c", "d"].iter().enumerate() {
        let b: Vec<f64> = results.iter().map(|r| r.0[k]).collect();
        let f: Vec<f64> = results.iter().map(|r| r.1[k]).collect();
        let (mb, mf) = (median(&b), median(&f));
        let (sb, sf) = (bootstrap_se(&b, 1), bootstrap_se(&f, 2));
        rows.push(
            json!({"parameter": name, "builtin_median": mb, "builtin_se": sb,
            "model_file_median": mf, "model_file_se": sf, "difference": mf - mb,
            "within_se": (mf - mb).abs() <= sb.max(sf)}),
        );
    }
    let seconds: (f64, f64) = results
        .iter()
        .fold((0.0, 0.0), |acc, r| (acc.0 + r.2, acc.1 + r.3));
    emit(&json!({"task": "modelfile_em_summary",
        "params": {"runs": a.runs, "iters": a.iters, "M": a.particles, "seed": a.seed},
        "medians": rows, "builtin_s_total": seconds.0, "model_file_s_total": seconds.1}));
    Ok(())
}
