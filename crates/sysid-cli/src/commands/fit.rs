use super::fix::{apply, parse_fix};
use super::n4sid::parse_order;
use crate::DataArgs;
use crate::error::CliError;
use crate::files::{read_model, write_output};
use nalgebra::DVector;
use std::path::{Path, PathBuf};
use sysid::em::linear::{
    LinearEmSpec, QuasiNewtonOptions, coordinate_count, fit, fit_squarem, maximise_loglik,
};

/// `--polish auto` polishes when the free coordinates are at most this many (each
/// gradient costs twice as many filter passes; a black-box model of order 3 with one
/// input and output already has 23).
const POLISH_AUTO_MAX: usize = 20;

/// With a polish to follow, EM hands over when it is this many nats from its maximum
/// (by its own estimate).
const POLISH_SWITCH_NATS: f64 = 0.1;
use sysid::em::{EmOptions, Termination};
use sysid::kalman::{
    InitialState, LinearGaussianModel, ModelSpec, fit_percent, stationary_covariance,
};
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Options of `sysid fit`.
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Model class: `lti` (linear Gaussian state space, exact EM), `nlbench` (the
    /// seed-000 benchmark, particle EM), `affine` (particle EM for an affine model:
    /// `--system nlbench`, or a linear model given by `--init FILE`) or `wiener`
    /// (blind Wiener identification from y1, y2 by gradient EM, seed 001). Leave it
    /// out with `--model`.
    #[arg(required_unless_present = "model")]
    pub kind: Option<String>,
    /// A nonlinear model file (`.toml`, docs/model-format.md) whose free parameters
    /// are estimated from their values in the file: closed-form particle EM when the
    /// equations are affine in them (`--method robust` or `em`), gradient EM otherwise.
    /// The fitted model is written as a model file.
    #[arg(long, conflicts_with = "kind")]
    pub model: Option<PathBuf>,
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order (required with `--init n4sid`; checked against a model file), or
    /// a range `FROM..TO` (linear EM): every order is fitted, a table of
    /// log-likelihood, parameters, AIC, BIC and validation fit is printed, and the one
    /// `--select` chooses is written. BIC and AIC count the identifiable parameters (a
    /// black-box model's, less the n^2 of a change of state basis).
    #[arg(long)]
    pub order: Option<String>,
    /// Starting model: `n4sid` (subspace fit; its S is set to zero) or a model file.
    /// For `nlbench`: `a,b,c,d` or `a,b,c,d,q,r` (default: the nominal values
    /// 0.5,25,8,0.05,0.01,0.1).
    #[arg(long, default_value = "n4sid")]
    pub init: String,
    /// `fit affine`: the affine system (`nlbench`); without it `--init` names a linear
    /// model file.
    #[arg(long)]
    pub system: Option<String>,
    /// Hold a matrix fixed: `NAME` at its initial value, or `NAME=VALUE` with a number
    /// (broadcast) or a JSON matrix. Names: A B C D h Q R S mu P1. Repeatable.
    #[arg(long, value_name = "NAME[=VALUE]")]
    pub fix: Vec<String>,
    /// Estimate these covariances as diagonal (`Q`, `R`, comma separated); a full
    /// initial value is replaced by its diagonal.
    #[arg(long, value_delimiter = ',')]
    pub diag: Vec<String>,
    /// Linear EM: bound the free noise variances below (`Q, R >= V I`, in the data's
    /// units; 0 = plain maximum likelihood). Use it when the likelihood climbs towards
    /// a singular `Q` or `R`, where EM is no longer numerically monotone.
    #[arg(long, value_name = "V", default_value_t = 0.0)]
    pub min_variance: f64,
    /// Linear EM: bound the output noise below relative to each output's sample
    /// variance, `R >= REL diag(var y)`, e.g. 1e-4 for a noise standard deviation of
    /// at least 1 % of each output's. Use it when an output's noise variance heads to
    /// zero (the likelihood then grows without bound). 0 (the default) = plain maximum
    /// likelihood.
    #[arg(long, value_name = "REL", default_value_t = 0.0)]
    pub min_output_noise: f64,
    /// Linear EM: estimate R as a full covariance. By default R is diagonal when there
    /// are several outputs (independent sensor noise, MARSS's default): with a full R
    /// the likelihood of a record with several outputs often climbs towards a singular
    /// R that makes one combination of the outputs exactly predictable, a degenerate
    /// optimum that predicts each output worse (the DaISy glass furnace: 61 % against
    /// 80 % one-step prediction fit).
    #[arg(long)]
    pub full_r: bool,
    /// `--init n4sid`: enforce a stable A in the subspace start (see `sysid n4sid
    /// --stable`).
    #[arg(long)]
    pub stable: bool,
    /// Linear EM: also estimate the output offset h (by default h is held at the
    /// start's value: for `--init n4sid`, the record's mean output less the
    /// steady-state response to its mean input).
    #[arg(long)]
    pub offset: bool,
    /// Linear EM: also estimate the initial state's mean mu and covariance P1 of this
    /// record. By default they are held at the start's values during EM (N4SID: mu = 0,
    /// P1 = the second moment of its state sequence), and the model written describes a
    /// new record's initial state instead ("initial": "stationary" for a stable fitted
    /// A, "diffuse" otherwise), so that it can be run on another record of the same
    /// process.
    #[arg(long)]
    pub estimate_initial: bool,
    /// Linear EM: the training record's initial state: `model` (the start's: N4SID's,
    /// or the `--init` file's), `stationary` (the stationary law of the start's state
    /// noise) or `diffuse` (exact diffuse: EM maximises Durbin and Koopman's diffuse
    /// likelihood, as statsmodels does for unit-root models). Whatever the choice, the
    /// model written describes a new record's initial state as `stationary` when its A
    /// is stable and `diffuse` otherwise (unless mu or P1 were estimated or fixed).
    #[arg(long, default_value = "model")]
    pub initial: String,
    /// Linear EM: `squarem` (the default) accelerates EM by squared extrapolation
    /// (Varadhan and Roland 2008; monotone like EM, three E-steps per cycle, often tens
    /// of times fewer E-steps to the optimum); `none` runs plain EM.
    #[arg(long, default_value = "squarem", value_parser = ["squarem", "none"])]
    pub accelerate: String,
    /// Linear EM: after EM, maximise the exact log-likelihood by BFGS (quasi-Newton,
    /// superlinear near the maximum, where EM crawls): `auto` (the default) when the
    /// free parameters number at most 20 (structural models), `on`, `off`.
    #[arg(long, default_value = "auto", value_parser = ["auto", "on", "off"])]
    pub polish: String,
    /// Linear EM: standard errors of the free parameters from the observed information
    /// (the negative Hessian of the exact log-likelihood in the model's entries, by
    /// central differences; a covariance by its upper triangle), with 95 % confidence
    /// intervals: `auto` (the default) for at most 20 free parameters, `on`, `off`.
    /// Black-box models (free A and C) are not identifiable and get none.
    #[arg(long, default_value = "auto", value_parser = ["auto", "on", "off"])]
    pub std_errors: String,
    /// Linear EM: `mean` removes each signal's mean before the fit and folds the means
    /// into the written model's offset h (and mu), so that it describes, predicts and
    /// simulates the original signals; `linear` removes a straight line in time (the
    /// time column, or the row number) from each signal and stores the lines in the
    /// model: predict, compare, simulate, forecast, resid, loglik, filter and smooth
    /// remove them from a record at its times and return outputs in the original units
    /// (states are those of the detrended signals); `none` (the default) fits the
    /// signals as they are.
    #[arg(long, default_value = "none")]
    pub detrend: String,
    /// Linear EM: fit on the first FRACTION of the rows (after --range) and report the
    /// fitted model's simulation and one-step prediction fits on the rest (as `sysid
    /// compare` computes them).
    #[arg(long)]
    pub split: Option<f64>,
    /// Linear EM with `--order FROM..TO`: the criterion that chooses the order written,
    /// `bic` (the default), `aic`, or `validation` (the best simulation fit on the rows
    /// held out by --split).
    #[arg(long, default_value = "bic", value_parser = ["bic", "aic", "validation"])]
    pub select: String,
    /// Maximum number of EM iterations (particle EM runs exactly this many; with
    /// `--accelerate squarem`, a budget of E-steps, three per cycle).
    #[arg(long, visible_alias = "iters", default_value_t = 500)]
    pub max_iter: usize,
    /// Particle EM: particles M of the filter (and paths of `ffbsi-reject`).
    #[arg(long, default_value_t = 100)]
    pub particles: usize,
    /// Particle EM: E-step smoother, `tanizaki` (seed 000's, O(M^2) per step) or
    /// `ffbsi-reject` (O(M) expected per step when the transition density is not too
    /// peaked).
    #[arg(long, default_value = "tanizaki")]
    pub smoother: String,
    /// Particle fits: `robust` (the default: several starts around --init explored
    /// with the noise estimated from an inflated value, the best by a 1000-particle
    /// log-likelihood refined with --particles for --max-iter iterations and averaged;
    /// docs/particle-em.md), `em` (one run of particle EM from --init, seed 000's
    /// algorithm) or `psaem` (stochastic-approximation EM with a conditional particle
    /// filter with ancestor sampling, Lindsten 2013; 15 particles are usually enough).
    #[arg(long, default_value = "robust")]
    pub method: String,
    /// Particle fits with `--method robust`: the number of starts (--init and
    /// perturbations of it, each coefficient times U[0.5, 1.5]).
    #[arg(long, default_value_t = 8)]
    pub starts: usize,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Particle fits: which noise covariances are estimated: `--estimate-noise` (or
    /// `=both`) both, `=q` the process noise only, `=r` the output noise only, `=none`
    /// neither (held at --init's values). Default: both for `--method robust` (which
    /// explores with both estimated anyway and holds a noise the user keeps only in its
    /// refinement), none for `em` and `psaem`. At a small process noise (nlbench's
    /// q = 0.01), estimating q is what lets the particle kernel move the trajectory.
    #[arg(
        long,
        value_name = "WHICH",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "both",
        value_parser = ["q", "r", "both", "none"]
    )]
    pub estimate_noise: Option<String>,
    /// Linear EM: stop when the estimated distance to the maximum of the
    /// log-likelihood (Aitken's extrapolation of the last three values) is below this
    /// many nats. A run that ends at --max-iter instead says so, with the estimate.
    #[arg(long, value_name = "NATS", default_value_t = 1e-4)]
    pub tol_nats: f64,
    /// Stop when the relative log-likelihood change of an iteration is below this
    /// (default: 1e-6, except for linear EM, which uses --tol-nats unless this is
    /// given).
    #[arg(long)]
    pub tol: Option<f64>,
    /// Where to write the fitted model (JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the log-likelihood trace (CSV: iteration, loglik).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// Print `{loglik, iterations, termination, seconds}` as JSON.
    #[arg(long)]
    pub json: bool,
}

