//! `sysid fit nlbench` and `sysid fit affine`: particle EM (seed 000) for the models
//! affine in their parameters that `sysid-models` provides.
//!
//! - `fit nlbench` (= `fit affine --system nlbench`): the seed-000 benchmark; `--init
//!   a,b,c,d[,q,r]` (default: the benchmark's nominal values). q and r are held at their
//!   starting values unless `--estimate-noise` (`=q` or `=r` for one of them).
//! - `fit affine --init model.json`: a linear Gaussian model (no inputs, offset or S) in
//!   affine form; A, C, Q and R are estimated by particle EM (the exact answer is
//!   `fit lti`; this is the check of the particle machinery on real data).
//!
//! Particle EM runs a fixed number of iterations (`--max-iter`, alias `--iters`); the
//! E-step's log-likelihood is a particle estimate, so decreases are counted, not errors.

use super::options::Options;
use crate::commands::particle::series_of;
use crate::error::CliError;
use crate::files::{DataFile, read_model, short, write_output};
use std::path::Path;
use sysid::em::affine::{
    AffineEmError, AffineEmSpec, AffineFit, AffineFitOptions, AffineFitReport, AffineMethod,
    AffineModel, AffineParams, CLIMB_GAIN, CheckedAffineFitOptions, RobustFit, StartStatus,
    describe, fit_affine,
};
use sysid::em::linear::Covariance;
use sysid::em::{EmObserver, EmResult, FitRun, Termination};
use sysid::kalman::ModelSpec;
use sysid::modelfile::ExprAffine;
use sysid::models::{LinearAffine, NlbenchAffine, NlbenchParams};

/// The affine model chosen on the command line, with its starting parameters.
enum Chosen {
    Nlbench(AffineParams),
    Linear(LinearAffine, AffineParams),
}

fn bad(option: &'static str, message: impl Into<String>) -> CliError {
    CliError::BadOption {
        option,
        message: message.into(),
    }
}

fn affine_error(context: &str) -> impl Fn(AffineEmError) -> CliError + '_ {
    move |source| CliError::AffineEm {
        context: context.to_string(),
        source,
    }
}

/// `a,b,c,d` or `a,b,c,d,q,r` over the nominal benchmark values.
fn parse_nlbench_init(text: &str) -> Result<NlbenchParams, CliError> {
    let values = text
        .split(',')
        .map(|s| {
            let v: f64 = s
                .trim()
                .parse()
                .map_err(|_| bad("--init", format!("{s:?} is not a number")))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad("--init", format!("{s:?} is not finite")))
            }
        })
        .collect::<Result<Vec<f64>, _>>()?;
    let mut p = NlbenchParams::TRUE;
    match values.as_slice() {
        [a, b, c, d] => (p.a, p.b, p.c, p.d) = (*a, *b, *c, *d),
        [a, b, c, d, q, r] => (p.a, p.b, p.c, p.d, p.q, p.r) = (*a, *b, *c, *d, *q, *r),
        _ => {
            return Err(bad(
                "--init",
                format!(
                    "nlbench needs a,b,c,d or a,b,c,d,q,r ({} values given)",
                    values.len()
                ),
            ));
        }
    }
    if !(p.q > 0.0 && p.r > 0.0) {
        return Err(bad("--init", "q and r must be positive"));
    }
    Ok(p)
}

fn choose(o: &Options, nlbench: bool) -> Result<Chosen, CliError> {
    if nlbench {
        let start = if o.init.eq_ignore_ascii_case("n4sid") {
            NlbenchParams::TRUE
        } else {
            parse_nlbench_init(&o.init)?
        };
        return Ok(Chosen::Nlbench(NlbenchAffine::params(&start)));
    }
    if o.init.eq_ignore_ascii_case("n4sid") {
        return Err(bad(
            "--init",
            "fit affine needs --init FILE (a linear model) or --system nlbench",
        ));
    }
    let model = read_model(Path::new(&o.init))?;
    let (affine, params) = LinearAffine::new(&model).map_err(affine_error(&o.init))?;
    Ok(Chosen::Linear(affine, params))
}

