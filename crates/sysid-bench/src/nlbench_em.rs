//! `nlbench-em` runner: the seed-000 particle-EM study (ALGORITHMS.md 3).
//!
//! Run `r` draws its data set from seed `stream(seed, 3r)`, its starting point (each of
//! a, b, c, d times an independent U[0.5, 1.5]) from `stream(seed, 3r + 1)` and its EM
//! random streams from `stream(seed, 3r + 2)`, so a run's output depends only on
//! `(seed, r)`: runs go in parallel in any order, and shards (`--shard i/n` takes the
//! runs with `r % n == i`) merge into exactly the unsharded output.

use crate::emit;
use crate::nlbench_study::{Method, NlbenchStudy, abcd, within_ten_percent as converged};
use rayon::prelude::*;
use serde_json::json;
use std::io::Write;
use sysid::em::affine::{RobustFit, RobustOptions, describe};
use sysid::models::{Nlbench, NlbenchAffine, NlbenchParams};
use sysid::smc::{FfbsiReject, FilterOptions, ParticleFilter, Series, Smoother, Tanizaki};

/// The runner's settings (the `nlbench-em` command line).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of Monte Carlo runs (each with its own data set and start).
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// EM iterations per run.
    #[arg(long, default_value_t = 1000)]
    pub iters: usize,
    /// Particles M (and smoothed paths for ffbsi-reject).
    #[arg(long, default_value_t = 50)]
    pub particles: usize,
    /// Data length T.
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// E-step smoother: tanizaki (the paper's) or ffbsi-reject.
    #[arg(long, default_value = "tanizaki")]
    pub smoother: String,
    /// Study seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run only the runs r with r % n == i, given as i/n.
    #[arg(long, default_value = "0/1", value_parser = parse_shard)]
    pub shard: (usize, usize),
    /// Write the (run, iteration, a, b, c, d) trajectories to this CSV file.
    #[arg(long)]
    pub trace_out: Option<std::path::PathBuf>,
    /// Replace an existing trace file.
    #[arg(long)]
    pub force: bool,
    /// How the runs fit: `paper` (the paper's Algorithm 2: q and r estimated from 10
    /// times their true values), `held-noise` (a variant: q and r held at the truth),
    /// `q` (a variant: q estimated from 100 times the truth, r held) or `robust` (the
    /// robust driver, `sysid_em::affine::fit_robust`, with the options below).
    #[arg(long, default_value = "paper")]
    pub method: String,
    /// robust: number of starts.
    #[arg(long, default_value_t = RobustOptions::default().starts)]
    pub starts: usize,
    /// robust: EM iterations per start (at --particles).
    #[arg(long, default_value_t = RobustOptions::default().explore_iterations)]
    pub explore_iters: usize,
    /// robust: EM iterations of the refinement.
    #[arg(long, default_value_t = RobustOptions::default().refine_iterations)]
    pub refine_iters: usize,
    /// robust: particles of the refinement.
    #[arg(long, default_value_t = RobustOptions::default().refine_particles)]
    pub refine_particles: usize,
    /// robust: particles of the filter that ranks the starts.
    #[arg(long, default_value_t = RobustOptions::default().select_particles)]
    pub select_particles: usize,
    /// robust: half-width of the starts' multiplicative perturbation.
    #[arg(long, default_value_t = RobustOptions::default().spread)]
    pub spread: f64,
    /// robust: factor on the noise variances at every start.
    #[arg(long, default_value_t = RobustOptions::default().noise_inflation)]
    pub inflation: f64,
    /// robust: a process-noise variance above this factor times its start stops a
    /// start as a runaway.
    #[arg(long, default_value_t = RobustOptions::default().runaway_factor)]
    pub runaway_factor: f64,
    /// robust: particles of the polish (the estimate's likelihood maximised directly;
    /// `sysid fit`'s default is 10 000). Default 0, off: the study's criterion is a, b,
    /// c, d within 10 %, which the refinement meets without it (docs/particle-em.md's
    /// results), and the polish would multiply the study's time by about 5.
    #[arg(long, default_value_t = 0)]
    pub polish_particles: usize,
    /// robust: extrapolate the refinement's drift (`RobustOptions::extrapolate`, the
    /// library's default). Off by default here: the documented studies ran without it.
    #[arg(long)]
    pub extrapolate: bool,
    /// Start every run at the truth (the no-drift check) instead of a random start.
    #[arg(long)]
    pub at_truth: bool,
}