fn initial_model(
    o: &Options,
    file: &crate::files::DataFile,
) -> Result<LinearGaussianModel, CliError> {
    let order = o.order.as_deref().map(parse_order).transpose()?;
    if o.init.eq_ignore_ascii_case("n4sid") {
        let order = match order {
            Some(Order::Fixed(n)) => Order::Fixed(n),
            Some(Order::Auto) | None => {
                return Err(CliError::BadOption {
                    option: "--order",
                    message: "--init n4sid needs a model order (--order n)".into(),
                });
            }
        };
        let result = n4sid(
            &file.record,
            &N4sidOptions {
                order,
                stable: o.stable,
                ..Default::default()
            },
        )?;
        // linear EM holds S fixed; start from the subspace model without it
        return result
            .model
            .without_cross_covariance()
            .to_builder()
            .mu(DVector::zeros(result.model.n()))
            .build()
            .map_err(|source| CliError::Kalman {
                context: "n4sid start".into(),
                source,
            });
    }
    let model = read_model(Path::new(&o.init))?;
    if let Some(Order::Fixed(n)) = order
        && n != model.n()
    {
        return Err(CliError::BadOption {
            option: "--order",
            message: format!("{n} differs from the order {} of {}", model.n(), o.init),
        });
    }
    super::check_columns(&model, file)?;
    Ok(model)
}