/// The command's settings and data, shared by the generic steps.
pub(super) struct Job<'a> {
    pub(super) o: &'a Options,
    pub(super) file: DataFile,
    pub(super) options: CheckedAffineFitOptions,
    /// Warnings found outside the fit (a model file's inseparable parameters).
    pub(super) extra_warnings: Vec<String>,
}

/// The fit options of the command line (`--method`, `--particles`, `--smoother`,
/// `--max-iter`, `--starts`), checked once, each error named by its flag.
pub(super) fn fit_options(
    o: &Options,
    spec: AffineEmSpec,
) -> Result<CheckedAffineFitOptions, CliError> {
    Ok(o.settings()?.affine_options()?.with_spec(spec))
}

/// `sysid fit nlbench` / `sysid fit affine`.
pub fn run(o: &Options, nlbench: bool) -> Result<(), CliError> {
    let options = fit_options(o, AffineEmSpec::default())?;
    let chosen = choose(o, nlbench)?;
    if matches!(chosen, Chosen::Linear(..)) && crate::commands::nonlinear::is_model_file(&o.out) {
        return Err(bad(
            "--out",
            "a linear model is written as a JSON model file (name it .json); `sysid fit lti` \
             fits it exactly",
        ));
    }
    let file = o.data.read()?;
    let outputs = match &chosen {
        Chosen::Nlbench(_) => 1,
        Chosen::Linear(model, _) => model.output_dim(),
    };
    crate::commands::check_column_counts(&file, 0, outputs)?;
    let job = Job {
        o,
        file,
        options,
        extra_warnings: Vec::new(),
    };
    let estimated = o
        .estimate_noise
        .as_deref()
        .unwrap_or(if o.method == "robust" { "both" } else { "none" });
    let free = |which: &str| {
        if estimated == which || estimated == "both" {
            Covariance::Full
        } else {
            Covariance::Fixed
        }
    };
    let spec = AffineEmSpec {
        pi_x: free("q"),
        pi_y: free("r"),
        ..AffineEmSpec::default()
    };
    let job = Job {
        options: job.options.with_spec(spec),
        ..job
    };
    match chosen {
        Chosen::Nlbench(start) => fit_with(&job, &NlbenchAffine, start, |p| {
            let n = NlbenchAffine::nlbench_params(p);
            vec![n.a, n.b, n.c, n.d, n.q, n.r]
        }),
        Chosen::Linear(model, start) => fit_with(&job, &model, start, |p| {
            p.beta_x
                .iter()
                .chain(p.beta_y.iter())
                .chain(p.pi_x.iter())
                .chain(p.pi_y.iter())
                .copied()
                .collect()
        }),
    }
}

/// The progress bar of a run: EM's and PSAEM's iterations; the robust driver runs its
/// starts in parallel and has a spinner (off a terminal, a line every 30 s).
pub(super) fn progress_of(
    o: &Options,
    options: &AffineFitOptions,
) -> Option<crate::progress::Progress> {
    let label = match options.method {
        AffineMethod::Robust => {
            return Some(crate::progress::Progress::spinner(
                "robust particle EM",
                o.json,
            ));
        }
        AffineMethod::Em => options.smoother.name(),
        _ => "psaem",
    };
    Some(crate::progress::Progress::new(
        options.iterations as u64,
        label,
        o.json,
    ))
}

/// The progress bar as an observer of EM (none: an observer that does nothing).
pub(super) fn observer_of<T>(
    progress: &Option<crate::progress::Progress>,
) -> Box<dyn EmObserver<T>> {
    match progress {
        Some(p) => Box::new(p.clone()),
        None => Box::new(()),
    }
}

