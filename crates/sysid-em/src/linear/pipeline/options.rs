//! What a linear fit does: the options of [`super::LinearFit::run`] and their checked
//! form.

use super::{Fix, LinearFitError, Matrix};
use crate::{CheckedEmOptions, EmOptions, OptionsError, SettingError};
use sysid_kalman::{InitialState, LinearGaussianModel, TrendKind};
use sysid_subspace::WeightingChoice;

/// `Display` by the type's `name()` and `FromStr` over its `ALL` and `NAMES`, the error
/// listing the names: one spelling for the library, the command line and Python.
macro_rules! named_choice {
    ($t:ty, $what:literal) => {
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $t {
            type Err = String;

            fn from_str(name: &str) -> Result<Self, String> {
                <$t>::ALL
                    .into_iter()
                    .find(|c| c.name() == name)
                    .ok_or_else(|| {
                        format!(
                            concat!("unknown ", $what, " {:?} (known: {})"),
                            name,
                            <$t>::NAMES.join(", ")
                        )
                    })
            }
        }
    };
}

/// The most states an order range may reach.
pub const MAX_ORDER: usize = 20;

/// Where EM starts.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Start {
    /// A subspace (N4SID) fit of the training record at the chosen order, its
    /// cross-covariance `S` and initial mean set to zero. Under
    /// [`WeightingChoice::Auto`] (the default) one fit per SVD weighting (MOESP, N4SID,
    /// CVA): EM runs from each and the best by the written model's likelihood is
    /// finished (the likelihood of a black-box model has several local maxima, and
    /// the weightings often start in different ones).
    N4sid {
        /// Enforce a stable `A` in the subspace fit.
        stable: bool,
        /// The SVD weighting, or all three.
        weighting: WeightingChoice,
    },
    /// A model of the user's (a model file, an earlier fit), with the initial state its
    /// file gives a record (`Given` for its own `mu` and `P1`): under
    /// [`LinearFitOptions::initial`]'s default the training record starts so, and a
    /// model given with its own initial state is written with it.
    Model {
        /// The model.
        model: Box<LinearGaussianModel>,
        /// Its file's initial state.
        initial: InitialState,
    },
}

impl Start {
    /// A start from `model` with its own `mu` and `P1`.
    pub fn model(model: LinearGaussianModel) -> Start {
        Start::Model {
            model: Box::new(model),
            initial: InitialState::Given,
        }
    }

    /// A start from a model file.
    ///
    /// # Errors
    /// The file's model fails its checks.
    pub fn of_file(spec: &sysid_kalman::ModelSpec) -> Result<Start, sysid_kalman::KalmanError> {
        Ok(Start::Model {
            model: Box::new(spec.build()?),
            initial: spec.initial,
        })
    }
}

/// The order or orders fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderChoice {
    /// The start model's order (a [`Start::Model`] only).
    OfStart,
    /// This order (checked against a [`Start::Model`]).
    Fixed(usize),
    /// Every order `from..=to` is fitted (N4SID start, no polish, no standard errors);
    /// the one `select` prefers is then fitted in full.
    Range {
        /// The smallest order.
        from: usize,
        /// The largest order (at most [`MAX_ORDER`]).
        to: usize,
        /// The criterion that chooses.
        select: Selection,
    },
}

/// The criterion that chooses an order of a range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Selection {
    /// Bayesian information criterion (the default).
    #[default]
    Bic,
    /// Akaike information criterion.
    Aic,
    /// The best simulation fit on the rows held out by the split.
    Validation,
}

impl Selection {
    /// The names, in the order of the variants.
    pub const NAMES: [&'static str; 3] = ["bic", "aic", "validation"];
    const ALL: [Selection; 3] = [Selection::Bic, Selection::Aic, Selection::Validation];

    /// `bic`, `aic` or `validation`.
    pub fn name(self) -> &'static str {
        Self::NAMES[Self::ALL.iter().position(|&s| s == self).unwrap_or(0)]
    }
}

named_choice!(Selection, "criterion");

/// How EM is run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Acceleration {
    /// SQUAREM (Varadhan and Roland 2008; monotone, three E-steps per cycle).
    #[default]
    Squarem,
    /// Plain EM.
    None,
}

