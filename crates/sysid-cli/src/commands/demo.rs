//! `sysid demo` (and `cargo run --release`): the pipeline on the papers' systems.
//!
//! 1. Seed 004: the 2x2 system of McMillan degree 8, T = 200. N4SID (order 8), then
//!    exact EM from the N4SID model and from the paper's initial model.
//! 2. Seed 000: the particle-EM study on `nlbench` (M = 50, Tanizaki) at a reduced
//!    scale (2 runs x 200 iterations on T = 500, so that the demo takes under 20 s on two
//!    cores; `--full`: the paper's 200 x 1000 on T = 1000), the paper's EM against the
//!    robust default from the same data and starts.
//! 3. The smoothed state of one `nlbench` data set at its EM estimate, with a 95 %
//!    band, against the true state.
//!
//! Prints a table and writes four figures (SVG and PNG).

use crate::error::CliError;
use crate::files::fmt;
use crate::progress::{Progress, note};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;
use sysid::em::EmOptions;
use sysid::em::affine::RobustOptions;
use sysid::em::linear::fit;
use sysid::kalman::{KalmanWorkspace, LinearGaussianModel};
use sysid::models::{
    Nlbench, NlbenchParams, System, lti2x2, lti2x2_em_spec, lti2x2_experiment_start,
    lti2x2_paper_start,
};
use sysid::smc::{FfbsiReject, FilterOptions, ParticleFilter, Series, Smoother, Tanizaki};
use sysid::subspace::{N4sidOptions, Order, n4sid};
use sysid_bench::nlbench_study::{Method, NlbenchRun, NlbenchStudy, abcd, within_ten_percent};
use sysid_plot::trajectories::{Run, parameter_trajectories};
use sysid_plot::{Band, Figure, Panel, Series as Curve, Stroke};

/// The most particle-EM runs the demo takes (the paper's study has 200).
const MAX_RUNS: usize = 1000;

/// Particle-EM runs of the default demo: each robust run costs about 15 CPU-seconds
/// at T = 500 (its exploration, refinement and 10 000-particle polish), and the demo
/// is to finish within 20 s on two cores.
const DEMO_RUNS: usize = 2;

/// Data length of the default demo's runs (the paper's is 1000, `--full`).
const DEMO_STEPS: usize = 500;

/// The shortest data set the demo takes (shorter ones identify little).
const MIN_STEPS: usize = 50;

/// The longest (a million steps of 10 000 particles is already many minutes).
const MAX_STEPS: usize = 1_000_000;

/// The most EM iterations per run the demo takes (the paper's 1000).
const MAX_ITERATIONS: usize = 100_000;

/// Options of `sysid demo`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Where the figures go. The default, ./sysid-demo, belongs to the demo and is
    /// refreshed on every run; files in a directory given here are replaced only with
    /// --force.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Replace existing figures in --out-dir.
    #[arg(long)]
    pub force: bool,
    /// The paper's scale for the particle-EM study: 200 runs x 1000 iterations.
    #[arg(long)]
    pub full: bool,
    /// Particle-EM runs (default 2, or 200 with --full).
    #[arg(long)]
    pub runs: Option<usize>,
    /// EM iterations per particle-EM run (default 200, or 1000 with --full).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Length T of each particle-EM run's data set (default 500, or the paper's 1000
    /// with --full).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Seed of the data sets, starts and particle streams.
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Print the results as one JSON line instead of the table.
    #[arg(long)]
    pub json: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            out_dir: None,
            force: false,
            full: false,
            runs: None,
            iters: None,
            steps: None,
            seed: 1,
            json: false,
        }
    }
}

/// The figures, by file stem.
const FIGURES: [&str; 5] = [
    "em-trajectories",
    "em-trajectories-robust",
    "bode",
    "smoothed-state",
    "loglik-trace",
];

/// Length of the seed-004 data set, EM limits (ALGORITHMS.md 1.5, the `lti2x2` runner).
const LTI_STEPS: usize = 200;
const LTI_MAX_ITER: usize = 1000;
const LTI_TOL: f64 = 1e-7;

/// One linear model's row of the table.
struct LinearRow {
    name: &'static str,
    model: LinearGaussianModel,
    loglik: Option<f64>,
    response_error: Option<f64>,
    iterations: Option<usize>,
    trace: Vec<f64>,
    seconds: f64,
}