/// Each option that not every model class uses: whether it was given (differs from
/// its default) and the classes it applies to (`model` is `--model FILE.toml`).
fn class_options(o: &Options) -> [(&'static str, bool, &'static [&'static str]); 26] {
    const LTI: &[&str] = &["lti"];
    const PARTICLE: &[&str] = &["nlbench", "affine", "wiener", "model"];
    const PARTICLE_EM: &[&str] = &["nlbench", "affine", "model"];
    [
        ("--order", o.order.is_some(), LTI),
        ("--init", o.init != "n4sid", &["lti", "nlbench", "affine"]),
        ("--system", o.system.is_some(), &["affine"]),
        ("--fix", !o.fix.is_empty(), LTI),
        ("--diag", !o.diag.is_empty(), LTI),
        ("--min-variance", o.min_variance != 0.0, LTI),
        ("--min-output-noise", o.min_output_noise != 0.0, LTI),
        ("--full-r", o.full_r, LTI),
        ("--stable", o.stable, LTI),
        ("--offset", o.offset, LTI),
        ("--estimate-initial", o.estimate_initial, LTI),
        ("--initial", o.initial != "model", LTI),
        ("--accelerate", o.accelerate != "squarem", LTI),
        ("--polish", o.polish != "auto", LTI),
        ("--std-errors", o.std_errors != "auto", LTI),
        ("--detrend", o.detrend != "none", LTI),
        ("--split", o.split.is_some(), LTI),
        ("--select", o.select != "bic", LTI),
        ("--tol-nats", o.tol_nats != 1e-4, LTI),
        ("--tol", o.tol.is_some(), LTI),
        ("--particles", o.particles != 100, PARTICLE),
        ("--seed", o.seed != 1, PARTICLE),
        ("--smoother", o.smoother != "tanizaki", PARTICLE_EM),
        ("--method", o.method != "robust", PARTICLE_EM),
        ("--starts", o.starts != 8, PARTICLE_EM),
        (
            "--estimate-noise",
            o.estimate_noise.is_some(),
            &["nlbench", "affine"],
        ),
    ]
}

/// Refuses an option the model class does not use (it used to be ignored in silence).
fn refuse_other_class_options(o: &Options, class: &str) -> Result<(), CliError> {
    for (option, given, classes) in class_options(o) {
        if given && !classes.contains(&class) {
            let users: Vec<String> = classes
                .iter()
                .map(|c| {
                    if *c == "model" {
                        "fit --model".to_string()
                    } else {
                        format!("fit {c}")
                    }
                })
                .collect();
            let what = if class == "model" {
                "a model file (fit --model)".to_string()
            } else {
                format!("fit {class}")
            };
            return Err(CliError::BadOption {
                option,
                message: format!(
                    "does not apply to {what}; it is an option of {}",
                    users.join(", ")
                ),
            });
        }
    }
    Ok(())
}

pub fn run(o: &Options) -> Result<(), CliError> {
    // refuse before a long fit, not after it
    crate::files::refuse_existing(
        std::iter::once(o.out.as_path()).chain(o.trace.as_deref()),
        o.force,
    )?;
    let Some(kind) = &o.kind else {
        refuse_other_class_options(o, "model")?;
        return super::fit_model::run(o);
    };
    let class = kind.to_ascii_lowercase();
    if ["lti", "nlbench", "affine", "wiener"].contains(&class.as_str()) {
        refuse_other_class_options(o, &class)?;
    }
    match class.as_str() {
        "lti" => {}
        "nlbench" => return super::fit_affine::run(o, true),
        "wiener" => return super::fit_wiener::run(o),
        "affine" => {
            return match o.system.as_deref() {
                None => super::fit_affine::run(o, false),
                Some("nlbench") => super::fit_affine::run(o, true),
                Some(other) => Err(CliError::UnknownSystem {
                    name: other.into(),
                    known: "nlbench (or give a linear model with --init FILE)".into(),
                }),
            };
        }
        _ => {
            return Err(CliError::BadOption {
                option: "fit",
                message: format!(
                    "unknown model class {kind:?} (known: lti, nlbench, affine, wiener; or \
                     give a model file with --model)"
                ),
            });
        }
    }
    if let Some((from, to)) = order_range(o.order.as_deref())? {
        return order_table(o, from, to);
    }
    fit_lti(o, Mode::Write(None)).map(|_| ())
}

/// What [`fit_lti`] does with its result.
enum Mode {
    /// Write the model, the trace and the summary (with an order table, if any).
    Write(Option<serde_json::Value>),
    /// Only compute: a candidate of an order table.
    Probe,
}

/// The figures of one fit, for an order table.
struct Outcome {
    order: usize,
    loglik: Option<f64>,
    parameters: usize,
    observed: usize,
    /// simulation fit on the rows held out by --split
    validation: Option<f64>,
}

/// `--order FROM..TO`: the orders of a table, or `None` for one order (or `auto`).
fn order_range(order: Option<&str>) -> Result<Option<(usize, usize)>, CliError> {
    let Some((from, to)) = order.and_then(|o| o.split_once("..")) else {
        return Ok(None);
    };
    let bad = || CliError::BadOption {
        option: "--order",
        message: format!("{from}..{to} is not a range of orders like 1..8"),
    };
    let (from, to) = (
        from.trim().parse::<usize>().map_err(|_| bad())?,
        to.trim().parse::<usize>().map_err(|_| bad())?,
    );
    if from == 0 || from > to || to > 20 {
        return Err(bad());
    }
    Ok(Some((from, to)))
}

/// Fits every order `from..=to` (N4SID start, EM, same options; no polish), tabulates
/// log-likelihood, parameters, AIC, BIC and the validation fit (with --split), and fits
/// and writes the order `--select` chooses.
fn order_table(o: &Options, from: usize, to: usize) -> Result<(), CliError> {
    let select = o.select.as_str();
    if select == "validation" && o.split.is_none() {
        return Err(CliError::BadOption {
            option: "--select",
            message: "validation needs held-out rows: add --split FRACTION".into(),
        });
    }
    let mut rows = Vec::new();
    for n in from..=to {
        let mut probe = o.clone();
        probe.order = Some(n.to_string());
        probe.polish = "off".into();
        probe.std_errors = "off".into();
        match fit_lti(&probe, Mode::Probe) {
            Ok(outcome) => rows.push(outcome),
            Err(e) => crate::warn(&format!("order {n} failed: {e}")),
        }
    }
    let score = |r: &Outcome| -> f64 {
        let k = r.parameters as f64;
        match (select, r.loglik) {
            ("validation", _) => -r.validation.unwrap_or(f64::NEG_INFINITY),
            ("aic", Some(l)) => -2.0 * l + 2.0 * k,
            (_, Some(l)) => -2.0 * l + k * (r.observed as f64).ln(),
            _ => f64::INFINITY,
        }
    };
    let best = rows
        .iter()
        .min_by(|a, b| score(a).total_cmp(&score(b)))
        .ok_or_else(|| CliError::BadOption {
            option: "--order",
            message: format!("no order in {from}..{to} could be fitted"),
        })?;
    let table: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let (l, k) = (r.loglik.unwrap_or(f64::NAN), r.parameters as f64);
            serde_json::json!({
                "order": r.order, "loglik": r.loglik, "parameters": r.parameters,
                "aic": -2.0 * l + 2.0 * k, "bic": -2.0 * l + k * (r.observed as f64).ln(),
                "validation_simulation_fit_percent": r.validation,
            })
        })
        .collect();
    if !o.json {
        let mut text = format!(
            "{:>5} {:>14} {:>6} {:>12} {:>12} {:>12}",
            "order", "loglik", "k", "AIC", "BIC", "validation"
        );
        for (row, r) in table.iter().zip(&rows) {
            text += &format!(
                "\n{:>5} {:>14.4} {:>6} {:>12.2} {:>12.2} {:>12}{}",
                r.order,
                r.loglik.unwrap_or(f64::NAN),
                r.parameters,
                row["aic"].as_f64().unwrap_or(f64::NAN),
                row["bic"].as_f64().unwrap_or(f64::NAN),
                r.validation.map_or("-".into(), |v| format!("{v:.2} %")),
                if r.order == best.order {
                    "  <- chosen"
                } else {
                    ""
                }
            );
        }
        crate::say(&text);
    }
    let mut chosen = o.clone();
    chosen.order = Some(best.order.to_string());
    let table = serde_json::json!({"select": select, "chosen": best.order, "orders": table});
    fit_lti(&chosen, Mode::Write(Some(table))).map(|_| ())
}