/// The run of the command: its seed, stopped by Ctrl-C.
pub(super) fn fit_run(o: &Options) -> FitRun<'static> {
    FitRun::new(o.seed).stopped_by(&crate::progress::interrupted)
}

fn fit_with<A, F>(job: &Job, model: &A, start: AffineParams, row: F) -> Result<(), CliError>
where
    A: AffineModel + ParamNames,
    A::Smc: sysid::smc::TransitionBound,
    F: Fn(&AffineParams) -> Vec<f64>,
{
    let o = job.o;
    let context = o.data.data.display().to_string();
    let series = series_of(&job.file, &context)?;
    let progress = progress_of(o, job.options.options());
    let began = std::time::Instant::now();
    // Ctrl-C ends EM, or the robust exploration or refinement, where it is; the result
    // so far is written, marked interrupted
    crate::progress::interruptible();
    let mut observer = observer_of(&progress);
    let fit = fit_affine(
        model,
        series,
        start.clone(),
        &job.options,
        &fit_run(o),
        observer.as_mut(),
    )
    .map_err(affine_error(&context))?;
    if let Some(p) = &progress {
        p.finish();
    }
    report(job, model, &start, &fit, began.elapsed().as_secs_f64(), row)
}

/// Writes the estimate (and the trace) of an affine fit, and reports.
pub(super) fn report<A, F>(
    job: &Job,
    model: &A,
    start: &AffineParams,
    fit: &AffineFit,
    seconds: f64,
    row: F,
) -> Result<(), CliError>
where
    A: ParamNames,
    F: Fn(&AffineParams) -> Vec<f64>,
{
    match &fit.report {
        AffineFitReport::Robust(robust) => report_robust(job, model, start, robust, seconds, row),
        AffineFitReport::Em { result, iterates } => {
            for w in &job.extra_warnings {
                crate::warn(w);
            }
            let method = match fit.method {
                AffineMethod::Em => job.o.smoother.as_str(),
                _ => "psaem",
            };
            report_em(job, model, start, result, iterates, method, row)
        }
    }
}

/// Names of the columns of the parameter trace and the output file's contents.
pub(super) trait ParamNames {
    fn names(&self, params: &AffineParams) -> Vec<String>;
    fn model_json(&self, params: &AffineParams) -> Result<serde_json::Value, CliError>;

    /// The estimate as a nonlinear model file, where the class has one (written for
    /// an output named `.toml`).
    fn model_file(&self, _params: &AffineParams) -> Option<sysid::modelfile::ModelFile> {
        None
    }

    /// The output file's text: the model, with `summary` (how it was fitted) where the
    /// format has room for it; a model file for an output named `.toml`.
    fn model_text(
        &self,
        params: &AffineParams,
        summary: &serde_json::Value,
        out: &Path,
    ) -> Result<String, CliError> {
        if crate::commands::nonlinear::is_model_file(out)
            && let Some(file) = self.model_file(params)
        {
            return Ok(file.to_toml(&super::toml_metadata::metadata_lines(summary)));
        }
        let mut json = self.model_json(params)?;
        // A linear model file stays a plain model file (readable by every command);
        // the nlbench result records how it was obtained.
        if json.get("system").is_some() {
            json["particle_em"] = summary.clone();
        }
        Ok(serde_json::to_string_pretty(&json).expect("serialises") + "\n")
    }
}

impl ParamNames for ExprAffine {
    fn names(&self, _: &AffineParams) -> Vec<String> {
        self.file().free_names()
    }

    fn model_json(&self, params: &AffineParams) -> Result<serde_json::Value, CliError> {
        Ok(self
            .file()
            .free_names()
            .into_iter()
            .zip(self.theta(params))
            .map(|(n, v)| (n, serde_json::json!(v)))
            .collect::<serde_json::Map<_, _>>()
            .into())
    }

