//! Why a subspace result should not be used as it is.

use crate::{AUTO_MAX_ORDER, Focus, InputMethod, N4sidOptions, N4sidResult, Order};

/// A warning about an [`N4sidResult`] ([`N4sidResult::warnings`]): the command line
/// prints them, a program inspects them.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum SubspaceWarning {
    /// The identified `A` is unstable.
    Unstable {
        /// Its spectral radius.
        spectral_radius: f64,
    },
    /// `A` was re-estimated to be stable, and is biased.
    Stabilised {
        /// The stabilised spectral radius.
        spectral_radius: f64,
    },
    /// The simulation focus could not be used (an unstable `A`).
    FocusNotPossible,
    /// Collinear inputs: `B` and `D` are the minimum-norm solution.
    CollinearInputs,
    /// [`Order::Auto`] chose the largest order it considered: a higher one may be
    /// better.
    OrderAtEdge {
        /// The order chosen.
        order: usize,
        /// Block rows used (the candidates stop at `p i - 1`).
        block_rows: usize,
        /// Whether the cap of [`AUTO_MAX_ORDER`] (rather than the block rows) ended
        /// the candidates.
        capped: bool,
    },
}

impl std::fmt::Display for SubspaceWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SubspaceWarning::Unstable { spectral_radius } => write!(
                f,
                "the identified A is unstable (spectral radius {spectral_radius:.4}): \
                 simulations of this model diverge; rerun with --stable to enforce a stable A, \
                 or try another order"
            ),
            SubspaceWarning::Stabilised { spectral_radius } => write!(
                f,
                "A was unstable and was re-estimated to be stable (--stable; spectral radius \
                 now {spectral_radius:.4}); the stabilised A is biased"
            ),
            SubspaceWarning::FocusNotPossible => f.write_str(
                "--focus simulation was not possible (A is unstable, so its simulation \
                 diverges): B and D come from the state equations",
            ),
            SubspaceWarning::CollinearInputs => f.write_str(
                "the inputs are collinear (one is constant or a combination of others): B and \
                 D are the minimum-norm solution; drop the redundant input column",
            ),
            SubspaceWarning::OrderAtEdge {
                order,
                block_rows,
                capped,
            } => {
                write!(
                    f,
                    "the chosen order {order} is the largest candidate: a higher order may fit \
                     better; "
                )?;
                if *capped {
                    write!(
                        f,
                        "--order auto stops at {AUTO_MAX_ORDER} states; give a larger order \
                         by hand (--order n) and compare"
                    )
                } else {
                    write!(
                        f,
                        "with {block_rows} block rows the candidates stop there; more block \
                         rows (--block-rows) allow higher orders"
                    )
                }
            }
        }
    }
}

impl N4sidResult {
    /// What a user needs to be told about this result, fitted with `options`.
    pub fn warnings(&self, options: &N4sidOptions) -> Vec<SubspaceWarning> {
        let mut warnings = Vec::new();
        if self.spectral_radius >= 1.0 {
            warnings.push(SubspaceWarning::Unstable {
                spectral_radius: self.spectral_radius,
            });
        }
        if self.stabilised {
            warnings.push(SubspaceWarning::Stabilised {
                spectral_radius: self.spectral_radius,
            });
        }
        if options.focus == Focus::Simulation
            && self.input_method == InputMethod::StateEquations
            && self.model.m() > 0
        {
            warnings.push(SubspaceWarning::FocusNotPossible);
        }
        if self.collinear_inputs {
            warnings.push(SubspaceWarning::CollinearInputs);
        }
        let largest = self.order_scores.iter().map(|s| s.order).max();
        if options.order == Order::Auto && largest == Some(self.order) && self.order > 1 {
            warnings.push(SubspaceWarning::OrderAtEdge {
                order: self.order,
                block_rows: self.block_rows,
                capped: self.order >= AUTO_MAX_ORDER,
            });
        }
        warnings
    }
}