/// `i/n` as `(i, n)`.
fn parse_shard(text: &str) -> Result<(usize, usize), String> {
    text.split_once('/')
        .and_then(|(i, n)| Some((i.parse().ok()?, n.parse().ok()?)))
        .ok_or_else(|| format!("{text:?}: expected i/n"))
}

/// Particles of the reference filter that scores the truth and the final estimate.
const REFERENCE_PARTICLES: usize = 10_000;

/// A final estimate counts as reaching the truth's likelihood when its reference
/// log-likelihood is at most this many nats below the truth's.
const REFERENCE_SLACK: f64 = 10.0;

/// One run's result.
struct RunResult {
    run: usize,
    start: NlbenchParams,
    estimate: NlbenchParams,
    iterations: usize,
    decreases: usize,
    final_loglik: f64,
    /// Reference log-likelihoods (a large-M filter on the run's data) at the truth and
    /// at the final estimate, to tell a poor data set from a poor EM run.
    reference_truth: Option<f64>,
    reference_start: Option<f64>,
    reference_final: Option<f64>,
    seconds: f64,
    /// (a, b, c, d) after each iteration
    trace: Vec<[f64; 4]>,
    /// The robust driver's starts, maxima, warnings and timing.
    robust: Option<serde_json::Value>,
}

/// The `--method` option with the robust settings.
fn method(a: &Args) -> Result<Method, String> {
    Ok(match a.method.as_str() {
        "paper" => Method::Paper,
        "held-noise" => Method::HeldNoise,
        "q" => Method::ProcessNoise,
        "robust" => Method::Robust(RobustOptions {
            starts: a.starts,
            explore_iterations: a.explore_iters,
            refine_iterations: a.refine_iters,
            refine_particles: a.refine_particles,
            select_particles: a.select_particles,
            spread: a.spread,
            noise_inflation: a.inflation,
            runaway_factor: a.runaway_factor,
            polish_particles: a.polish_particles,
            extrapolate: a.extrapolate,
            ..RobustOptions::default()
        }),
        other => {
            return Err(format!(
                "--method {other:?}: use paper, held-noise, q or robust"
            ));
        }
    })
}

/// What the robust driver reports about a run.
fn robust_json(fit: &RobustFit) -> serde_json::Value {
    let params = |p: &sysid::em::affine::AffineParams| {
        let n = NlbenchAffine::nlbench_params(p);
        json!({"a": n.a, "b": n.b, "c": n.c, "d": n.d, "q": n.q, "r": n.r})
    };
    json!({
        "starts": fit.starts.iter().map(|o| json!({
            "status": describe(&o.status), "loglik": o.loglik,
            "noise_escalations": o.noise_escalations, "estimate": params(&o.estimate),
        })).collect::<Vec<_>>(),
        "maxima": fit.maxima.iter().map(|m| json!({
            "loglik": m.loglik, "starts": m.starts, "estimate": params(&m.estimate),
        })).collect::<Vec<_>>(),
        "selected_loglik": fit.selected.loglik,
        "refine_stop": format!("{:?}", fit.stop),
        "warnings": fit.warnings,
        "seconds": {"explore": fit.timing.explore.as_secs_f64(),
            "select": fit.timing.select.as_secs_f64(), "refine": fit.timing.refine.as_secs_f64()},
    })
}

fn run_one<S: Smoother<Nlbench> + Clone + Send + Sync>(
    a: &Args,
    run: usize,
    smoother: S,
) -> Result<RunResult, String> {
    let study = NlbenchStudy {
        seed: a.seed,
        steps: a.steps,
        particles: a.particles,
        iterations: a.iters,
        method: method(a)?,
        at_truth: a.at_truth,
    };
    let r = study
        .run(run, smoother, &mut ())
        .map_err(|e| e.to_string())?;
    let reference_data = Series::new(&r.outputs, 1).map_err(|e| e.to_string())?;
    let reference = |params: NlbenchParams| -> Option<f64> {
        let model = Nlbench::new(params).ok()?;
        let mut filter = ParticleFilter::new(FilterOptions {
            particles: REFERENCE_PARTICLES,
            ..FilterOptions::default()
        })
        .ok()?;
        filter
            .run(&model, &reference_data, study.run_seed(run, 2))
            .ok()
            .map(|s| s.loglik)
    };
    Ok(RunResult {
        run,
        start: r.start,
        estimate: r.estimate,
        reference_truth: reference(NlbenchParams::TRUE),
        reference_start: reference(r.start),
        reference_final: reference(r.estimate),
        iterations: r.iterations,
        decreases: r.decreases,
        final_loglik: r.loglik.unwrap_or(f64::NAN),
        seconds: r.elapsed.as_secs_f64(),
        robust: r.robust.as_ref().map(robust_json),
        trace: r.trajectory,
    })
}

