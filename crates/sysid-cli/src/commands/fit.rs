use super::fix::{apply, parse_fix};
use super::n4sid::parse_order;
use crate::DataArgs;
use crate::error::CliError;
use crate::files::{create_output, read_model, write_output};
use nalgebra::DVector;
use std::io::Write;
use std::path::{Path, PathBuf};
use sysid::em::linear::{LinearEmSpec, fit};
use sysid::em::{EmOptions, Termination};
use sysid::kalman::{LinearGaussianModel, ModelSpec};
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Options of `sysid fit`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Model class: `lti` (linear Gaussian state space, exact EM).
    pub kind: String,
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order (required with `--init n4sid`; checked against a model file).
    #[arg(long)]
    pub order: Option<String>,
    /// Starting model: `n4sid` (subspace fit; its S is set to zero) or a model file.
    #[arg(long, default_value = "n4sid")]
    pub init: String,
    /// Hold a matrix fixed: `NAME` at its initial value, or `NAME=VALUE` with a number
    /// (broadcast) or a JSON matrix. Names: A B C D h Q R S mu P1. Repeatable.
    #[arg(long, value_name = "NAME[=VALUE]")]
    pub fix: Vec<String>,
    /// Estimate these covariances as diagonal (`Q`, `R`, comma separated); a full
    /// initial value is replaced by its diagonal.
    #[arg(long, value_delimiter = ',')]
    pub diag: Vec<String>,
    /// Maximum number of EM iterations.
    #[arg(long, default_value_t = 500)]
    pub max_iter: usize,
    /// Stopping tolerance on the relative log-likelihood change.
    #[arg(long, default_value_t = 1e-6)]
    pub tol: f64,
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
                block_rows: None,
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

pub fn run(o: &Options) -> Result<(), CliError> {
    if !o.kind.eq_ignore_ascii_case("lti") {
        return Err(CliError::BadOption {
            option: "fit",
            message: format!("unknown model class {:?} (known: lti)", o.kind),
        });
    }
    let fixes = o
        .fix
        .iter()
        .map(|f| parse_fix(f))
        .collect::<Result<Vec<_>, _>>()?;
    let options = EmOptions {
        max_iterations: o.max_iter,
        tol: o.tol,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| CliError::BadOption {
        option: "--max-iter/--tol",
        message: e.to_string(),
    })?;
    let file = o.data.read()?;
    let mut spec = LinearEmSpec::default();
    let start = initial_model(o, &file)?;
    let start = apply(start, &mut spec, &fixes, &o.diag)?;
    let start = spec.project(&start)?;
    let result = fit(
        start,
        std::slice::from_ref(&file.record),
        spec,
        &options,
        &mut (),
    );
    let stop = match &result.termination {
        Termination::Error { error, .. } => return Err(CliError::Em(error.clone())),
        Termination::Converged => "converged",
        Termination::MaxIterations => "max_iterations",
        Termination::LikelihoodDecreased { .. } => "likelihood_decreased",
        _ => "other",
    };
    let text =
        serde_json::to_string_pretty(&ModelSpec::from_model(&result.estimate)).expect("serialises");
    write_output(&o.out, o.force, &(text + "\n"))?;
    if let Some(path) = &o.trace {
        let mut w = create_output(path, o.force)?;
        let io = |source| CliError::Io {
            path: path.clone(),
            source,
        };
        writeln!(w, "iteration,loglik").map_err(io)?;
        for (k, l) in result.trace.iter().enumerate() {
            writeln!(w, "{k},{l}").map_err(io)?;
        }
        w.flush().map_err(io)?;
    }
    let loglik = result.loglik.unwrap_or(f64::NEG_INFINITY);
    if o.json {
        crate::say(
            &serde_json::json!({
                "command": "fit", "loglik": result.loglik, "iterations": result.iterations,
                "termination": stop, "seconds": result.elapsed.as_secs_f64(), "out": o.out,
            })
            .to_string(),
        );
    } else {
        crate::say(&format!(
            "loglik {loglik} after {} iterations ({stop}, {:.2} s); wrote {}",
            result.iterations,
            result.elapsed.as_secs_f64(),
            o.out.display()
        ));
    }
    if let Termination::LikelihoodDecreased {
        iteration,
        previous,
        current,
    } = result.termination
    {
        return Err(CliError::BadOption {
            option: "fit",
            message: format!(
                "EM decreased the log-likelihood at iteration {iteration} ({previous} -> {current}); \
                 the better model was written; this is a bug, please report it"
            ),
        });
    }
    Ok(())
}
