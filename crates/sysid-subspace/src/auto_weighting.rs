//! The SVD weighting chosen by the data: MOESP, N4SID and CVA are all fitted and the
//! stable model that predicts the estimation record best one step ahead is kept.
//!
//! # Algorithm
//! For each weighting, [`n4sid`] with the caller's other options (each chooses its own
//! order under `Order::Auto`); each model is scored by the fit of its one-step Kalman
//! predictions on the same record (`LinearGaussianModel::compare`, mean over the
//! outputs). The best-scoring model with a spectral radius below 1 is kept; when none
//! is stable, the best-scoring one (its warning says it is unstable). Ties keep the
//! earlier weighting in the order MOESP, N4SID, CVA.
//!
//! # Complexity
//! Three N4SID fits and three Kalman filters over the record.

use crate::{N4sidOptions, N4sidResult, SubspaceError, Weighting, n4sid};
use sysid_kalman::{Horizon, Record};

/// A weighting, or the data's choice of one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WeightingChoice {
    /// Fit all three and keep the best stable one ([`n4sid_weighted`]).
    #[default]
    Auto,
    /// This weighting.
    Fixed(Weighting),
}

impl WeightingChoice {
    /// The names: `auto`, then each weighting's.
    pub const NAMES: [&'static str; 4] = ["auto", "moesp", "n4sid", "cva"];

    /// `auto`, or a weighting's name (`moesp`, `n4sid`, `cva`).
    pub fn parse(name: &str) -> Option<WeightingChoice> {
        if name.eq_ignore_ascii_case("auto") {
            return Some(WeightingChoice::Auto);
        }
        Weighting::parse(name).map(WeightingChoice::Fixed)
    }

    /// Its name in [`WeightingChoice::NAMES`].
    pub fn name(self) -> &'static str {
        match self {
            WeightingChoice::Auto => Self::NAMES[0],
            WeightingChoice::Fixed(w) => w.name(),
        }
    }
}

impl std::fmt::Display for WeightingChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for WeightingChoice {
    type Err = String;

    /// A choice by name, ignoring case; the error lists the names.
    fn from_str(name: &str) -> Result<Self, String> {
        WeightingChoice::parse(name).ok_or_else(|| {
            format!(
                "unknown weighting {name:?} (known: {})",
                Self::NAMES.join(", ")
            )
        })
    }
}

/// One weighting's model, as scored by the choice.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightingScore {
    /// The weighting.
    pub weighting: Weighting,
    /// Its order (`None` when it failed).
    pub order: Option<usize>,
    /// Its spectral radius (after `--stable`, if asked).
    pub spectral_radius: Option<f64>,
    /// Mean one-step prediction fit (%) on the record.
    pub prediction_fit: Option<f64>,
    /// Why it could not be fitted or scored.
    pub error: Option<String>,
}

impl WeightingScore {
    /// A stable model that could be scored.
    pub fn usable(&self) -> bool {
        self.spectral_radius.is_some_and(|r| r < 1.0) && self.prediction_fit.is_some()
    }
}

/// The result of [`n4sid_weighted`]: the kept fit and every weighting's score (empty
/// for a fixed weighting).
#[derive(Debug, Clone)]
pub struct WeightedN4sid {
    /// The model kept.
    pub result: N4sidResult,
    /// MOESP, N4SID and CVA, scored (under [`WeightingChoice::Auto`]).
    pub candidates: Vec<WeightingScore>,
}

/// [`n4sid`] with `choice`'s weighting (see the module documentation for `Auto`);
/// `options.weighting` is ignored.
///
/// # Errors
/// A fixed weighting's error; under `Auto`, the first weighting's error when none of
/// the three could be fitted and scored.
pub fn n4sid_weighted(
    record: &Record,
    options: &N4sidOptions,
    choice: WeightingChoice,
) -> Result<WeightedN4sid, SubspaceError> {
    let weightings = match choice {
        WeightingChoice::Fixed(w) => {
            let result = n4sid(
                record,
                &N4sidOptions {
                    weighting: w,
                    ..*options
                },
            )?;
            return Ok(WeightedN4sid {
                result,
                candidates: Vec::new(),
            });
        }
        WeightingChoice::Auto => [Weighting::Moesp, Weighting::N4sid, Weighting::Cva],
    };
    let mut fits = Vec::new();
    let mut candidates = Vec::new();
    for weighting in weightings {
        let fitted = n4sid(
            record,
            &N4sidOptions {
                weighting,
                ..*options
            },
        );
        let score = match &fitted {
            Ok(result) => {
                let fit = result
                    .model
                    .compare(record, Horizon::Steps(1), 0, None)
                    .map(|c| c.mean_fit_percent())
                    .ok()
                    .filter(|f| f.is_finite());
                WeightingScore {
                    weighting,
                    order: Some(result.order),
                    spectral_radius: Some(result.spectral_radius),
                    prediction_fit: fit,
                    error: fit
                        .is_none()
                        .then(|| "its one-step predictions could not be scored".into()),
                }
            }
            Err(e) => WeightingScore {
                weighting,
                order: None,
                spectral_radius: None,
                prediction_fit: None,
                error: Some(e.to_string()),
            },
        };
        candidates.push(score);
        fits.push(fitted);
    }
    let best = |usable: bool| {
        candidates
            .iter()
            .enumerate()
            .filter(|(_, c)| c.prediction_fit.is_some() && (!usable || c.usable()))
            .fold(None::<(usize, f64)>, |best, (k, c)| {
                let f = c.prediction_fit.unwrap_or(f64::NEG_INFINITY);
                match best {
                    Some((_, b)) if b >= f => best,
                    _ => Some((k, f)),
                }
            })
            .map(|(k, _)| k)
    };
    let chosen = best(true)
        .or_else(|| best(false))
        .or_else(|| fits.iter().position(Result::is_ok));
    match chosen {
        Some(k) => Ok(WeightedN4sid {
            result: fits.swap_remove(k).expect("a chosen weighting was fitted"),
            candidates,
        }),
        None => Err(fits
            .into_iter()
            .find_map(Result::err)
            .unwrap_or(SubspaceError::NoOutputs)),
    }
}