/// The study's settings, as every line of its output repeats them.
fn params_json(a: &Args) -> serde_json::Value {
    let (index, count) = a.shard;
    json!({"T": a.steps, "M": a.particles, "iters": a.iters, "runs": a.runs,
        "smoother": a.smoother, "seed": a.seed, "method": a.method, "at_truth": a.at_truth,
        "shard": format!("{index}/{count}")})
}

/// A run's line of the output.
fn line_json(params: &serde_json::Value, r: &RunResult) -> serde_json::Value {
    let [sa, sb, sc, sd] = abcd(&r.start);
    let [ea, eb, ec, ed] = abcd(&r.estimate);
    json!({
        "task": "nlbench_em_run", "params": params, "run": r.run,
        "start": {"a": sa, "b": sb, "c": sc, "d": sd},
        "estimate": {"a": ea, "b": eb, "c": ec, "d": ed, "q": r.estimate.q, "r": r.estimate.r},
        "converged": converged(&r.estimate), "iterations": r.iterations,
        "trajectory_inside_box": r.trace.iter().all(inside_box),
        "likelihood_decreases": r.decreases, "final_loglik": r.final_loglik,
        "reference_loglik": {"truth": r.reference_truth, "start": r.reference_start,
            "final": r.reference_final,
            "particles": REFERENCE_PARTICLES},
        "seconds": r.seconds, "robust": r.robust,
    })
}

/// The settings of a study from the runner's flags (`["--runs", "8", ...]`), at the
/// command line's defaults for the flags not given.
///
/// # Errors
/// A flag the runner does not know, or a value it cannot read.
pub fn args_from(flags: &[String]) -> Result<Args, String> {
    use clap::Parser;
    #[derive(clap::Parser)]
    struct Flags {
        #[command(flatten)]
        args: Args,
    }
    let all = std::iter::once("nlbench-em".to_string()).chain(flags.iter().cloned());
    Flags::try_parse_from(all)
        .map(|f| f.args)
        .map_err(|e| e.to_string().lines().next().unwrap_or_default().to_string())
}

/// Run `run` of the study `a`: its output line, as `nlbench-em` prints it (whatever
/// shard it belongs to: a run depends only on the study's seed and its index, so
/// that runs spread over workers in any way give the study's lines).
///
/// # Errors
/// Bad settings (`--method`, `--smoother`), a run index outside `0..runs`, or a run
/// that fails.
pub fn run_line(a: &Args, run: usize) -> Result<serde_json::Value, String> {
    method(a)?;
    if run >= a.runs {
        return Err(format!("run {run}: the study has {} runs", a.runs));
    }
    Ok(line_json(&params_json(a), &result_of(a, run)?))
}

/// Run `run` with the study's smoother.
fn result_of(a: &Args, run: usize) -> Result<RunResult, String> {
    match a.smoother.as_str() {
        "tanizaki" => run_one(a, run, Tanizaki::default()),
        "ffbsi-reject" => run_one(
            a,
            run,
            FfbsiReject {
                paths: a.particles,
                max_trials: None,
                parallel: false,
            },
        ),
        other => Err(format!(
            "--smoother {other:?}: use tanizaki or ffbsi-reject"
        )),
    }
}

/// Whether (a, b, c, d) are all within 10 % of the truth.
fn inside_box(v: &[f64; 4]) -> bool {
    v.iter()
        .zip(abcd(&NlbenchParams::TRUE))
        .all(|(x, t)| ((x - t) / t).abs() <= 0.1)
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (pos - lo as f64) * (sorted[hi] - sorted[lo])
}