fn fit_lti(o: &Options, mode: Mode) -> Result<Outcome, CliError> {
    let probe = matches!(mode, Mode::Probe);
    let fixes = o
        .fix
        .iter()
        .map(|f| parse_fix(f))
        .collect::<Result<Vec<_>, _>>()?;
    // a matrix fixed twice: the last would silently win
    for (k, f) in fixes.iter().enumerate() {
        if fixes[..k].iter().any(|g| g.name == f.name) {
            return Err(CliError::BadOption {
                option: "--fix",
                message: format!("{} is fixed twice; give it once", f.name),
            });
        }
    }
    let options = EmOptions {
        max_iterations: o.max_iter,
        tol: o.tol.unwrap_or(0.0),
        distance_tol: o.tol_nats,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| CliError::BadOption {
        option: "--max-iter/--tol",
        message: e.to_string(),
    })?;
    let mut file = o.data.read()?;
    file.require_outputs(&o.data.data)?;
    let validation = match o.split {
        None => None,
        Some(fraction) => {
            let total = file.record.len();
            let cut = (fraction * total as f64).floor() as usize;
            if !(fraction > 0.0 && fraction < 1.0) || cut < 2 || cut + 2 > total {
                return Err(CliError::BadOption {
                    option: "--split",
                    message: format!(
                        "{fraction} leaves no useful estimation or validation rows of {total} \
                         (give a fraction strictly between 0 and 1)"
                    ),
                });
            }
            let rest = super::rows(file.clone(), &format!("{}:", cut + 1))?;
            file = super::rows(file, &format!("1:{cut}"))?;
            Some(rest)
        }
    };
    let trend = super::detrend::apply(&mut file, super::detrend::parse(&o.detrend)?)?;
    non_negative("--min-variance", o.min_variance)?;
    non_negative("--min-output-noise", o.min_output_noise)?;
    let mut spec = LinearEmSpec {
        min_variance: o.min_variance,
        h: o.offset,
        mu: o.estimate_initial,
        p1: o.estimate_initial,
        output_noise_floor: output_noise_floor(&file, o.min_output_noise)?,
        ..LinearEmSpec::default()
    };
    let start = super::parse_initial(&o.initial)?
        .apply_to_record(&initial_model(o, &file)?, &file.record)
        .map_err(|source| CliError::BadOption {
            option: "--initial",
            message: source.to_string(),
        })?;
    // linear EM holds S; beside a non-zero S it cannot estimate Q or R. A start file
    // with an S (as `sysid n4sid` writes) is started without it, as `--init n4sid` is,
    // unless the user holds S on purpose.
    let mut start_warnings = Vec::new();
    let start = if start.has_cross_covariance() && !fixes.iter().any(|f| f.name == "S") {
        start_warnings.push(
            "the start's cross-covariance S was set to zero: linear EM holds S and cannot \
             estimate Q or R beside a non-zero one (the N4SID start is treated the same way); \
             --fix S keeps it, with Q and R fixed too"
                .to_string(),
        );
        start.without_cross_covariance()
    } else {
        start
    };
    if o.estimate_initial && start.is_diffuse() {
        return Err(CliError::BadOption {
            option: "--estimate-initial",
            message: "the initial state is diffuse (no mu or P1 to estimate); drop one of \
                      --estimate-initial and the diffuse initial state"
                .into(),
        });
    }
    let mut diagonal = o.diag.clone();
    if file.record.y.nrows() > 1
        && !o.full_r
        && !o.diag.iter().any(|d| d.trim().eq_ignore_ascii_case("R"))
    {
        diagonal.push("R".into());
    }
    let start = apply(start, &mut spec, &fixes, &diagonal)?;
    let start = spec.project(&start)?;
    let mut progress = crate::progress::Progress::new(o.max_iter as u64, "fit lti", o.json);
    if !probe {
        // Ctrl-C stops EM after the iteration and writes the model so far (an order
        // scan's probes stop at once)
        crate::progress::interruptible();
    }
    let started = std::time::Instant::now();
    let records = std::slice::from_ref(&file.record);
    let coordinates = coordinate_count(&start, &spec);
    let polish_on = match o.polish.as_str() {
        "on" => true,
        "off" => false,
        _ => coordinates > 0 && coordinates <= POLISH_AUTO_MAX,
    };
    // with a polish to follow, EM only needs to reach the maximum's neighbourhood
    let options = if polish_on {
        EmOptions {
            distance_tol: options.distance_tol.max(POLISH_SWITCH_NATS),
            ..options.into_inner()
        }
        .check()
        .map_err(|e| CliError::BadOption {
            option: "--tol-nats",
            message: e.to_string(),
        })?
    } else {
        options
    };
    // an output-error model (Q held at zero): EM cannot move A (the smoothed states
    // are then a deterministic function of the parameters), so the likelihood is
    // maximised directly
    let output_error =
        spec.q == sysid::em::linear::Covariance::Fixed && start.q().iter().all(|&v| v == 0.0);
    let polish_on = polish_on || output_error;
    let start_model = start.clone();
    let (result, e_steps) = match o.accelerate.as_str() {
        _ if output_error => {
            let loglik = sysid::kalman::loglik_dataset(&start, records)
                .map_err(|e| start_failure(e.into(), &start, &file, &spec))?;
            let run = sysid::em::EmResult {
                estimate: start,
                loglik: Some(loglik),
                trace: vec![loglik],
                iterations: 0,
                termination: Termination::Converged,
                decreases: 0,
                elapsed: std::time::Duration::ZERO,
            };
            (run, 0)
        }
        "none" => {
            let run = fit(start, records, spec.clone(), &options, &mut progress);
            let e_steps = run.trace.len();
            (run, e_steps)
        }
        "squarem" => {
            let cycles = EmOptions {
                max_iterations: o.max_iter.div_ceil(3).max(1),
                ..options.clone().into_inner()
            }
            .check()
            .map_err(|e| CliError::BadOption {
                option: "--max-iter",
                message: e.to_string(),
            })?;
            let accelerated = fit_squarem(start, records, spec.clone(), &cycles, &mut progress);
            (accelerated.run, accelerated.e_steps)
        }
        other => {
            return Err(CliError::BadOption {
                option: "--accelerate",
                message: format!("unknown method {other:?} (known: squarem, none)"),
            });
        }
    };
    progress.finish();
    let mut result = result;
    let mut polish = None;
    let stopped = matches!(result.termination, Termination::Interrupted { .. });
    if polish_on
        && !stopped
        && result.loglik.is_some()
        && !matches!(result.termination, Termination::Error { .. })
    {
        let outcome = maximise_loglik(
            &result.estimate,
            records,
            &spec,
            &QuasiNewtonOptions::default(),
        )
        .map_err(CliError::Em)?;
        result.estimate = outcome.model.clone();
        result.loglik = Some(outcome.loglik);
        polish = Some(outcome);
    }
    let failure = match &result.termination {
        Termination::Error { error, iteration } if *iteration > 1 && result.loglik.is_some() => {
            Some((error.clone(), *iteration))
        }
        Termination::Error { error, .. } => {
            return Err(start_failure(error.clone(), &start_model, &file, &spec));
        }
        _ => None,
    };
    // a polish that ran and stopped short of its own criterion (not at a boundary,
    // which is reported apart) leaves an unconverged estimate, whatever EM did
    let polish_short = polish.as_ref().filter(|p| !p.converged && !p.boundary);
    let stop = if polish.as_ref().is_some_and(|p| p.converged) {
        "converged"
    } else if polish_short.is_some() {
        "not_converged"
    } else {
        em_stop(&result.termination)
    };
    let mut warnings = start_warnings;
    if stop == "max_iterations" {
        let last_gain = match result.trace[..] {
            [.., a, b] => b - a,
            _ => f64::NAN,
        };
        warnings.push(format!(
            "EM stopped at its iteration limit (--max-iter {}) with the log-likelihood still \
             rising ({last_gain:.3e} nats in the last iteration): the estimate is not converged; \
             raise --max-iter{}",
            o.max_iter,
            if polish_on {
                ""
            } else {
                ", or let --polish on finish it"
            }
        ));
    }
    if let Some(p) = polish_short {
        warnings.push(format!(
            "the quasi-Newton polish stopped before converging ({}, after gaining {:.3e} \
             nats): the estimate is not the maximum; fit again from it (--init {}), or bound \
             the variances (--min-output-noise, --min-variance) if one is heading to zero",
            p.status,
            p.loglik - p.loglik_before,
            o.out.display()
        ));
    }
    if let Some(p) = polish.as_ref().filter(|p| p.boundary) {
        warnings.push(format!(
            "the quasi-Newton polish {}; bound the variances (--min-output-noise, \
             --min-variance) for an interior maximum",
            p.status
        ));
    }
    warnings.extend(collapse_warnings(&result.estimate, &spec, &file));
    // an A the user held (a trend or seasonal model's unit roots) is theirs to choose
    let radius = sysid::subspace::spectral_radius(result.estimate.a());
    if spec.a && radius >= 1.0 {
        warnings.push(format!(
            "the fitted A is unstable (spectral radius {radius:.4}): simulations of this model \
             diverge; start from a stable model (--stable for the N4SID start) or try another \
             order"
        ));
    }
    let user_initial = o.estimate_initial || fixes.iter().any(|f| f.name == "P1" || f.name == "mu");
    let written = if user_initial {
        InitialState::Given
    } else if radius < 1.0 {
        InitialState::Stationary
    } else {
        InitialState::Diffuse
    };
    let described = super::detrend::written_model(&result.estimate, trend.as_ref())?;
    let want_errors = match o.std_errors.as_str() {
        "on" => true,
        "off" => false,
        // a black-box model (free A and C) is not identifiable: no errors unless asked
        _ => {
            coordinates > 0
                && coordinates <= POLISH_AUTO_MAX
                && !(spec.a && spec.c && result.estimate.n() > 1)
        }
    };
    let uncertainty = (want_errors && !stopped)
        .then(|| sysid::em::linear::standard_errors(&result.estimate, records, &spec));
    let (parameters, table) =
        match &uncertainty {
            Some(Ok(u)) => {
                (
                    serde_json::json!(u.parameters.iter().map(|p| serde_json::json!({
                "name": p.name, "value": p.value, "std_error": p.std_error,
                "ci95": [p.value - 1.96 * p.std_error, p.value + 1.96 * p.std_error],
            })).collect::<Vec<_>>()),
                    parameter_table(u),
                )
            }
            Some(Err(e)) => {
                warnings.push(format!("no standard errors: {e}"));
                (serde_json::Value::Null, String::new())
            }
            None => (serde_json::Value::Null, String::new()),
        };
    let mut spec_out = ModelSpec::with_initial(&described, written);
    let observed = file.record.y.iter().filter(|v| !v.is_nan()).count() as f64;
    // a black-box model's entries have n^2 redundant directions (a change of state
    // basis changes them, not the likelihood): the criteria count the others
    let identifiable = if spec.a && spec.c {
        coordinates.saturating_sub(result.estimate.n().pow(2))
    } else {
        coordinates
    };
    let k = identifiable as f64;
    spec_out.metadata = Some(sysid::kalman::Metadata {
        order: Some(result.estimate.n()),
        loglik: result.loglik,
        parameters: Some(identifiable),
        aic: result.loglik.map(|l| -2.0 * l + 2.0 * k),
        bic: result.loglik.map(|l| -2.0 * l + k * observed.ln()),
        termination: Some(stop.to_string()),
        detrend: trend.as_ref().map(super::detrend::Trend::describe),
        covariance: match &uncertainty {
            Some(Ok(u)) => Some(sysid::kalman::ParameterCovariance {
                names: u.parameters.iter().map(|p| p.name.clone()).collect(),
                matrix: (0..u.covariance.nrows())
                    .map(|i| u.covariance.row(i).iter().copied().collect())
                    .collect(),
            }),
            _ => None,
        },
        ..crate::files::metadata_of(&file, &o.data.data)
    });
    if !probe {
        crate::files::write_model(&o.out, o.force, &spec_out)?;
    }
    // the written model (original units, a new record's initial state) on the rows
    // held out by --split
    let validation_fit = match &validation {
        None => serde_json::Value::Null,
        Some(rest) => {
            // a linear trend continues over the held-out rows; the fits are in the
            // file's units
            let mut rest = rest.clone();
            if let Some(t) = trend
                .as_ref()
                .filter(|t| t.kind == super::detrend::Kind::Linear)
            {
                t.remove(&mut rest);
            }
            let measured = rest.measured();
            let model = written
                .apply_to_record(&described, &rest.record)
                .map_err(|source| CliError::Kalman {
                    context: "--split".into(),
                    source,
                })?;
            let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
            let simulation = model
                .response(&rest.record, None)
                .map(|r| mean(fit_percent(&measured, &rest.restored(&r.outputs), 0)));
            let prediction = model
                .predict(&rest.record, 1)
                .map(|p| mean(fit_percent(&measured, &rest.restored(&p.mean), 0)));
            serde_json::json!({
                "rows": rest.record.len(),
                "simulation_fit_percent": simulation.ok(),
                "prediction_fit_percent": prediction.ok(),
            })
        }
    };
    if let Some(path) = o.trace.as_ref().filter(|_| !probe) {
        let mut text = String::from("iteration,loglik\n");
        for (k, l) in result.trace.iter().enumerate() {
            text += &format!("{k},{l}\n");
        }
        write_output(path, o.force, &text)?;
    }
    if let Some((error, iteration)) = failure {
        let input = CliError::Em(error.clone()).exit_code() == 2;
        // a cause the diagnosis names (a collapsing variance, collinear inputs) is the
        // data's, with an option that avoids it
        let input = input || !estimated_singular_parts(&result.estimate, &file, &spec).is_empty();
        return Err(CliError::FitFailedMidRun {
            message: format!(
                "EM failed at iteration {iteration}: {error}; the last good model (iteration {}, \
                 log-likelihood {}) was written to {}{}; {}",
                result.iterations,
                result.loglik.unwrap_or(f64::NAN),
                o.out.display(),
                o.trace
                    .as_ref()
                    .map(|t| format!(" and the trace to {}", t.display()))
                    .unwrap_or_default(),
                decrease_diagnosis(&result.estimate, &file, &spec)
            ),
            input,
        });
    }
    let loglik = result.loglik.unwrap_or(f64::NEG_INFINITY);
    let validation_text = match &validation_fit {
        serde_json::Value::Null => String::new(),
        v => format!(
            "\nvalidation ({} rows held out): simulation fit {} %, one-step prediction fit {} %",
            v["rows"],
            v["simulation_fit_percent"]
                .as_f64()
                .map_or("-".into(), |f| format!("{f:.2}")),
            v["prediction_fit_percent"]
                .as_f64()
                .map_or("-".into(), |f| format!("{f:.2}")),
        ),
    };
    let outcome = Outcome {
        order: result.estimate.n(),
        loglik: result.loglik,
        parameters: identifiable,
        observed: file.record.y.iter().filter(|v| !v.is_nan()).count(),
        validation: validation_fit["simulation_fit_percent"].as_f64(),
    };
    let order_table = match mode {
        Mode::Probe => return Ok(outcome),
        Mode::Write(table) => table,
    };
    crate::report(
        o.json,
        serde_json::json!({
            "command": "fit", "loglik": result.loglik, "iterations": result.iterations,
            "order_table": order_table,
            "parameters": parameters,
            "e_steps": e_steps, "accelerate": o.accelerate,
            "polish": polish.as_ref().map(|p| serde_json::json!({
                "coordinates": p.parameters, "iterations": p.iterations,
                "evaluations": p.evaluations, "status": p.status, "converged": p.converged,
                "gain": p.loglik - p.loglik_before,
            })),
            "termination": stop, "em_termination": em_stop(&result.termination),
            "seconds": started.elapsed().as_secs_f64(), "out": o.out, "warnings": warnings,
            "validation": validation_fit,
        }),
        || {
            let polish_text = polish
                .as_ref()
                .map(|p| {
                    format!(
                        "; polish: {} (+{:.3e} nats)",
                        p.status,
                        p.loglik - p.loglik_before
                    )
                })
                .unwrap_or_default();
            format!(
                "loglik {loglik} after {} EM iterations ({e_steps} E-steps, {}){polish_text}; \
                 {stop} in {:.2} s; wrote {}{validation_text}{table}",
                result.iterations,
                em_stop(&result.termination),
                started.elapsed().as_secs_f64(),
                o.out.display()
            )
        },
    );
    for w in &warnings {
        crate::warn(w);
    }
    if let Termination::LikelihoodDecreased {
        iteration,
        previous,
        current,
    } = result.termination
    {
        return Err(CliError::LikelihoodDecreased(format!(
            "EM decreased the log-likelihood at iteration {iteration} ({previous} -> {current}); \
             the better model was written; {}",
            decrease_diagnosis(&result.estimate, &file, &spec)
        )));
    }
    super::interrupted(
        &result.termination,
        std::iter::once(o.out.clone()).chain(o.trace.clone()),
    )?;
    Ok(outcome)
}

