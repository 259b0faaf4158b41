//! The initial state of a record: the model's own `(mu, P1, A_d)`, the stationary law
//! of its state noise, or exactly diffuse.

use crate::{KalmanError, LinearGaussianModel, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// How the initial state `x_1` of a record is modelled (the `initial` key of a model
/// file, `--initial` on the command line).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InitialState {
    /// The model's `mu`, `P1` and diffuse directions as given.
    #[default]
    Given,
    /// `P1` the stationary covariance `P = A P A' + Q` of the state noise (needs a
    /// stable `A`) and `mu` the steady state of the record's early inputs,
    /// `(I - A)^{-1} B u_bar` with `u_bar` the mean input over the system's memory at
    /// the start of the record (0 without inputs, or through
    /// [`InitialState::apply`]): a record that starts in steady state.
    Stationary,
    /// Every direction of `x_1` diffuse (`A_d = I`, `P1 = 0`): nothing is assumed of
    /// the initial state; the data determine it (exact diffuse initialisation).
    Diffuse,
}

impl InitialState {
    /// The names the command line and Python use: `model` (the model's own, a model
    /// file's `given`), `stationary`, `diffuse`.
    pub const NAMES: [&'static str; 3] = ["model", "stationary", "diffuse"];

    /// Its name in [`InitialState::NAMES`].
    pub fn name(self) -> &'static str {
        match self {
            InitialState::Given => Self::NAMES[0],
            InitialState::Stationary => Self::NAMES[1],
            InitialState::Diffuse => Self::NAMES[2],
        }
    }

    /// `model` with this initial state.
    ///
    /// # Errors
    /// [`KalmanError::NotStationary`] for [`Stationary`](Self::Stationary) with an
    /// unstable `A`.
    pub fn apply(self, model: &LinearGaussianModel) -> Result<LinearGaussianModel> {
        let n = model.n();
        let builder = model.to_builder();
        let builder = match self {
            InitialState::Given => return Ok(model.clone()),
            InitialState::Stationary => builder
                .p1(stationary_covariance(model.a(), model.q())?)
                .diffuse(DMatrix::zeros(n, 0)),
            InitialState::Diffuse => builder
                .p1(DMatrix::zeros(n, n))
                .diffuse(DMatrix::identity(n, n)),
        };
        builder.mu(DVector::zeros(n)).build()
    }

    /// [`apply`](Self::apply) for a given record: a stationary initial state starts at
    /// the steady state of the record's early inputs, `mu = (I - A)^{-1} B u_bar`,
    /// where `u_bar` is the mean input over the first `H` samples and `H` the system's
    /// memory, the steps in which `rho^H` falls to 1 % (`rho` the spectral radius of
    /// `A`; at least 1, at most the record; [`stationary_input_memory`]), the window's
    /// edge smoothed over one step ([`early_input_mean`]) so that `mu`, and the record's
    /// likelihood, move smoothly with `A` (a fit can maximise it). The inputs before the record are unknown;
    /// assuming they resembled its first `H` is right both for a record that starts in
    /// a steady state (a constant input: the first input's steady state) and for one
    /// driven by noise (its mean: the first input alone would put the state far from
    /// where a noise-driven system sits, and the first predictions would be off by
    /// many standard deviations).
    ///
    /// # Errors
    /// As [`apply`](Self::apply).
    pub fn apply_to_record(
        self,
        model: &LinearGaussianModel,
        record: &crate::Record,
    ) -> Result<LinearGaussianModel> {
        if self != InitialState::Stationary || model.m() == 0 || record.is_empty() {
            return self.apply(model);
        }
        let mean_input = early_input_mean(record, stationary_input_memory(model));
        self.apply_with_input(model, &mean_input)
    }

    /// [`apply`](Self::apply), a stationary initial state starting at the steady state
    /// of the constant input `mean_input`, `mu = (I - A)^{-1} B u_bar` (a fit holds the
    /// early inputs' mean while it searches; [`apply_to_record`](Self::apply_to_record)
    /// takes it from the record).
    ///
    /// # Errors
    /// As [`apply`](Self::apply).
    pub fn apply_with_input(
        self,
        model: &LinearGaussianModel,
        mean_input: &DVector<f64>,
    ) -> Result<LinearGaussianModel> {
        let applied = self.apply(model)?;
        if self != InitialState::Stationary || model.m() == 0 {
            return Ok(applied);
        }
        let n = model.n();
        let forced = model.b() * mean_input;
        let mu = (DMatrix::identity(n, n) - model.a())
            .lu()
            .solve(&forced)
            .unwrap_or_else(|| DVector::zeros(n));
        applied.to_builder().mu(mu).build()
    }
}