/// Runs the study and prints JSON lines.
pub fn run(a: &Args) -> Result<(), String> {
    method(a)?;
    if a.runs == 0 || a.iters == 0 || a.particles == 0 || a.steps < 2 {
        return Err("--runs, --iters and --particles must be >= 1 and --steps >= 2".into());
    }
    let (index, count) = a.shard;
    if count == 0 || index >= count {
        return Err(format!("--shard {index}/{count}: need 0 <= i < n"));
    }
    if let Some(path) = &a.trace_out
        && path.exists()
        && !a.force
    {
        return Err(format!(
            "{}: refusing to overwrite (use --force)",
            path.display()
        ));
    }
    let runs: Vec<usize> = (0..a.runs).filter(|r| r % count == index).collect();
    let started = std::time::Instant::now();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let progress = |result: Result<RunResult, String>| {
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if let Ok(r) = &result {
            eprintln!(
                "nlbench-em: run {} done ({k}/{}, {:.1} s, converged {})",
                r.run,
                runs.len(),
                r.seconds,
                converged(&r.estimate)
            );
        }
        result
    };
    let results: Vec<Result<RunResult, String>> = runs
        .par_iter()
        .map(|&run| result_of(a, run))
        .map(progress)
        .collect();
    let results: Vec<RunResult> = results.into_iter().collect::<Result<_, _>>()?;
    let params = params_json(a);
    for r in &results {
        emit(&line_json(&params, r));
    }
    if let Some(path) = &a.trace_out {
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?,
        );
        let io = |e: std::io::Error| format!("{}: {e}", path.display());
        writeln!(w, "run,iteration,a,b,c,d").map_err(io)?;
        for r in &results {
            for (k, v) in r.trace.iter().enumerate() {
                writeln!(w, "{},{},{},{},{},{}", r.run, k + 1, v[0], v[1], v[2], v[3])
                    .map_err(io)?;
            }
        }
        w.flush().map_err(io)?;
    }
    let estimates: Vec<NlbenchParams> = results.iter().map(|r| r.estimate).collect();
    let seconds: Vec<f64> = results.iter().map(|r| r.seconds).collect();
    let references: Vec<(f64, f64)> = results
        .iter()
        .map(|r| {
            (
                r.reference_truth.unwrap_or(f64::NAN),
                r.reference_final.unwrap_or(f64::NAN),
            )
        })
        .collect();
    let mut summary = summary_json(&params, &estimates, &references, &seconds);
    summary["wall_seconds"] = json!(started.elapsed().as_secs_f64());
    summary["threads"] = json!(rayon::current_num_threads());
    emit(&summary);
    Ok(())
}

/// The study summary of a set of runs: fraction converged, median and IQR of each
/// estimate, median seconds per run. Computed from the run lines alone, so merged
/// shards give the same figures as one unsharded run.
fn summary_json(
    params: &serde_json::Value,
    estimates: &[NlbenchParams],
    references: &[(f64, f64)],
    seconds: &[f64],
) -> serde_json::Value {
    // How far each final estimate's likelihood falls below the truth's.
    let mut gaps: Vec<f64> = references.iter().map(|(t, f)| t - f).collect();
    gaps.sort_by(f64::total_cmp);
    let near_truth = gaps.iter().filter(|&&g| g <= REFERENCE_SLACK).count();
    let converged_count = estimates.iter().filter(|p| converged(p)).count();
    let summary_of = |f: fn(&NlbenchParams) -> f64| {
        let mut v: Vec<f64> = estimates.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        json!({"median": quantile(&v, 0.5), "q25": quantile(&v, 0.25), "q75": quantile(&v, 0.75)})
    };
    let mut seconds = seconds.to_vec();
    seconds.sort_by(f64::total_cmp);
    json!({
        "task": "nlbench_em_summary", "params": params,
        "runs_done": estimates.len(), "converged": converged_count,
        "fraction_converged": converged_count as f64 / estimates.len() as f64,
        "a": summary_of(|p| p.a), "b": summary_of(|p| p.b),
        "c": summary_of(|p| p.c), "d": summary_of(|p| p.d),
        "seconds_per_run_median": quantile(&seconds, 0.5),
        "reference": {"particles": REFERENCE_PARTICLES, "slack_nats": REFERENCE_SLACK,
            "final_within_slack_of_truth": near_truth,
            "gap_truth_minus_final": {"median": quantile(&gaps, 0.5),
                "q25": quantile(&gaps, 0.25), "q75": quantile(&gaps, 0.75)}},
    })
}

/// Merges the JSON-lines outputs of shards: re-emits the run lines in run order (each
/// run once) and the summary of all of them.
pub fn merge(files: &[std::path::PathBuf]) -> Result<(), String> {
    let mut lines = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        for (k, line) in text.lines().enumerate() {
            let value: serde_json::Value = serde_json::from_str(line)
                .map_err(|e| format!("{}, line {}: {e}", path.display(), k + 1))?;
            if value["task"] == "nlbench_em_run" && value["run"].as_u64().is_none() {
                return Err(format!("{}, line {}: no run index", path.display(), k + 1));
            }
            lines.push(value);
        }
    }
    for line in merged(lines, &format!("merged from {} files", files.len()))? {
        emit(&line);
    }
    Ok(())
}