impl Acceleration {
    /// The names, in the order of the variants.
    pub const NAMES: [&'static str; 2] = ["squarem", "none"];
    const ALL: [Acceleration; 2] = [Acceleration::Squarem, Acceleration::None];

    /// `squarem` or `none`.
    pub fn name(self) -> &'static str {
        Self::NAMES[Self::ALL.iter().position(|&s| s == self).unwrap_or(0)]
    }
}

named_choice!(Acceleration, "acceleration");

/// A step that can be asked for, refused, or left to the fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Switch {
    /// When it is feasible: at most 20 free coordinates (and, for standard errors,
    /// not a black-box model).
    #[default]
    Auto,
    /// Always.
    On,
    /// Never.
    Off,
}

impl Switch {
    /// The names, in the order of the variants.
    pub const NAMES: [&'static str; 3] = ["auto", "on", "off"];
    const ALL: [Switch; 3] = [Switch::Auto, Switch::On, Switch::Off];

    /// `auto`, `on` or `off`.
    pub fn name(self) -> &'static str {
        Self::NAMES[Self::ALL.iter().position(|&s| s == self).unwrap_or(0)]
    }
}

named_choice!(Switch, "choice");

/// Everything [`super::LinearFit::run`] does. Build it from [`Default`] and set the
/// fields; [`LinearFitOptions::check`] gives the form the fit accepts.
///
/// # Example
/// ```
/// use sysid_em::linear::{LinearFitOptions, OrderChoice};
/// let mut options = LinearFitOptions::default();
/// options.order = OrderChoice::Fixed(2);
/// assert!(options.clone().check().is_ok());
/// options.min_variance = -1.0;
/// assert!(options.check().is_err());
/// ```
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct LinearFitOptions {
    /// Where EM starts (default: N4SID).
    pub start: Start,
    /// The order or orders (default: the start's; N4SID needs one).
    pub order: OrderChoice,
    /// Matrices held fixed.
    pub fixes: Vec<Fix>,
    /// Covariances estimated as diagonal (`Q`, `R`).
    pub diagonal: Vec<Matrix>,
    /// Estimate a full `R` for several outputs (by default `R` is diagonal then:
    /// independent sensor noise, MARSS's default).
    pub full_r: bool,
    /// Lower bound on the free noise variances (`Q, R >= v I`); 0 for none.
    pub min_variance: f64,
    /// Lower bound on `R` relative to each output's sample variance; 0 for none.
    pub min_output_noise: f64,
    /// Estimate the output offset `h` (otherwise held at the start's).
    pub offset: bool,
    /// Estimate the training record's initial mean and covariance.
    pub estimate_initial: bool,
    /// The training record's initial state (default: the start model's).
    pub initial: InitialState,
    /// How EM is run (default: SQUAREM).
    pub acceleration: Acceleration,
    /// The quasi-Newton polish of the exact log-likelihood after EM.
    pub polish: Switch,
    /// Standard errors from the observed information.
    pub std_errors: Switch,
    /// Remove each signal's mean or line before the fit (default: none).
    pub detrend: Option<TrendKind>,
    /// Fit on this fraction of the steps and score the model on the rest.
    pub split: Option<f64>,
    /// EM iterations at most (E-steps with SQUAREM). Default 500.
    pub max_iterations: usize,
    /// Stop at this relative change of the log-likelihood (default: none).
    pub tol: Option<f64>,
    /// Stop when the estimated distance to the maximum is below this many nats.
    /// Default 1e-4.
    pub tol_nats: f64,
}

impl LinearFitOptions {
    /// What runs when the subspace start's settings (`weighting`, `stable`) are given
    /// with a start model: they are refused, not dropped.
    pub const MODEL_START: &'static str =
        "EM from the given start model (init is a model file, not n4sid)";
    /// What runs when `select` is given without a range of orders.
    pub const ONE_ORDER: &'static str = "a fit of one order (order is not a range)";
}

