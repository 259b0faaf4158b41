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
    /// The scoring finish stopped before converging (not at a boundary).
    PolishShort {
        /// Why it stopped.
        status: String,
        /// What it gained (nats).
        gain: f64,
        /// Its estimate of what is left to gain (nats).
        distance: f64,
        /// Directions the data determine, of the free coordinates.
        identified: usize,
        /// The free coordinates.
        coordinates: usize,
    },
    /// The record starts far from the written model's stationary law: at EM's estimate,
    /// the stationary initial state costs this many nats against the start's.
    TransientStart {
        /// EM's log-likelihood (the start's initial state) less the written model's,
        /// both at EM's estimate.
        nats: f64,
    },
    /// The finish headed to a maximum on the boundary (a collapsing `R`).
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
                distance,
                identified,
                coordinates,
            } => write!(
                f,
                "the finish (scoring of the written model's likelihood) stopped before \
                 converging ({status}, after gaining {gain:.3e} nats, about {distance:.1e} \
                 left by its estimate): the estimate is not the maximum; {identified} of the \
                 {coordinates} free coordinates are determined by the data, and a model with \
                 many weakly determined directions (an order high for the record) converges \
                 slowly: compare lower orders (--order 1..N) or fit again from the written \
                 model (--init FILE)"
            ),
            LinearFitWarning::TransientStart { nats } => write!(
                f,
                "the record starts far from the model's stationary law: at EM's estimate, \
                 the stationary initial state the model is written with scores {nats:.1} \
                 nats below the start's; the fit maximised the written model's \
                 likelihood, which bends the dynamics to explain the first steps: if the \
                 record starts away from equilibrium, --initial diffuse treats its \
                 initial state as unknown (and writes it so)"
            ),
            LinearFitWarning::PolishAtBoundary { status } => write!(
                f,
                "the finish stopped heading to a boundary ({status}): R collapses; bound \
                 the variances (--min-output-noise, --min-variance) for an interior maximum"
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
