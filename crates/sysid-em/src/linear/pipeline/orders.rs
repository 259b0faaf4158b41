//! An order range: every order fitted, tabulated, and the chosen one fitted in full.

use super::{
    CheckedLinearFitOptions, FitStatus, LinearFit, LinearFitError, LinearFitWarning, Selection,
    Signals, Switch,
};
use crate::EmObserver;
use sysid_kalman::LinearGaussianModel;

/// One order of a range: its fit's figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderRow {
    /// The order.
    pub order: usize,
    /// The log-likelihood of the training record.
    pub loglik: Option<f64>,
    /// Identifiable free parameters.
    pub parameters: usize,
    /// Observed output values.
    pub observed: usize,
    /// Simulation fit on the held-out steps (with a split).
    pub validation: Option<f64>,
}

impl OrderRow {
    /// `-2 l + 2 k` (NaN without a log-likelihood).
    pub fn aic(&self) -> f64 {
        -2.0 * self.loglik.unwrap_or(f64::NAN) + 2.0 * self.parameters as f64
    }

    /// `-2 l + k ln(observed)` (NaN without a log-likelihood).
    pub fn bic(&self) -> f64 {
        -2.0 * self.loglik.unwrap_or(f64::NAN)
            + self.parameters as f64 * (self.observed as f64).ln()
    }

    /// The criterion's score, smaller is better (infinite when it cannot be scored).
    fn score(&self, select: Selection) -> f64 {
        match (select, self.loglik) {
            (Selection::Validation, _) => -self.validation.unwrap_or(f64::NEG_INFINITY),
            (Selection::Aic, Some(_)) => self.aic(),
            (Selection::Bic, Some(_)) => self.bic(),
            _ => f64::INFINITY,
        }
    }
}

/// The orders of a range and the one chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderTable {
    /// The criterion.
    pub select: Selection,
    /// The order chosen.
    pub chosen: usize,
    /// Every order that could be fitted, in increasing order.
    pub rows: Vec<OrderRow>,
}

/// Fits every order `from..=to` (N4SID start, same options, no polish, no standard
/// errors), tabulates them, and fits the order `select` chooses in full.
pub(super) fn fit_range(
    data: &Signals,
    options: &CheckedLinearFitOptions,
    (from, to): (usize, usize),
    select: Selection,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> Result<LinearFit, LinearFitError> {
    let mut probe = options.clone();
    probe.options.polish = Switch::Off;
    probe.options.std_errors = Switch::Off;
    let (training, held_out) = super::split(data, options)?;
    let mut rows = Vec::new();
    let mut warnings = Vec::new();
    for n in from..=to {
        let fitted = super::fit_prepared(
            training.clone(),
            held_out.as_ref(),
            &probe,
            Some(n),
            observer,
        );
        match fitted {
            Ok(fit) if fit.status == FitStatus::Interrupted => {
                return Err(LinearFitError::Interrupted { order: n });
            }
            Ok(fit) => match fit.failure {
                Some(failure) => warnings.push(LinearFitWarning::OrderFailed {
                    order: n,
                    reason: format!(
                        "EM failed at iteration {}: {}; {}",
                        failure.iteration, failure.error, failure.diagnosis
                    ),
                }),
                None => rows.push(OrderRow {
                    order: n,
                    loglik: fit.loglik,
                    parameters: fit.criteria.parameters,
                    observed: fit.criteria.observed,
                    validation: fit.validation.and_then(|v| v.simulation_fit_percent),
                }),
            },
            Err(e) => warnings.push(LinearFitWarning::OrderFailed {
                order: n,
                reason: e.to_string(),
            }),
        }
    }
    let chosen = rows
        .iter()
        .min_by(|a, b| a.score(select).total_cmp(&b.score(select)))
        .ok_or(LinearFitError::NoOrder { from, to })?
        .order;
    // an end of the range the range could have gone past: its top below the cap, or
    // a bottom above 1
    let at_top = chosen == to && to < super::MAX_ORDER;
    if from < to && (at_top || (chosen == from && from > 1)) {
        warnings.push(LinearFitWarning::OrderAtEdge {
            order: chosen,
            from,
            to,
        });
    }
    let mut fit =
        super::fit_prepared(training, held_out.as_ref(), options, Some(chosen), observer)?;
    warnings.append(&mut fit.warnings);
    fit.warnings = warnings;
    fit.order_table = Some(OrderTable {
        select,
        chosen,
        rows,
    });
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::super::{LinearFit, LinearFitOptions, OrderChoice, Selection, Signals};
    use super::LinearFitWarning;
    use nalgebra::{DMatrix, dmatrix};
    use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
    use sysid_kalman::LinearGaussianModel;

    /// The warnings of an order range fitted to a second-order system.
    fn warnings(from: usize, to: usize) -> (usize, Vec<LinearFitWarning>) {
        let truth = LinearGaussianModel::builder(
            dmatrix![1.2, -0.5; 1.0, 0.0],
            dmatrix![1.0, 0.3],
            DMatrix::identity(2, 2) * 0.01,
            dmatrix![0.01],
        )
        .b(dmatrix![1.0; 0.0])
        .build()
        .unwrap();
        let u = DMatrix::from_fn(1, 600, |_, t| ((t * 7919) % 13) as f64 / 6.0 - 1.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        let record = truth.simulate(&u, &mut rng).unwrap().record;
        let options = LinearFitOptions {
            order: OrderChoice::Range {
                from,
                to,
                select: Selection::Bic,
            },
            polish: super::Switch::Off,
            ..LinearFitOptions::default()
        };
        let fit =
            LinearFit::run(&Signals::new(record), &options.check().unwrap(), &mut ()).unwrap();
        (fit.order_table.unwrap().chosen, fit.warnings)
    }

    #[test]
    fn an_order_chosen_at_an_end_the_range_could_pass_is_flagged() {
        let edge = |w: &LinearFitWarning| matches!(w, LinearFitWarning::OrderAtEdge { .. });
        let (chosen, w) = warnings(1, 2);
        assert_eq!(chosen, 2);
        assert!(w.iter().any(edge), "{w:?}");
        assert!(
            w[0].to_string().contains("top of the range 1..2"),
            "{}",
            w[0]
        );
        let (chosen, w) = warnings(2, 3);
        assert_eq!(chosen, 2);
        assert!(w.iter().any(edge), "a bottom above 1: {w:?}");
        let (chosen, w) = warnings(1, 4);
        assert_eq!(chosen, 2);
        assert!(!w.iter().any(edge), "{w:?}");
    }
}
