//! `lti2x2` runner: the seed-004 reproduction (Gibson and Ninness). For each of
//! `datasets` seeded data sets (T steps, output noise variance 0.01, white N(0, I)
//! inputs), EM from the paper's initial model and EM from N4SID (order 8); reports the
//! log-likelihoods, iterations and frequency-response errors.

use crate::emit;
use rayon::prelude::*;
use serde_json::{Value, json};
use std::time::Instant;
use sysid::em::linear::fit;
use sysid::em::{EmOptions, Termination};
use sysid::kalman::{KalmanWorkspace, LinearGaussianModel};
use sysid::models::{
    LTI2X2_PAPER_START_Q, System, lti2x2, lti2x2_experiment_start, lti2x2_paper_start,
};
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Frequency grid of the response errors.
const GRID: usize = 512;

pub struct Args {
    pub datasets: usize,
    pub steps: usize,
    pub seed: u64,
    pub max_iter: usize,
    pub tol: f64,
}

fn termination_name<E>(t: &Termination<E>) -> &'static str {
    match t {
        Termination::Converged => "converged",
        Termination::MaxIterations => "max_iterations",
        Termination::LikelihoodDecreased { .. } => "likelihood_decreased",
        Termination::Error { .. } => "error",
        _ => "other",
    }
}

fn one_dataset(index: usize, args: &Args) -> Vec<Value> {
    let seed = args.seed + index as u64;
    let sim = System::Lti2x2
        .simulate(args.steps, seed)
        .expect("simulation");
    let truth = lti2x2();
    let records = [sim.record];
    let loglik_true = KalmanWorkspace::new()
        .loglik(&truth, &records[0])
        .expect("loglik");
    let spec = sysid::models::lti2x2_em_spec();
    let options = EmOptions {
        max_iterations: args.max_iter,
        tol: args.tol,
        ..EmOptions::default()
    }
    .check()
    .expect("valid options");
    let paper = lti2x2_paper_start();
    let n4sid_start = Instant::now();
    let subspace = n4sid(
        &records[0],
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        },
    );
    let n4sid_seconds = n4sid_start.elapsed().as_secs_f64();
    let mut lines = Vec::new();
    let starts: Vec<(&str, Option<LinearGaussianModel>)> = vec![
        ("paper", Some(paper)),
        (
            "n4sid",
            subspace
                .as_ref()
                .ok()
                .map(|r| lti2x2_experiment_start(&r.model)),
        ),
    ];
    for (name, start) in starts {
        let Some(start) = start else {
            lines.push(json!({"task": "lti2x2_run", "params": {"dataset": index, "seed": seed, "start": name},
                "error": format!("{:?}", subspace.as_ref().err())}));
            continue;
        };
        let loglik_initial = KalmanWorkspace::new().loglik(&start, &records[0]).ok();
        let error_initial = start.relative_response_error(&truth, GRID);
        let t0 = Instant::now();
        let result = fit(start, &records, spec.clone(), &options, &mut ());
        let seconds = t0.elapsed().as_secs_f64();
        let mut line = json!({
            "task": "lti2x2_run",
            "params": {"dataset": index, "seed": seed, "start": name, "T": args.steps,
                       "max_iter": args.max_iter, "tol": args.tol, "initial_q": LTI2X2_PAPER_START_Q},
            "loglik_true": loglik_true,
            "loglik_initial": loglik_initial,
            "loglik_final": result.loglik,
            "iterations": result.iterations,
            "termination": termination_name(&result.termination),
            "response_error_initial": error_initial,
            "response_error_final": result.estimate.relative_response_error(&truth, GRID),
            "seconds": seconds,
            "ms_per_iteration": 1e3 * seconds / (result.iterations.max(1) as f64),
        });
        if name == "n4sid" {
            line["n4sid_seconds"] = json!(n4sid_seconds);
        }
        lines.push(line);
    }
    lines
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let k = v.len();
    Some(if k % 2 == 1 {
        v[k / 2]
    } else {
        0.5 * (v[k / 2 - 1] + v[k / 2])
    })
}

pub fn run(args: &Args) {
    let start = Instant::now();
    let all: Vec<Vec<Value>> = (0..args.datasets)
        .into_par_iter()
        .map(|d| one_dataset(d, args))
        .collect();
    let lines: Vec<Value> = all.into_iter().flatten().collect();
    for line in &lines {
        emit(line);
    }
    let pick = |start: &str, key: &str| -> Vec<f64> {
        lines
            .iter()
            .filter(|l| l["params"]["start"] == start)
            .filter_map(|l| l[key].as_f64())
            .collect()
    };
    let n4sid_runs: Vec<&Value> = lines
        .iter()
        .filter(|l| l["params"]["start"] == "n4sid")
        .collect();
    let at_least_true = n4sid_runs
        .iter()
        .filter(
            |l| match (l["loglik_final"].as_f64(), l["loglik_true"].as_f64()) {
                (Some(f), Some(t)) => f >= t,
                _ => false,
            },
        )
        .count();
    emit(&json!({
        "task": "lti2x2_summary",
        "params": {"datasets": args.datasets, "T": args.steps, "seed": args.seed,
                   "max_iter": args.max_iter, "tol": args.tol},
        "n4sid_start_final_loglik_at_least_true": at_least_true,
        "n4sid_runs": n4sid_runs.len(),
        "median_response_error_paper_initial": median(pick("paper", "response_error_initial")),
        "median_response_error_n4sid": median(pick("n4sid", "response_error_initial")),
        "median_response_error_em_from_paper": median(pick("paper", "response_error_final")),
        "median_response_error_em_from_n4sid": median(pick("n4sid", "response_error_final")),
        "median_iterations_from_paper": median(pick("paper", "iterations")),
        "median_iterations_from_n4sid": median(pick("n4sid", "iterations")),
        "median_ms_per_iteration": median(pick("n4sid", "ms_per_iteration")),
        "median_n4sid_seconds": median(pick("n4sid", "n4sid_seconds")),
        "seconds_total": start.elapsed().as_secs_f64(),
    }));
}