/// The estimates as a table (statsmodels' summary): value, standard error, z, 95 %
/// interval; a leading newline.
fn parameter_table(u: &sysid::em::linear::Uncertainty) -> String {
    let mut text = format!(
        "\n{:>10} {:>14} {:>12} {:>8} {:>14} {:>14}",
        "parameter", "estimate", "std err", "z", "[0.025", "0.975]"
    );
    for p in &u.parameters {
        text += &format!(
            "\n{:>10} {:>14.6e} {:>12.4e} {:>8.2} {:>14.6e} {:>14.6e}",
            p.name,
            p.value,
            p.std_error,
            p.value / p.std_error,
            p.value - 1.96 * p.std_error,
            p.value + 1.96 * p.std_error
        );
    }
    text
}

/// Refuses an option value that is not a finite non-negative number.
fn non_negative(option: &'static str, value: f64) -> Result<(), CliError> {
    if value.is_finite() && value >= 0.0 {
        return Ok(());
    }
    Err(CliError::BadOption {
        option,
        message: format!("must be a finite non-negative number, got {value}"),
    })
}

/// The EM runner's own termination, for the summary.
fn em_stop(termination: &Termination<sysid::em::linear::LinearEmError>) -> &'static str {
    match termination {
        Termination::Converged => "converged",
        Termination::MaxIterations => "max_iterations",
        Termination::LikelihoodDecreased { .. } => "likelihood_decreased",
        Termination::Error { .. } => "error",
        Termination::Interrupted { .. } => "interrupted",
        _ => "other",
    }
}