/// The run lines among `lines` (the outputs of shards, or of runs made one by one by
/// [`run_line`]), each run once and in run order, then the summary of all of them,
/// its `shard` labelled `label`: the output of the unsharded study but for the timing
/// fields and the labels.
///
/// # Errors
/// No run line among `lines`.
pub fn merged(
    lines: Vec<serde_json::Value>,
    label: &str,
) -> Result<Vec<serde_json::Value>, String> {
    let mut runs: std::collections::BTreeMap<u64, serde_json::Value> = Default::default();
    for value in lines {
        if value["task"] == "nlbench_em_run"
            && let Some(run) = value["run"].as_u64()
        {
            runs.insert(run, value);
        }
    }
    let Some(first) = runs.values().next() else {
        return Err("no nlbench_em_run lines in the inputs".into());
    };
    let mut params = first["params"].clone();
    params["shard"] = json!(label);
    let field = |v: &serde_json::Value, k: &str| v["estimate"][k].as_f64().unwrap_or(f64::NAN);
    let estimates: Vec<NlbenchParams> = runs
        .values()
        .map(|v| NlbenchParams {
            a: field(v, "a"),
            b: field(v, "b"),
            c: field(v, "c"),
            d: field(v, "d"),
            ..NlbenchParams::TRUE
        })
        .collect();
    let reference =
        |v: &serde_json::Value, k: &str| v["reference_loglik"][k].as_f64().unwrap_or(f64::NAN);
    let references: Vec<(f64, f64)> = runs
        .values()
        .map(|v| (reference(v, "truth"), reference(v, "final")))
        .collect();
    let seconds: Vec<f64> = runs
        .values()
        .map(|v| v["seconds"].as_f64().unwrap_or(f64::NAN))
        .collect();
    let summary = summary_json(&params, &estimates, &references, &seconds);
    Ok(runs.into_values().chain(std::iter::once(summary)).collect())
}

/// Seed 000's Figure 1 from a study's run lines (starts) and trajectories.
pub fn figure(
    runs_file: &std::path::Path,
    trace_file: &std::path::Path,
    out_dir: &std::path::Path,
    stem: &str,
    title: &str,
    max_runs: usize,
    force: bool,
) -> Result<(), String> {
    use sysid_plot::trajectories::{Run, parameter_trajectories};
    let read = |p: &std::path::Path| {
        std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))
    };
    let mut starts: std::collections::BTreeMap<u64, Vec<f64>> = Default::default();
    for (k, line) in read(runs_file)?.lines().enumerate() {
        let v: serde_json::Value = serde_json::from_str(line)
            .map_err(|e| format!("{}, line {}: {e}", runs_file.display(), k + 1))?;
        if v["task"] == "nlbench_em_run" {
            let field = |p: &str| v["start"][p].as_f64().unwrap_or(f64::NAN);
            let run = v["run"].as_u64().unwrap_or(u64::MAX);
            starts.insert(run, ["a", "b", "c", "d"].map(field).to_vec());
        }
    }
    let mut iterates: std::collections::BTreeMap<u64, Vec<Vec<f64>>> = Default::default();
    for (k, line) in read(trace_file)?.lines().enumerate().skip(1) {
        let values: Vec<f64> = line
            .split(',')
            .map(|f| f.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("{}, line {}: {e}", trace_file.display(), k + 1))?;
        let [run, _, a, b, c, d] = values[..] else {
            return Err(format!(
                "{}, line {}: expected run,iteration,a,b,c,d",
                trace_file.display(),
                k + 1
            ));
        };
        iterates
            .entry(run as u64)
            .or_default()
            .push(vec![a, b, c, d]);
    }
    let bundle: Vec<Run<'_>> = iterates
        .iter()
        .filter_map(|(run, it)| {
            starts.get(run).map(|start| Run {
                start: start.clone(),
                iterates: it,
            })
        })
        .take(max_runs)
        .collect();
    if bundle.is_empty() {
        return Err("no run has both a start and a trajectory".into());
    }
    let figure = parameter_trajectories(
        title,
        &["a", "b", "c", "d"],
        &abcd(&NlbenchParams::TRUE),
        &bundle,
        "EM iteration",
        500,
    );
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let written = figure
        .write(out_dir, stem, force)
        .map_err(|e| e.to_string())?;
    emit(&json!({"task": "nlbench_em_figure", "runs": bundle.len(), "written": written}));
    Ok(())
}
