use super::fix::{apply, parse_fix};
use super::n4sid::parse_order;
use crate::DataArgs;
use crate::error::CliError;
use crate::files::{read_model, write_output};
use nalgebra::DVector;
use std::path::{Path, PathBuf};
use sysid::em::linear::{LinearEmSpec, fit};
use sysid::em::{EmOptions, Termination};
use sysid::kalman::{LinearGaussianModel, ModelSpec};
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Options of `sysid fit`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Model class: `lti` (linear Gaussian state space, exact EM), `nlbench` (the
    /// seed-000 benchmark, particle EM), `affine` (particle EM for an affine model:
    /// `--system nlbench`, or a linear model given by `--init FILE`) or `wiener`
    /// (blind Wiener identification from y1, y2 by gradient EM, seed 001).
    pub kind: String,
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order (required with `--init n4sid`; checked against a model file).
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
    /// Maximum number of EM iterations (particle EM runs exactly this many).
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
    /// Particle fits: `em` (particle EM with --smoother, seed 000) or `psaem`
    /// (stochastic-approximation EM with a conditional particle filter with ancestor
    /// sampling, Lindsten 2013; 15 particles are usually enough).
    #[arg(long, default_value = "em")]
    pub method: String,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Particle EM and PSAEM: also estimate the noise covariances (else held at their
    /// start): `--estimate-noise` both, `--estimate-noise=q` the process noise only,
    /// `--estimate-noise=r` the output noise only. At a small process noise (nlbench's
    /// q = 0.01), estimating q is what lets the particle kernel move the trajectory.
    #[arg(
        long,
        value_name = "WHICH",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "both",
        value_parser = ["q", "r", "both"]
    )]
    pub estimate_noise: Option<String>,
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

pub fn run(o: &Options) -> Result<(), CliError> {
    // refuse before a long fit, not after it
    crate::files::refuse_existing(
        std::iter::once(o.out.as_path()).chain(o.trace.as_deref()),
        o.force,
    )?;
    match o.kind.to_ascii_lowercase().as_str() {
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
                    "unknown model class {:?} (known: lti, nlbench, affine, wiener)",
                    o.kind
                ),
            });
        }
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
    if !(o.min_variance.is_finite() && o.min_variance >= 0.0) {
        return Err(CliError::BadOption {
            option: "--min-variance",
            message: format!(
                "must be a finite non-negative number, got {}",
                o.min_variance
            ),
        });
    }
    let mut spec = LinearEmSpec {
        min_variance: o.min_variance,
        ..LinearEmSpec::default()
    };
    let start = initial_model(o, &file)?;
    let start = apply(start, &mut spec, &fixes, &o.diag)?;
    let start = spec.project(&start)?;
    let mut progress = crate::progress::Progress::new(o.max_iter as u64, "fit lti", o.json);
    let result = fit(
        start,
        std::slice::from_ref(&file.record),
        spec,
        &options,
        &mut progress,
    );
    progress.finish();
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
        let mut text = String::from("iteration,loglik\n");
        for (k, l) in result.trace.iter().enumerate() {
            text += &format!("{k},{l}\n");
        }
        write_output(path, o.force, &text)?;
    }
    let loglik = result.loglik.unwrap_or(f64::NEG_INFINITY);
    crate::report(
        o.json,
        serde_json::json!({
            "command": "fit", "loglik": result.loglik, "iterations": result.iterations,
            "termination": stop, "seconds": result.elapsed.as_secs_f64(), "out": o.out,
        }),
        || {
            format!(
                "loglik {loglik} after {} iterations ({stop}, {:.2} s); wrote {}",
                result.iterations,
                result.elapsed.as_secs_f64(),
                o.out.display()
            )
        },
    );
    if let Termination::LikelihoodDecreased {
        iteration,
        previous,
        current,
    } = result.termination
    {
        return Err(CliError::LikelihoodDecreased(format!(
            "EM decreased the log-likelihood at iteration {iteration} ({previous} -> {current}); \
             the better model was written; {}",
            decrease_diagnosis(&result.estimate)
        )));
    }
    Ok(())
}

/// Why exact EM may have lowered the likelihood at `model`: a noise covariance that is
/// numerically singular (the statistics no longer resolve its small direction), or, if
/// none is, a request for a bug report.
fn decrease_diagnosis(model: &sysid::kalman::LinearGaussianModel) -> String {
    let ratio = |m: &nalgebra::DMatrix<f64>| {
        let e = nalgebra::SymmetricEigen::new(m.clone()).eigenvalues;
        e.min() / e.amax()
    };
    let singular: Vec<String> = [("Q", model.q()), ("R", model.r())]
        .into_iter()
        .filter(|(_, m)| m.nrows() > 0 && m.amax() > 0.0)
        .map(|(name, m)| (name, ratio(m)))
        .filter(|&(_, r)| r < 1e-10)
        .map(|(name, r)| format!("{name} (smallest/largest eigenvalue {r:.1e})"))
        .collect();
    if singular.is_empty() {
        "this is a bug, please report it".into()
    } else {
        format!(
            "the likelihood is rising towards a singular {}, where rounding dominates the M-step: \
             bound the variances with --min-variance (e.g. 1e-6 of the output variance)",
            singular.join(" and ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::decrease_diagnosis;
    use nalgebra::dmatrix;
    use sysid::kalman::LinearGaussianModel;

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
        let message = decrease_diagnosis(&model(1e-14));
        assert!(
            message.contains("singular R (smallest/largest eigenvalue 1.0e-14)"),
            "{message}"
        );
        assert!(message.contains("--min-variance"), "{message}");
        assert!(decrease_diagnosis(&model(0.1)).contains("bug"));
    }

    #[test]
    fn a_decrease_is_a_failure_not_bad_input() {
        let error = crate::error::CliError::LikelihoodDecreased("x".into());
        assert_eq!(error.exit_code(), 1);
        assert_eq!(error.to_string(), "fit: x");
    }
}