struct LinearPart {
    loglik_true: f64,
    rows: Vec<LinearRow>,
}

fn kalman(context: &str) -> impl Fn(sysid::kalman::KalmanError) -> CliError + '_ {
    move |source| CliError::Kalman {
        context: context.to_string(),
        source,
    }
}

/// Seed 004: N4SID, then EM from it and from the paper's start.
fn linear_part(seed: u64, json: bool) -> Result<LinearPart, CliError> {
    let sim = System::Lti2x2
        .simulate(LTI_STEPS, seed)
        .map_err(kalman("lti2x2 simulation"))?;
    let truth = lti2x2();
    let records = [sim.record];
    let mut ws = KalmanWorkspace::new();
    let loglik_true = ws.loglik(&truth, &records[0]).map_err(kalman("lti2x2"))?;
    let t0 = Instant::now();
    let subspace = n4sid(
        &records[0],
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        },
    )?;
    let n4sid_seconds = t0.elapsed().as_secs_f64();
    let n4sid_model = lti2x2_experiment_start(&subspace.model);
    let paper = lti2x2_paper_start();
    let options = EmOptions {
        max_iterations: LTI_MAX_ITER,
        tol: LTI_TOL,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| CliError::BadOption {
        option: "demo",
        message: e.to_string(),
    })?;
    let mut row = |name, model: LinearGaussianModel, iterations, trace, seconds| LinearRow {
        name,
        loglik: ws.loglik(&model, &records[0]).ok(),
        response_error: model.relative_response_error(&truth, 512),
        iterations,
        trace,
        seconds,
        model,
    };
    let mut rows = vec![
        row("truth", truth.clone(), None, Vec::new(), 0.0),
        row(
            "paper's initial model",
            paper.clone(),
            None,
            Vec::new(),
            0.0,
        ),
        row(
            "N4SID (order 8)",
            n4sid_model.clone(),
            None,
            Vec::new(),
            n4sid_seconds,
        ),
    ];
    for (name, start) in [
        ("EM from N4SID", n4sid_model),
        ("EM from the paper's model", paper),
    ] {
        let mut progress = Progress::new(LTI_MAX_ITER as u64, "lti2x2 EM", json);
        let result = fit(start, &records, lti2x2_em_spec(), &options, &mut progress);
        progress.finish();
        let seconds = result.elapsed.as_secs_f64();
        rows.push(row(
            name,
            result.estimate,
            Some(result.iterations),
            result.trace,
            seconds,
        ));
    }
    Ok(LinearPart { loglik_true, rows })
}

/// Seed 000: the particle-EM study, runs in parallel (each depends only on the seed
/// and its index).
fn particle_part(
    study: &NlbenchStudy,
    runs: usize,
    json: bool,
) -> Result<Vec<NlbenchRun>, CliError> {
    let robust = matches!(study.method, Method::Robust(_));
    let (total, label) = if robust {
        (runs as u64, "nlbench robust EM (runs)")
    } else {
        ((runs * study.iterations) as u64, "nlbench paper EM")
    };
    let progress = Progress::new(total, label, json);
    let results: Vec<NlbenchRun> = (0..runs)
        .into_par_iter()
        .map(|run| {
            let result = study
                .run(run, Tanizaki::default(), &mut progress.clone())
                .map_err(|e| CliError::BadOption {
                    option: "demo",
                    message: format!("nlbench run {run}: {e}"),
                });
            if robust {
                progress.inc(1);
            }
            result
        })
        .collect::<Result<_, _>>()?;
    progress.finish();
    Ok(results)
}

/// The run whose final log-likelihood estimate is the highest.
fn best_run(runs: &[NlbenchRun]) -> &NlbenchRun {
    runs.iter()
        .max_by(|a, b| {
            let l = |r: &NlbenchRun| r.loglik.unwrap_or(f64::NEG_INFINITY);
            l(a).total_cmp(&l(b))
        })
        .expect("at least one run")
}