impl Default for LinearFitOptions {
    fn default() -> Self {
        LinearFitOptions {
            start: Start::N4sid {
                stable: false,
                weighting: WeightingChoice::Auto,
            },
            order: OrderChoice::OfStart,
            fixes: Vec::new(),
            diagonal: Vec::new(),
            full_r: false,
            min_variance: 0.0,
            min_output_noise: 0.0,
            offset: false,
            estimate_initial: false,
            initial: InitialState::Given,
            acceleration: Acceleration::Squarem,
            polish: Switch::Auto,
            std_errors: Switch::Auto,
            detrend: None,
            split: None,
            max_iterations: 500,
            tol: None,
            tol_nats: 1e-4,
        }
    }
}

/// [`LinearFitOptions`] that passed [`LinearFitOptions::check`]: the only form
/// [`super::LinearFit::run`] takes.
#[derive(Debug, Clone)]
pub struct CheckedLinearFitOptions {
    pub(super) options: LinearFitOptions,
    pub(super) em: CheckedEmOptions,
}

impl std::ops::Deref for CheckedLinearFitOptions {
    type Target = LinearFitOptions;
    fn deref(&self) -> &LinearFitOptions {
        &self.options
    }
}

fn invalid(option: &'static str, message: impl Into<String>) -> LinearFitError {
    LinearFitError::InvalidOption {
        option,
        message: message.into(),
    }
}

/// The runner's refusal of EM's options, named as the fit's settings (`max_iter`,
/// `tol`, `tol_nats`).
pub(super) fn em_options_error(e: OptionsError) -> LinearFitError {
    match SettingError::from(e) {
        SettingError::Invalid { setting, reason } => invalid(setting, reason),
        other => invalid(other.setting(), other.to_string()),
    }
}

impl LinearFitOptions {
    /// Checks what can be checked without the data.
    ///
    /// # Errors
    /// [`LinearFitError::InvalidOption`] naming the field: zero iterations, a negative
    /// or non-finite tolerance or bound, a matrix fixed twice, a diagonal matrix other
    /// than `Q` or `R`, an empty or too long order range, an N4SID start without an
    /// order, validation selection without a split.
    pub fn check(self) -> Result<CheckedLinearFitOptions, LinearFitError> {
        let em = EmOptions {
            max_iterations: self.max_iterations,
            tol: self.tol.unwrap_or(0.0),
            distance_tol: self.tol_nats,
            ..EmOptions::default()
        }
        .check()
        .map_err(em_options_error)?;
        for (k, fix) in self.fixes.iter().enumerate() {
            if self.fixes[..k].iter().any(|g| g.matrix == fix.matrix) {
                return Err(invalid(
                    "fix",
                    format!("{} is fixed twice; give it once", fix.matrix),
                ));
            }
        }
        if let Some(other) = self
            .diagonal
            .iter()
            .find(|m| !matches!(m, Matrix::Q | Matrix::R))
        {
            return Err(invalid("diag", Matrix::not_diagonal(other.name())));
        }
        for (option, value) in [
            ("min_variance", self.min_variance),
            ("min_output_noise", self.min_output_noise),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(invalid(
                    option,
                    format!("must be a finite non-negative number, got {value}"),
                ));
            }
        }
        match (self.order, &self.start) {
            (OrderChoice::OfStart, Start::N4sid { .. }) => {
                return Err(invalid(
                    "order",
                    "an N4SID start needs a model order (--order n)",
                ));
            }
            (OrderChoice::Fixed(0), _) => {
                return Err(invalid("order", "the order must be at least 1"));
            }
            (OrderChoice::Range { from, to, select }, start) => {
                if from == 0 || from > to || to > MAX_ORDER {
                    return Err(invalid(
                        "order",
                        format!(
                            "{from}..{to} is not a range of orders like 1..8 (from 1 to at \
                             most {MAX_ORDER})"
                        ),
                    ));
                }
                if !matches!(start, Start::N4sid { .. }) {
                    return Err(invalid(
                        "order",
                        "an order range starts each order from N4SID; it cannot start from a \
                         model",
                    ));
                }
                if select == Selection::Validation && self.split.is_none() {
                    return Err(invalid(
                        "select",
                        "validation needs held-out rows: add --split FRACTION",
                    ));
                }
            }
            _ => {}
        }
        Ok(CheckedLinearFitOptions { options: self, em })
    }
}