/// Warnings for free variances that have (numerically) collapsed to zero.
fn collapse_warnings(
    model: &LinearGaussianModel,
    spec: &LinearEmSpec,
    file: &crate::files::DataFile,
) -> Vec<String> {
    // a singular Q of several states is a valid model (an innovation form has rank p);
    // a vanishing R, or the Q of a single state, is the degenerate boundary
    singular_parts(model, file)
        .into_iter()
        .filter(|(name, _)| match *name {
            "R" => spec.r != sysid::em::linear::Covariance::Fixed,
            "Q" => spec.q != sysid::em::linear::Covariance::Fixed && model.n() == 1,
            _ => false,
        })
        .map(|(name, what)| {
            format!(
                "{what}: the likelihood is rising towards a singular {name}, a boundary where \
                 the estimate is not trustworthy; bound it ({})",
                if name == "R" {
                    "--min-output-noise 1e-4"
                } else {
                    "--min-variance"
                }
            )
        })
        .collect()
}

/// The noise covariances (and `P1`) of `model` that are numerically singular, each
/// with a description: `R` relative to the outputs' sample variances (so a scalar `R`
/// is caught too), `Q` and `P1` relative to the state's scale (the largest eigenvalue
/// of `Q`, `P1` or the stationary covariance).
fn singular_parts(
    model: &LinearGaussianModel,
    file: &crate::files::DataFile,
) -> Vec<(&'static str, String)> {
    let smallest = |m: &nalgebra::DMatrix<f64>| {
        if m.nrows() == 0 {
            return f64::INFINITY;
        }
        nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.min()
    };
    let largest = |m: &nalgebra::DMatrix<f64>| {
        if m.nrows() == 0 {
            return 0.0;
        }
        nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.max()
    };
    let var = file.record.output_variances();
    let r = model.r();
    let whitened = nalgebra::DMatrix::from_fn(r.nrows(), r.ncols(), |i, j| {
        r[(i, j)] / (var[i] * var[j]).sqrt().max(f64::MIN_POSITIVE)
    });
    let state_scale = largest(model.q())
        .max(largest(model.p1()))
        .max(stationary_covariance(model.a(), model.q()).map_or(0.0, |p| largest(&p)));
    let mut out = Vec::new();
    let r_low = smallest(&whitened);
    if r_low < SINGULAR {
        out.push((
            "R",
            format!("R's smallest variance is {r_low:.1e} of the outputs' variance"),
        ));
    }
    for (name, m) in [("Q", model.q()), ("P1", model.p1())] {
        // rows and columns that are exactly zero are structure (a deterministic state)
        let kept: Vec<usize> = (0..m.nrows()).filter(|&i| m[(i, i)] != 0.0).collect();
        let sub = nalgebra::DMatrix::from_fn(kept.len(), kept.len(), |i, j| m[(kept[i], kept[j])]);
        let low = smallest(&sub);
        if !kept.is_empty() && state_scale > 0.0 && low < SINGULAR * state_scale {
            out.push((
                name,
                format!(
                    "{name}'s smallest eigenvalue is {:.1e} of the state's scale",
                    low / state_scale
                ),
            ));
        }
    }
    out
}