    /// The model file with the estimates as its values; the fit's scalar facts go to
    /// its `[metadata]`.
    fn model_text(
        &self,
        params: &AffineParams,
        summary: &serde_json::Value,
        _out: &Path,
    ) -> Result<String, CliError> {
        let fitted = self.file().with_values(&self.theta(params));
        Ok(fitted.to_toml(&super::toml_metadata::metadata_lines(summary)))
    }
}

impl ParamNames for NlbenchAffine {
    fn names(&self, _: &AffineParams) -> Vec<String> {
        ["a", "b", "c", "d", "q", "r"].map(String::from).to_vec()
    }

    /// The built-in nlbench model file (`sysid pf --system nlbench`'s) at the
    /// estimates, which every command for model files reads.
    fn model_file(&self, params: &AffineParams) -> Option<sysid::modelfile::ModelFile> {
        let builtin = crate::commands::nonlinear::system("nlbench").ok()?;
        let p = NlbenchAffine::nlbench_params(params);
        let value = |name: &str| match name {
            "a" => Some(p.a),
            "b" => Some(p.b),
            "c" => Some(p.c),
            "d" => Some(p.d),
            "q" => Some(p.q),
            "r" => Some(p.r),
            _ => None,
        };
        let theta: Option<Vec<f64>> = builtin.free_names().iter().map(|n| value(n)).collect();
        Some(builtin.with_values(&theta?))
    }

    fn model_json(&self, params: &AffineParams) -> Result<serde_json::Value, CliError> {
        let p = NlbenchAffine::nlbench_params(params);
        Ok(serde_json::json!({
            "system": "nlbench", "a": p.a, "b": p.b, "c": p.c, "d": p.d,
            "q": p.q, "r": p.r, "mu": p.mu, "p1": p.p1,
        }))
    }
}

impl ParamNames for LinearAffine {
    fn names(&self, p: &AffineParams) -> Vec<String> {
        let mut names = Vec::new();
        for (label, m) in [
            ("A", &p.beta_x),
            ("C", &p.beta_y),
            ("Q", &p.pi_x),
            ("R", &p.pi_y),
        ] {
            // column-major, as the values are written
            for j in 0..m.ncols() {
                for i in 0..m.nrows() {
                    names.push(format!("{label}{}{}", i + 1, j + 1));
                }
            }
        }
        names
    }

    fn model_json(&self, params: &AffineParams) -> Result<serde_json::Value, CliError> {
        let model = self.model(params).map_err(affine_error("estimate"))?;
        Ok(serde_json::to_value(ModelSpec::from_model(&model)).expect("serialises"))
    }
}

/// Writes what particle EM or PSAEM estimated and its trace, and reports.
fn report_em<A, F>(
    job: &Job,
    model: &A,
    start: &AffineParams,
    result: &EmResult<AffineParams, AffineEmError>,
    iterates: &[(f64, AffineParams)],
    method: &str,
    row: F,
) -> Result<(), CliError>
where
    A: ParamNames,
    F: Fn(&AffineParams) -> Vec<f64>,
{
    let o = job.o;
    let context = o.data.data.display().to_string();
    let names = model.names(start);
    if let Termination::Error { iteration, error } = &result.termination {
        return Err(affine_error(&format!(
            "{context}, EM iteration {iteration}"
        ))(error.clone()));
    }
    let stopped = matches!(result.termination, Termination::Interrupted { .. });
    let summary = serde_json::json!({
        "iterations": result.iterations, "particles": o.particles, "method": method,
        "seed": o.seed, "loglik_estimate": result.loglik,
        "likelihood_decreases": result.decreases, "interrupted": stopped,
    });
    let text = model.model_text(&result.estimate, &summary, &o.out)?;
    write_output(&o.out, o.force, &text)?;
    if let Some(path) = &o.trace {
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, (loglik, estimate)) in iterates.iter().enumerate() {
            let mut values = vec![loglik.to_string()];
            values.extend(row(estimate).iter().map(|v| v.to_string()));
            text += &format!("{},{}\n", k + 1, values.join(","));
        }
        write_output(path, o.force, &text)?;
    }
    crate::report(
        o.json,
        serde_json::json!({
            "command": "fit", "loglik_estimate": result.loglik,
            "iterations": result.iterations, "likelihood_decreases": result.decreases,
            "seconds": result.elapsed.as_secs_f64(), "out": o.out,
        }),
        || {
            format!(
                "particle EM: {} iterations in {:.2} s ({} particles, {}), loglik estimate {}; wrote {}",
                result.iterations,
                result.elapsed.as_secs_f64(),
                o.particles,
                method,
                result.loglik.unwrap_or(f64::NEG_INFINITY),
                o.out.display()
            )
        },
    );
    crate::commands::interrupted(
        &result.termination,
        std::iter::once(o.out.clone()).chain(o.trace.clone()),
    )
}