/// Pointwise smoothed mean and 2.5 % / 97.5 % quantiles of a run's state at its EM
/// estimate (rejection FFBSi, 200 paths from a 500-particle filter).
fn smoothed_state(run: &NlbenchRun, seed: u64) -> Result<Vec<(f64, f64, f64)>, CliError> {
    let smc = |context: &'static str| {
        move |source| CliError::Smc {
            context: context.to_string(),
            source,
        }
    };
    let model = Nlbench::new(run.estimate).map_err(|e| CliError::BadOption {
        option: "demo",
        message: format!("nlbench estimate: {e}"),
    })?;
    let data = Series::new(&run.outputs, 1).map_err(smc("nlbench data"))?;
    let mut filter = ParticleFilter::new(FilterOptions {
        particles: 500,
        store_history: true,
        ..FilterOptions::default()
    })
    .map_err(smc("filter options"))?;
    filter
        .run(&model, &data, seed)
        .map_err(smc("nlbench filter"))?;
    let history = filter.history().ok_or_else(|| CliError::BadOption {
        option: "demo",
        message: "the particle filter kept no history".into(),
    })?;
    let (paths, _) = FfbsiReject {
        paths: 200,
        max_trials: None,
        parallel: true,
    }
    .trajectories(&model, history, &data, seed.wrapping_add(1))
    .map_err(smc("nlbench smoother"))?;
    Ok((0..paths.steps())
        .map(|t| {
            let mut xs = paths.states(t).to_vec();
            xs.sort_by(f64::total_cmp);
            let q = |p: f64| xs[((p * (xs.len() - 1) as f64).round() as usize).min(xs.len() - 1)];
            let mean = xs.iter().sum::<f64>() / xs.len() as f64;
            (mean, q(0.025), q(0.975))
        })
        .collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let k = v.len();
    if k == 0 {
        f64::NAN
    } else if k % 2 == 1 {
        v[k / 2]
    } else {
        0.5 * (v[k / 2 - 1] + v[k / 2])
    }
}

/// Bode magnitude and phase of every channel (`sysid plot`'s figure), the truth dashed
/// in black; the EM run from the paper's model is left out (it overlays EM from N4SID).
fn bode(rows: &[LinearRow]) -> Result<Figure, CliError> {
    let models: Vec<(String, LinearGaussianModel)> = rows
        .iter()
        .filter(|r| r.name != "EM from the paper's model")
        .map(|r| (r.name.to_string(), r.model.clone()))
        .collect();
    let mut figure = super::plot::bode_figure(&models, &[], None)?;
    for panel in &mut figure.panels {
        for series in &mut panel.series {
            if series.name.as_deref() == Some("truth") {
                series.stroke = Stroke::Dashed;
                series.colour = Some(6);
            }
        }
    }
    Ok(figure)
}

/// One EM run's line in a bundle; the first carries the bundle's legend entry.
fn bundle_member(k: usize, points: Vec<(f64, f64)>) -> Curve {
    let line = Curve::faint(points);
    if k == 0 {
        Curve {
            name: Some("EM runs (one line each)".into()),
            ..line
        }
    } else {
        line
    }
}

/// Seed 000's Figure 1 for a set of runs.
fn trajectory_figure(title: &str, runs: &[NlbenchRun], x_label: &str) -> Figure {
    let iterates: Vec<Vec<Vec<f64>>> = runs
        .iter()
        .map(|r| r.trajectory.iter().map(|v| v.to_vec()).collect())
        .collect();
    let bundle: Vec<Run<'_>> = runs
        .iter()
        .zip(&iterates)
        .map(|(r, it)| Run {
            start: abcd(&r.start).to_vec(),
            iterates: it,
        })
        .collect();
    parameter_trajectories(
        title,
        &["a", "b", "c", "d"],
        &abcd(&NlbenchParams::TRUE),
        &bundle,
        x_label,
        1000,
    )
}