/// The mean of a record's inputs over its first `memory` steps (at least one, at most
/// the record): the input whose steady state [`InitialState::Stationary`] starts a
/// record at, with the memory [`stationary_input_memory`]. The window's edge is smooth:
/// step `k` (from 0) has the weight `s(memory - k)` with `s(x) = 3x^2 - 2x^3` on
/// `[0, 1]` (0 below, 1 above), so that the mean, and the record's likelihood, have a
/// continuous derivative in the model's parameters (a window of whole steps, or one
/// with a fractional last step, has kinks where a fit stalls).
pub fn early_input_mean(record: &crate::Record, memory: f64) -> DVector<f64> {
    let memory = memory.clamp(1.0, record.len().max(1) as f64);
    let mut sum = DVector::zeros(record.u.nrows());
    let mut weights = 0.0;
    for (k, column) in record.u.column_iter().enumerate() {
        let x = memory - k as f64;
        if x <= 0.0 {
            break;
        }
        let w = if x >= 1.0 {
            1.0
        } else {
            x * x * (3.0 - 2.0 * x)
        };
        sum += column * w;
        weights += w;
    }
    if weights > 0.0 { sum / weights } else { sum }
}

/// The memory of a model in steps: the early inputs that [`InitialState::Stationary`]
/// averages.
///
/// It is measured on the input response `C A^k B`: its energy's centroid
/// `L = sum_k k |C A^k B|^2 / sum_k |C A^k B|^2` (from the Gramians: `W = A W A' + B B'`,
/// `V = A V A' + A W A'`, `L = tr(C V C') / tr(C W C')`), expressed as the steps `H` in
/// which a first-order system with that centroid, `rho^2 = L / (1 + L)`, falls to 1 %:
/// `H = ln 0.01 / ln rho`. For `x' = a x + b u` this is `ln 0.01 / ln |a|`. It depends
/// smoothly on `A`, `B` and `C` and not on the state's basis (the spectral radius has
/// kinks where two eigenvalues' moduli cross, which maxima of a likelihood sit on).
/// Infinite for an unstable `A`; 0 when no input reaches the outputs.
pub fn stationary_input_memory(model: &LinearGaussianModel) -> f64 {
    let (a, b, c) = (model.a(), model.b(), model.c());
    let Ok(w) = stationary_covariance(a, &(b * b.transpose())) else {
        return f64::INFINITY;
    };
    let Ok(v) = stationary_covariance(a, &(a * &w * a.transpose())) else {
        return f64::INFINITY;
    };
    let energy = (c * &w * c.transpose()).trace();
    let moment = (c * &v * c.transpose()).trace();
    if energy.is_nan() || moment.is_nan() || energy <= 0.0 || moment <= 0.0 {
        return 0.0;
    }
    let centroid = moment / energy;
    2.0 * 0.01_f64.ln() / (centroid / (1.0 + centroid)).ln()
}

/// The steps of a record's first inputs that [`InitialState::Stationary`] averages
/// (the system's memory: the steps after which `rho(A)^k < 0.01`); a record read in
/// blocks gives its first block at least this many steps for the same `mu`.
pub fn stationary_input_window(model: &LinearGaussianModel) -> usize {
    let memory = stationary_input_memory(model);
    if memory.is_finite() {
        memory.ceil().max(1.0) as usize
    } else {
        usize::MAX
    }
}

/// The largest modulus of `a`'s eigenvalues.
pub fn spectral_radius(a: &DMatrix<f64>) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    a.complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

/// The stationary covariance `P = A P A' + Q = sum_k A^k Q A'^k` by Smith's doubling
/// (two terms' worth more each round), symmetric by construction.
///
/// # Errors
/// [`KalmanError::NotStationary`] when `A` is not stable (spectral radius >= 1).
pub fn stationary_covariance(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let radius = spectral_radius(a);
    if radius >= 1.0 || !radius.is_finite() {
        return Err(KalmanError::NotStationary { radius });
    }
    let (mut p, mut power) = (q.clone(), a.clone());
    for _ in 0..64 {
        let next = &p + &power * &p * power.transpose();
        let change = (&next - &p).amax();
        p = next;
        power = &power * &power;
        if change <= f64::EPSILON * p.amax() {
            break;
        }
    }
    sysid_linalg::symmetrize(&mut p);
    Ok(p)
}

impl std::fmt::Display for InitialState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for InitialState {
    type Err = String;

    /// An initial state by its name (`given`, a model file's spelling, for `model`);
    /// the error lists the names.
    fn from_str(name: &str) -> std::result::Result<Self, String> {
        match name {
            "model" | "given" => Ok(InitialState::Given),
            "stationary" => Ok(InitialState::Stationary),
            "diffuse" => Ok(InitialState::Diffuse),
            other => Err(format!(
                "unknown initial state {other:?} (known: {})",
                Self::NAMES.join(", ")
            )),
        }
    }
}