/// `--method robust`: writes the estimate with the starts' table and the trace of the
/// refinement, and reports the warnings.
fn report_robust<A, F>(
    job: &Job,
    model: &A,
    start: &AffineParams,
    fit: &RobustFit,
    seconds: f64,
    row: F,
) -> Result<(), CliError>
where
    A: ParamNames,
    F: Fn(&AffineParams) -> Vec<f64>,
{
    let o = job.o;
    let options = job.options.robust();
    let names = model.names(start);
    let named = |p: &AffineParams| -> serde_json::Value {
        names
            .iter()
            .cloned()
            .zip(row(p))
            .map(|(n, v)| (n, serde_json::json!(v)))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    let starts: Vec<serde_json::Value> = fit
        .starts
        .iter()
        .map(|s| {
            serde_json::json!({
                "status": describe(&s.status), "loglik": s.loglik, "iterations": s.iterations,
                "start": named(&s.start), "estimate": named(&s.estimate),
            })
        })
        .collect();
    let maxima: Vec<serde_json::Value> = fit
        .maxima
        .iter()
        .map(|m| serde_json::json!({"loglik": m.loglik, "starts": m.starts, "estimate": named(&m.estimate)}))
        .collect();
    let (settled, change) = match fit.stop {
        sysid::em::affine::RefineStop::Settled { change } => (true, change),
        sysid::em::affine::RefineStop::StillMoving { change } => (false, change),
    };
    let summary = serde_json::json!({
        "method": "robust", "seed": o.seed, "smoother": o.smoother,
        "interrupted": fit.interrupted,
        "loglik": fit.loglik, "loglik_particles": fit.loglik_particles,
        "polish": fit.polish.as_ref().map(|p| serde_json::json!({
            "particles": p.particles, "evaluations": p.evaluations, "converged": p.converged,
            "em_loglik": p.start_loglik, "loglik": p.loglik, "loglik_sd": p.loglik_sd,
            "check_evaluations": p.check_evaluations, "check_gain": p.check_gain,
            "at_maximum": p.curvature.as_ref().map(|c| c.is_maximum()),
            "interrupted": p.interrupted})),
        "starts": starts, "local_maxima": maxima,
        "refinement": {"iterations": fit.refine_trace.len(), "particles": options.refine_particles,
            "averaged_last": fit.refine_trace.len()
                - (fit.refine_trace.len() / 2).max(fit.extrapolation.last),
            "settled": settled, "largest_change_last_quarters": change,
            "jumps_tried": fit.extrapolation.tried, "jumps_taken": fit.extrapolation.taken},
        "warnings": fit.warnings.iter().chain(&job.extra_warnings).collect::<Vec<_>>(),
    });
    let mut outputs = vec![(
        o.out.clone(),
        model.model_text(&fit.estimate, &summary, &o.out)?,
    )];
    if let Some(path) = &o.trace {
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, (p, l)) in fit.refine_trace.iter().zip(&fit.refine_loglik).enumerate() {
            let values: Vec<String> = row(p).iter().map(|v| v.to_string()).collect();
            text += &format!("{},{l},{}\n", k + 1, values.join(","));
        }
        outputs.push((path.clone(), text));
    }
    for (path, text) in &outputs {
        write_output(path, o.force, text)?;
    }
    for w in fit.warnings.iter().chain(&job.extra_warnings) {
        crate::warn(w);
    }
    // the model file is the same on any machine; the timing goes to the report only
    let mut report = summary;
    report["seconds"] = serde_json::json!({
        "explore": fit.timing.explore.as_secs_f64(), "select": fit.timing.select.as_secs_f64(),
        "refine": fit.timing.refine.as_secs_f64(), "polish": fit.timing.polish.as_secs_f64(),
        "total": seconds,
    });
    report["command"] = serde_json::json!("fit");
    report["out"] = serde_json::json!(o.out);
    report["estimate"] = named(&fit.estimate);
    let standard_errors = fit
        .polish
        .as_ref()
        .and_then(|p| p.curvature.as_ref())
        .and_then(|c| c.standard_errors(&row));
    report["standard_errors"] = match &standard_errors {
        Some(se) => names
            .iter()
            .cloned()
            .zip(se.iter().map(|v| serde_json::json!(v)))
            .collect::<serde_json::Map<_, _>>()
            .into(),
        None => serde_json::Value::Null,
    };
    crate::report(o.json, report, || {
        let mut text = format!(
            "robust particle EM: {} starts, the best refined for {} iterations ({} particles) \
             in {seconds:.2} s; log-likelihood {:.2} ({} particles); wrote {}",
            o.starts,
            fit.refine_trace.len(),
            options.refine_particles,
            fit.loglik,
            fit.loglik_particles,
            o.out.display()
        );
        let values: Vec<String> = names
            .iter()
            .zip(row(&fit.estimate))
            .enumerate()
            .map(|(k, (n, v))| match &standard_errors {
                Some(se) => format!("{n} = {} (se {})", short(v), short(se[k])),
                None => format!("{n} = {}", short(v)),
            })
            .collect();
        text += &format!("\n  estimate: {}", values.join(", "));
        if fit.extrapolation.taken > 0 {
            text += &format!(
                "\n  the refinement crawled: {} of {} extrapolated jumps along its drift raised \
                 the likelihood and were taken (the last at iteration {})",
                fit.extrapolation.taken, fit.extrapolation.tried, fit.extrapolation.last
            );
        }
        if let Some(p) = &fit.polish {
            text += &format!(
                "\n  checked by a {}-particle filter: the EM estimate scores {:.2}; maximised \
                 directly ({} filters{}): {:.2} (sd {:.2})",
                p.particles,
                p.start_loglik,
                p.evaluations,
                if p.converged { ", converged" } else { "" },
                p.loglik,
                p.loglik_sd
            );
            if p.check_evaluations > 0 {
                text += &format!(
                    "; its curvature ({} filters) {}",
                    p.check_evaluations,
                    if p.check_gain > CLIMB_GAIN {
                        format!("led {:.2} nats higher, along a ridge", p.check_gain)
                    } else if standard_errors.is_some() {
                        "is a maximum's".to_string()
                    } else {
                        "is not a maximum's".to_string()
                    }
                );
            }
        }
        text += "\n  start  status                     log-likelihood";
        for (k, s) in fit.starts.iter().enumerate() {
            let mark = if s.status == StartStatus::Explored {
                "*"
            } else {
                " "
            };
            text += &format!(
                "\n  {:>4}{mark} {:<26} {}",
                k + 1,
                describe(&s.status),
                s.loglik.map_or("-".into(), |l| format!("{l:.2}"))
            );
        }
        text
    });
    if fit.interrupted {
        return Err(CliError::Interrupted {
            iteration: fit.refine_trace.len(),
            written: outputs.into_iter().map(|(path, _)| path).collect(),
        });
    }
    Ok(())
}