fn figures(
    bode: Figure,
    linear: &LinearPart,
    runs: &[NlbenchRun],
    robust: &[NlbenchRun],
    best: &NlbenchRun,
    smoothed: &[(f64, f64, f64)],
    shown_steps: usize,
) -> Vec<(&'static str, Figure)> {
    let trajectories = trajectory_figure("paper EM", runs, "EM iteration");
    let robust_trajectories = trajectory_figure(
        "robust EM",
        robust,
        "refinement iteration (0: the start of the run)",
    );
    let band: Vec<(f64, f64, f64)> = smoothed
        .iter()
        .take(shown_steps)
        .enumerate()
        .map(|(t, &(_, lo, hi))| (t as f64, lo, hi))
        .collect();
    let states = Panel::new(
        format!(
            "nlbench run {} (best final log-likelihood): smoothed state at its EM estimate, \
             steps 1-{} of {}",
            best.run,
            shown_steps.min(smoothed.len()),
            smoothed.len()
        ),
        "time step t",
        "state x(t)",
    )
    .with_band(Band {
        name: "95 % smoothing band".into(),
        points: band,
        colour: 0,
    })
    .with_series(
        Curve::line(
            "smoothed mean",
            smoothed
                .iter()
                .take(shown_steps)
                .enumerate()
                .map(|(t, s)| (t as f64, s.0))
                .collect(),
        )
        .colour(0),
    )
    .with_series(
        Curve::line(
            "true state",
            best.states
                .iter()
                .take(shown_steps)
                .enumerate()
                .map(|(t, &x)| (t as f64, x))
                .collect(),
        )
        .stroke(Stroke::Dashed)
        .colour(1),
    );
    let mut lti_trace = Panel::new("lti2x2: exact EM", "EM iteration", "log-likelihood");
    for (k, row) in linear
        .rows
        .iter()
        .enumerate()
        .filter(|(_, r)| !r.trace.is_empty())
    {
        // from the first iterate on: the starts are far below and would flatten the curve
        let points = row
            .trace
            .iter()
            .enumerate()
            .skip(1)
            .map(|(i, &l)| (i as f64, l))
            .collect();
        lti_trace = lti_trace.with_series(Curve::line(row.name, points).colour(k));
    }
    let longest = linear.rows.iter().map(|r| r.trace.len()).max().unwrap_or(1) as f64;
    lti_trace = lti_trace.with_series(
        Curve::line(
            "truth",
            vec![(1.0, linear.loglik_true), (longest, linear.loglik_true)],
        )
        .stroke(Stroke::Dashed)
        .colour(6),
    );
    let mut particle_trace = Panel::new(
        "nlbench: paper's particle EM, log-likelihood estimates (M = 50)",
        "EM iteration",
        "log-likelihood",
    );
    for run in runs {
        // from the first iterate on, as above
        let points = run
            .loglik_trace
            .iter()
            .enumerate()
            .skip(1)
            .map(|(i, &l)| (i as f64, l))
            .collect();
        particle_trace = particle_trace.with_series(bundle_member(run.run, points));
    }
    vec![
        ("em-trajectories", trajectories),
        ("em-trajectories-robust", robust_trajectories),
        ("bode", bode),
        ("smoothed-state", Figure::single(states)),
        (
            "loglik-trace",
            Figure::grid(vec![lti_trace, particle_trace], 2),
        ),
    ]
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let started = Instant::now();
    let (dir, overwrite) = match &o.out_dir {
        Some(dir) => (dir.clone(), o.force),
        None => (PathBuf::from("sysid-demo"), true),
    };
    let paths: Vec<PathBuf> = FIGURES
        .iter()
        .flat_map(|stem| ["svg", "png"].map(|ext| dir.join(format!("{stem}.{ext}"))))
        .collect();
    crate::files::refuse_existing(paths.iter().map(PathBuf::as_path), overwrite)?;
    let runs = o.runs.unwrap_or(if o.full { 200 } else { DEMO_RUNS });
    let steps = o.steps.unwrap_or(if o.full { 1000 } else { DEMO_STEPS });
    let iterations = o.iters.unwrap_or(if o.full { 1000 } else { 200 });
    if !(MIN_STEPS..=MAX_STEPS).contains(&steps) {
        return Err(CliError::BadOption {
            option: "--steps",
            message: format!("{steps}: give {MIN_STEPS} to {MAX_STEPS} steps"),
        });
    }
    if runs == 0 || iterations == 0 {
        return Err(CliError::BadOption {
            option: "--runs/--iters",
            message: "must be at least 1".into(),
        });
    }
    // (a demo of 10^9 runs ran for days without a word)
    if runs > MAX_RUNS || iterations > MAX_ITERATIONS {
        return Err(CliError::BadOption {
            option: if runs > MAX_RUNS { "--runs" } else { "--iters" },
            message: format!(
                "{runs} runs x {iterations} iterations: the demo takes at most {MAX_RUNS} runs \
                 and {MAX_ITERATIONS} iterations (the paper's study is 200 x 1000, --full); \
                 a larger study is `sysid-bench nlbench-em --runs N --shard i/n` on several \
                 machines"
            ),
        });
    }
    note(&format!(
        "sysid demo: seed-004 system (N4SID, then EM), then {runs} particle-EM runs x {iterations} iterations; figures in {}",
        dir.display()
    ));
    let linear = linear_part(o.seed, o.json)?;
    let linear_seconds = started.elapsed().as_secs_f64();
    let study = NlbenchStudy {
        seed: o.seed,
        iterations,
        steps,
        method: Method::Paper,
        ..NlbenchStudy::default()
    };
    let t0 = Instant::now();
    let results = particle_part(&study, runs, o.json)?;
    let particle_seconds = t0.elapsed().as_secs_f64();
    // the same runs (data sets and starts) by the robust driver, refined for as many
    // iterations as the paper's runs make (at most its default 600; a tiny --iters
    // shortens its exploration too)
    let robust_study = NlbenchStudy {
        method: Method::Robust(RobustOptions {
            refine_iterations: iterations.min(RobustOptions::default().refine_iterations),
            explore_iterations: iterations.min(RobustOptions::default().explore_iterations),
            polish_evaluations: iterations.min(RobustOptions::default().polish_evaluations),
            ..RobustOptions::default()
        }),
        ..study
    };
    let t0 = Instant::now();
    let robust = particle_part(&robust_study, runs, o.json)?;
    let robust_seconds = t0.elapsed().as_secs_f64();
    let best = best_run(&robust);
    let smoothed = smoothed_state(best, o.seed)?;
    std::fs::create_dir_all(&dir).map_err(|source| CliError::Io {
        path: dir.clone(),
        source,
    })?;
    let mut written = Vec::new();
    let bode = bode(&linear.rows)?;
    for (stem, figure) in figures(bode, &linear, &results, &robust, best, &smoothed, 100) {
        written.extend(figure.write(&dir, stem, overwrite)?);
    }
    let total = started.elapsed().as_secs_f64();
    report(
        o,
        &linear,
        &[(&results, particle_seconds), (&robust, robust_seconds)],
        &Timings {
            steps,
            linear_seconds,
            total,
        },
        &written,
    );
    Ok(())
}