/// [`singular_parts`] that EM estimates (a held part is the user's choice).
fn estimated_singular_parts(
    model: &LinearGaussianModel,
    file: &crate::files::DataFile,
    spec: &LinearEmSpec,
) -> Vec<(&'static str, String)> {
    use sysid::em::linear::Covariance;
    singular_parts(model, file)
        .into_iter()
        .filter(|(name, _)| match *name {
            "R" => spec.r != Covariance::Fixed,
            "Q" => spec.q != Covariance::Fixed,
            _ => spec.p1,
        })
        .collect()
}

/// A variance below this fraction of its scale is numerically zero for EM's
/// statistics.
const SINGULAR: f64 = 1e-10;

/// Whether two or more inputs are collinear over the record (or one is constant):
/// the smallest singular value of the centred inputs relative to the largest.
fn collinear_inputs(file: &crate::files::DataFile) -> Option<String> {
    let u = &file.record.u;
    if u.nrows() < 1 || u.ncols() < 2 {
        return None;
    }
    let centred =
        nalgebra::DMatrix::from_fn(u.nrows(), u.ncols(), |i, t| u[(i, t)] - u.row(i).mean());
    let s = centred.singular_values();
    (s.min() <= 1e-10 * s.max().max(f64::MIN_POSITIVE)).then(|| {
        format!(
            "the inputs ({}) are collinear or one is constant (smallest/largest singular value \
             {:.1e}): drop the redundant input column",
            file.input_names.join(", "),
            s.min() / s.max().max(f64::MIN_POSITIVE)
        )
    })
}

