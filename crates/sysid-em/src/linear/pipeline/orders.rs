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
    let (training, held_out) = match options.split {
        Some(fraction) => {
            let (first, rest) = data.split(fraction)?;
            (first, Some(rest))
        }
        None => (data.clone(), None),
    };
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
