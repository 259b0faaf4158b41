//! Why a linear fit's result should not be trusted as it is.

use super::diagnosis::SingularPart;

/// A warning carried by a [`super::LinearFit`]: the command line prints them (and
/// `--strict` counts them); a program inspects them.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum LinearFitWarning {
    /// The start's cross-covariance `S` was set to zero (linear EM holds `S`).
    CrossCovarianceDropped,
    /// EM stopped at its iteration limit with the likelihood still rising.
    MaxIterations {
        /// The limit.
        max_iterations: usize,
        /// The last iteration's gain (nats).
        last_gain: f64,
        /// Whether a polish followed.
        polished: bool,
    },
    /// The quasi-Newton polish stopped before converging (not at a boundary).
    PolishShort {
        /// Why it stopped.
        status: String,
        /// What it gained (nats).
        gain: f64,
        /// A black-box model (free `A` and `C`): its state basis, the scale of a single
        /// state, is free, and only the initial state's held covariance ties it.
        free_basis: bool,
    },
    /// The polish headed to a maximum on the boundary (a collapsing `R`).
    PolishAtBoundary {
        /// Why it stopped.
        status: String,
    },
    /// A free noise covariance collapsed to a singular one.
    Collapsed(SingularPart),
    /// The fitted free `A` is unstable.
    Unstable {
        /// Its spectral radius.
        spectral_radius: f64,
    },
    /// Standard errors were asked for or due, and could not be given.
    NoStandardErrors {
        /// Why.
        reason: String,
    },
    /// The order chosen from a range is at an end of it that the range could have
    /// gone past (its top, or a bottom above 1).
    OrderAtEdge {
        /// The order chosen.
        order: usize,
        /// The range's first order.
        from: usize,
        /// Its last.
        to: usize,
    },
    /// An order of a range could not be fitted.
    OrderFailed {
        /// The order.
        order: usize,
        /// Why.
        reason: String,
    },
}

impl std::fmt::Display for LinearFitWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinearFitWarning::CrossCovarianceDropped => f.write_str(
                "the start's cross-covariance S was set to zero: linear EM holds S and cannot \
                 estimate Q or R beside a non-zero one (the N4SID start is treated the same way); \
                 --fix S keeps it, with Q and R fixed too",
            ),
            LinearFitWarning::MaxIterations {
                max_iterations,
                last_gain,
                polished,
            } => write!(
                f,
                "EM stopped at its iteration limit (--max-iter {max_iterations}) with the \
                 log-likelihood still rising ({last_gain:.3e} nats in the last iteration): the \
                 estimate is not converged; raise --max-iter{}",
                if *polished {
                    ""
                } else {
                    ", or let --polish on finish it"
                }
            ),
            LinearFitWarning::PolishShort {
                status,
                gain,
                free_basis,
            } => {
                write!(
                    f,
                    "the quasi-Newton polish stopped before converging ({status}, after \
                     gaining {gain:.3e} nats): the estimate is not the maximum; "
                )?;
                if *free_basis {
                    f.write_str(
                        "the state's basis is free (a black-box model: for one state, the \
                         scale of x trades C against Q) and the search walks along it; fix \
                         it (--fix C=1 for one state), or start the record from its \
                         stationary law (--initial stationary)",
                    )
                } else {
                    f.write_str(
                        "fit again from the written model (--init FILE), or bound the \
                         variances (--min-output-noise, --min-variance) if one is heading to \
                         zero",
                    )
                }
            }
            LinearFitWarning::PolishAtBoundary { status } => write!(
                f,
                "the quasi-Newton polish {status}; bound the variances (--min-output-noise, \
                 --min-variance) for an interior maximum"
            ),
            LinearFitWarning::Collapsed(part) => write!(
                f,
                "{}: the likelihood is rising towards a singular {}, a boundary where the \
                 estimate is not trustworthy; bound it ({})",
                part.description,
                part.matrix,
                if part.matrix == "R" {
                    "--min-output-noise 1e-3"
                } else {
                    "--min-variance"
                }
            ),
            LinearFitWarning::Unstable { spectral_radius } => write!(
                f,
                "the fitted A is unstable (spectral radius {spectral_radius:.4}): simulations of \
                 this model diverge; start from a stable model (--stable for the N4SID start) or \
                 try another order"
            ),
            LinearFitWarning::NoStandardErrors { reason } => {
                write!(f, "no standard errors: {reason}")
            }
            LinearFitWarning::OrderAtEdge { order, from, to } => write!(
                f,
                "order {order} was chosen at the {} of the range {from}..{to}: a {} order may be \
                 better; widen the range (orders 1 to {})",
                if order == to { "top" } else { "bottom" },
                if order == to { "higher" } else { "lower" },
                super::MAX_ORDER
            ),
            LinearFitWarning::OrderFailed { order, reason } => {
                write!(f, "order {order} failed: {reason}")
            }
        }
    }
}