/// `R >= rel diag(var y)`: each output's sample variance over the observed steps.
fn output_noise_floor(
    file: &crate::files::DataFile,
    rel: f64,
) -> Result<Option<DVector<f64>>, CliError> {
    if rel == 0.0 {
        return Ok(None);
    }
    let variances = file.record.output_variances();
    let mut floor = DVector::zeros(variances.len());
    for (i, &var) in variances.iter().enumerate() {
        if var <= 0.0 {
            let name = file
                .output_names
                .get(i)
                .cloned()
                .unwrap_or(format!("y{}", i + 1));
            return Err(CliError::BadOption {
                option: "--data",
                message: format!(
                    "output {name} has zero variance (it is constant or has fewer than two \
                     observed values): it carries no information; drop the column"
                ),
            });
        }
        floor[i] = rel * var;
    }
    Ok(Some(floor))
}

/// Why exact EM may have lowered the likelihood (or failed) at `model`: a noise
/// covariance or `P1` that is numerically singular (the statistics no longer resolve
/// its small direction), collinear inputs, or, if none of these, a request for a bug
/// report.
/// The error when EM cannot evaluate its start: why, if a cause is visible (a singular
/// `R` or `Q` of the start, e.g. N4SID's on noise-free data), with the options that
/// avoid it; else the error itself.
fn start_failure(
    error: sysid::em::linear::LinearEmError,
    start: &LinearGaussianModel,
    file: &crate::files::DataFile,
    spec: &LinearEmSpec,
) -> CliError {
    let causes = estimated_singular_parts(start, file, spec);
    if causes.is_empty() {
        return CliError::Em(error);
    }
    let causes: Vec<String> = causes
        .into_iter()
        .map(|(name, what)| format!("{what} (bound it: {})", bound_option(name)))
        .collect();
    CliError::FitFailedAtStart {
        message: format!(
            "the start model fails on the data ({error}): {} (noise-free data, or an order \
             too high for them?); nothing was written",
            causes.join("; ")
        ),
    }
}

/// The option that bounds a singular part named by [`singular_parts`].
fn bound_option(name: &str) -> &'static str {
    match name {
        "R" => "--min-output-noise 1e-4, or --min-variance",
        "Q" => "--min-variance (e.g. 1e-6 of the output variance)",
        _ => "do not estimate P1: drop --estimate-initial",
    }
}

fn decrease_diagnosis(
    model: &sysid::kalman::LinearGaussianModel,
    file: &crate::files::DataFile,
    spec: &LinearEmSpec,
) -> String {
    let mut causes: Vec<String> = estimated_singular_parts(model, file, spec)
        .into_iter()
        .map(|(name, what)| {
            format!(
                "{what}: the likelihood is rising towards a singular {name}, where rounding \
                 dominates the M-step; bound it ({})",
                bound_option(name)
            )
        })
        .collect();
    causes.extend(collinear_inputs(file));
    if causes.is_empty() {
        "this is a bug, please report it".into()
    } else {
        causes.join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::decrease_diagnosis;
    use crate::files::DataFile;
    use nalgebra::{DMatrix, dmatrix};
    use sysid::em::linear::LinearEmSpec;
    use sysid::kalman::{LinearGaussianModel, Record};

    fn file(u: DMatrix<f64>, y: DMatrix<f64>) -> DataFile {
        DataFile {
            input_names: (1..=u.nrows()).map(|i| format!("u{i}")).collect(),
            output_names: (1..=y.nrows()).map(|i| format!("y{i}")).collect(),
            time: (0..y.ncols()).map(|t| t as f64).collect(),
            labels: crate::data_file::Labels::Rows {
                first: 0,
                len: y.ncols(),
            },
            sample_time: None,
            columns: Vec::new(),
            trend: None,
            record: Record::new(u, y),
        }
    }

    fn outputs() -> DataFile {
        let y = DMatrix::from_fn(2, 50, |i, t| ((t * (i + 2)) as f64 * 0.7).sin());
        file(DMatrix::zeros(0, 50), y)
    }

    fn model(r_small: f64) -> LinearGaussianModel {
        LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0; 0.5],
            dmatrix![1.0],
            dmatrix![1.0, 0.0; 0.0, r_small],
        )
        .build()
        .unwrap()
    }

    #[test]
    fn a_decrease_at_a_singular_r_points_to_the_variance_floor() {
        let message = decrease_diagnosis(&model(1e-14), &outputs(), &LinearEmSpec::default());
        assert!(message.contains("towards a singular R"), "{message}");
        assert!(message.contains("--min-output-noise"), "{message}");
        assert!(
            decrease_diagnosis(&model(0.1), &outputs(), &LinearEmSpec::default()).contains("bug")
        );
    }

    #[test]
    fn a_scalar_r_going_to_zero_is_named() {
        let m = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![1e-13],
        )
        .build()
        .unwrap();
        let y = DMatrix::from_fn(1, 50, |_, t| (t as f64 * 0.7).sin());
        let message = decrease_diagnosis(
            &m,
            &file(DMatrix::zeros(0, 50), y),
            &LinearEmSpec::default(),
        );
        assert!(message.contains("singular R"), "{message}");
    }

    #[test]
    fn collinear_inputs_are_named() {
        let m = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![0.3],
        )
        .b(dmatrix![1.0, 1.0])
        .build()
        .unwrap();
        let u = DMatrix::from_fn(2, 50, |_, t| (t as f64 * 0.3).sin());
        let y = DMatrix::from_fn(1, 50, |_, t| (t as f64 * 0.7).sin());
        let message = decrease_diagnosis(&m, &file(u, y), &LinearEmSpec::default());
        assert!(message.contains("collinear"), "{message}");
        assert!(message.contains("u1, u2"), "{message}");
    }

    #[test]
    fn a_decrease_is_a_failure_not_bad_input() {
        let error = crate::error::CliError::LikelihoodDecreased("x".into());
        assert_eq!(error.exit_code(), 1);
        assert_eq!(error.to_string(), "fit: x");
    }
}