struct Timings {
    /// Data length of the particle-EM runs (shown with the times).
    steps: usize,
    linear_seconds: f64,
    total: f64,
}

/// One method's summary: the runs within 10 % of the truth, the median estimates and
/// the median time per run.
struct MethodSummary {
    name: &'static str,
    converged: usize,
    runs: usize,
    medians: [f64; 4],
    seconds_per_run: f64,
    seconds: f64,
}

fn summarise(name: &'static str, results: &[NlbenchRun], seconds: f64) -> MethodSummary {
    let column = |p: usize| results.iter().map(|r| abcd(&r.estimate)[p]).collect();
    MethodSummary {
        name,
        converged: results
            .iter()
            .filter(|r| within_ten_percent(&r.estimate))
            .count(),
        runs: results.len(),
        medians: [0, 1, 2, 3].map(|p| median(column(p))),
        seconds_per_run: median(results.iter().map(|r| r.elapsed.as_secs_f64()).collect()),
        seconds,
    }
}

fn report(
    o: &Options,
    linear: &LinearPart,
    methods: &[(&[NlbenchRun], f64)],
    t: &Timings,
    written: &[PathBuf],
) {
    let names = ["a", "b", "c", "d"];
    let truth = abcd(&NlbenchParams::TRUE);
    let [(paper, paper_seconds), (robust, robust_seconds)] = methods else {
        unreachable!("the demo runs the paper's method and the robust one")
    };
    let summaries = [
        summarise("paper", paper, *paper_seconds),
        summarise("robust", robust, *robust_seconds),
    ];
    let iterations = paper.first().map_or(0, |r| r.trajectory.len());
    let study = NlbenchStudy {
        steps: t.steps,
        ..NlbenchStudy::default()
    };
    let takeaway = format!(
        "take away: fit with the default `sysid fit nlbench` (robust): {}/{} runs within 10 % \
         of the truth, against {}/{} for one run of the paper's EM from the same starts",
        summaries[1].converged, summaries[1].runs, summaries[0].converged, summaries[0].runs
    );
    if o.json {
        let rows: Vec<serde_json::Value> = linear
            .rows
            .iter()
            .map(|r| serde_json::json!({"model": r.name, "loglik": r.loglik, "response_error": r.response_error,
                "iterations": r.iterations, "seconds": r.seconds}))
            .collect();
        let methods: Vec<serde_json::Value> = summaries
            .iter()
            .map(|m| {
                let estimates: serde_json::Map<String, serde_json::Value> = (0..4)
                    .map(|p| {
                        (
                            names[p].to_string(),
                            serde_json::json!({"truth": truth[p], "median": m.medians[p]}),
                        )
                    })
                    .collect();
                serde_json::json!({"method": m.name, "runs": m.runs,
                    "within_10_percent": m.converged, "estimates": estimates,
                    "seconds_per_run_median": m.seconds_per_run, "seconds": m.seconds})
            })
            .collect();
        crate::say(
            &serde_json::json!({
                "command": "demo",
                "lti2x2": {"T": LTI_STEPS, "loglik_true": linear.loglik_true, "models": rows},
                "nlbench_em": {"runs": paper.len(), "iterations": iterations, "T": study.steps,
                    "M": study.particles, "smoother": "tanizaki", "methods": methods,
                    "take_away": takeaway},
                "figures": written, "seconds": t.total,
            })
            .to_string(),
        );
        return;
    }
    let mut out = Vec::new();
    out.push(format!("seed 004: lti2x2 (2 inputs, 2 outputs, 8 states), T = {LTI_STEPS}: N4SID, then exact EM ({:.1} s)", t.linear_seconds));
    out.push(format!(
        "  {:<26} {:>15} {:>15} {:>11} {:>9}",
        "model", "log-likelihood", "response error", "iterations", "time (s)"
    ));
    for r in &linear.rows {
        out.push(format!(
            "  {:<26} {:>15} {:>15} {:>11} {:>9}",
            r.name,
            opt(r.loglik, 2),
            opt(r.response_error, 3),
            r.iterations.map_or("-".into(), |k| k.to_string()),
            if r.seconds > 0.0 {
                format!("{:.3}", r.seconds)
            } else {
                "-".into()
            },
        ));
    }
    out.push(
        "  (response error: relative frequency-response error against the truth, 512 frequencies)"
            .into(),
    );
    out.push(String::new());
    out.push(format!(
        "seed 000: nlbench particle EM, {} runs (each its own data set, T = {}, and start: a, b, c, d \
         times U[0.5, 1.5]), M = {}, Tanizaki smoother",
        paper.len(),
        study.steps,
        study.particles
    ));
    out.push(format!(
        "  {:<8} {:>11} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "method", "within 10%", "a", "b", "c", "d", "s/run", "total s"
    ));
    out.push(format!(
        "  {:<8} {:>11} {:>9} {:>9} {:>9} {:>9}",
        "truth",
        "",
        fmt(truth[0]),
        fmt(truth[1]),
        fmt(truth[2]),
        fmt(truth[3])
    ));
    for m in &summaries {
        out.push(format!(
            "  {:<8} {:>11} {:>9.4} {:>9.3} {:>9.3} {:>9.4} {:>9.1} {:>9.1}",
            m.name,
            format!("{}/{}", m.converged, m.runs),
            m.medians[0],
            m.medians[1],
            m.medians[2],
            m.medians[3],
            m.seconds_per_run,
            m.seconds
        ));
    }
    out.push(format!(
        "  (medians of the estimates; paper: q and r estimated from 10 times the truth, \
         {iterations} iterations; robust: 8 starts, the best refined and polished by a 10 000-particle likelihood, docs/particle-em.md; \
         {} threads)",
        crate::threads()
    ));
    if !o.full {
        out.push(
            "  (reduced scale; `sysid demo --full` runs the paper's 200 runs x 1000 iterations on T = 1000)"
                .into(),
        );
    }
    out.push(format!("  {takeaway}"));
    out.push(String::new());
    out.push(format!(
        "figures ({}):",
        written
            .first()
            .and_then(|p| p.parent())
            .unwrap_or(Path::new("."))
            .display()
    ));
    for pair in written.chunks(2) {
        let names: Vec<String> = pair
            .iter()
            .filter_map(|p| p.file_name())
            .map(|n| n.to_string_lossy().into_owned())
            .collect();
        out.push(format!("  {}", names.join(", ")));
    }
    out.push(format!("total {:.1} s", t.total));
    crate::say(&out.join("\n"));
}
