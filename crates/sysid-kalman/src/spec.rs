//! A serialisable description of a [`LinearGaussianModel`] (the JSON model file).

use crate::{InitialState, KalmanError, LinearGaussianModel, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Plain-data form of a model: matrices as arrays of rows, vectors as arrays.
/// Optional entries default as in [`LinearGaussianModel::builder`].
/// The JSON schema is documented in `docs/model-format.md`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// `A`, n x n.
    pub a: Vec<Vec<f64>>,
    /// `B`, n x m (absent: no inputs, or zero when `d` is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b: Option<Vec<Vec<f64>>>,
    /// `C`, p x n.
    pub c: Vec<Vec<f64>>,
    /// `D`, p x m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d: Option<Vec<Vec<f64>>>,
    /// `Q`, n x n.
    pub q: Vec<Vec<f64>>,
    /// `R`, p x p.
    pub r: Vec<Vec<f64>>,
    /// `S`, n x p.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub s: Option<Vec<Vec<f64>>>,
    /// `h`, p.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h: Option<Vec<f64>>,
    /// `mu`, n.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mu: Option<Vec<f64>>,
    /// `P1`, n x n.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p1: Option<Vec<Vec<f64>>>,
    /// `A_d`, n x q: diffuse directions of the initial state.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diffuse: Option<Vec<Vec<f64>>>,
    /// How a record's initial state is modelled: `given` (by `mu`, `p1`, `diffuse`;
    /// the default), `stationary` or `diffuse` (then those keys must be absent).
    #[serde(default, skip_serializing_if = "is_given")]
    pub initial: InitialState,
    /// What the model was made from and how well it fits: names, sample time, the
    /// command, the fit's figures. Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metadata: Option<Metadata>,
}

/// The covariance of a fit's free parameters, named as `A[1,2]`, `Q[1,1]`, `h[1]`
/// (1-based), `matrix[k][l]` for the `k`-th and `l`-th names.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterCovariance {
    /// The parameters, in the order of the rows.
    pub names: Vec<String>,
    /// The covariance, by rows.
    pub matrix: Vec<Vec<f64>>,
}

/// The trends removed from the signals before a fit (`--detrend mean|linear`).
///
/// `mean`: the means are folded into the model's offset `h` (and `mu`), so the model
/// describes the original signals and nothing is left to apply. `linear`: a straight
/// line in time per signal, `value(t) = offset + slope (t - origin)`, with `t` the data
/// file's time (its numeric time column, or the row number); a linear trend cannot be
/// folded into a time-invariant model, so the model describes the detrended signals
/// and every command that runs it on a record removes the trends at the record's times
/// and adds the outputs' trend back to what it returns.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Detrend {
    /// `mean` or `linear`.
    pub kind: String,
    /// The inputs' means (`mean`), or their trends' values at `origin` (`linear`).
    pub inputs: Vec<f64>,
    /// The outputs' means (`mean`), or their trends' values at `origin` (`linear`).
    pub outputs: Vec<f64>,
    /// `linear`: the time at which the offsets hold (the fitted record's first time).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<f64>,
    /// `linear`: the inputs' slopes per unit of time.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub input_slopes: Vec<f64>,
    /// `linear`: the outputs' slopes per unit of time.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub output_slopes: Vec<f64>,
    /// `linear`: the fitted record's time step (the mean spacing of its times), by
    /// which a record on another time base is recognised (its trend would be removed at
    /// the wrong times). Absent in files written before it was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_step: Option<f64>,
}

/// A model file's description of its data and of its fit (every entry optional;
/// unknown entries are kept out of the way of older readers by being ignored).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Metadata {
    /// Names of the input columns, in the model's order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<String>,
    /// Names of the output columns, in the model's order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<String>,
    /// The detrending the model was fitted with: means are already folded into its
    /// offset `h` (and `mu`); a linear trend is applied by the commands that use the
    /// model on data (see [`Detrend`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detrend: Option<Detrend>,
    /// The free parameters' covariance (inverse observed information), when standard
    /// errors were computed: plots draw confidence bands from it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance: Option<ParameterCovariance>,
    /// Sample time (in the units of the data's time column), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_time: Option<f64>,
    /// The state dimension `n`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub order: Option<usize>,
    /// Log-likelihood of the estimation data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loglik: Option<f64>,
    /// Number of free parameters of the fit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameters: Option<usize>,
    /// Akaike's criterion `-2 loglik + 2 k`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aic: Option<f64>,
    /// Schwarz's criterion `-2 loglik + k ln N` (`N` observed values).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bic: Option<f64>,
    /// Why the estimation stopped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub termination: Option<String>,
    /// The command line that wrote the model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
    /// The estimation data file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<String>,
    /// A fingerprint of the estimation data's values (FNV-1a, 64 bits, over the bits
    /// of the inputs and outputs, in hexadecimal): tells whether two models were fitted
    /// on the same numbers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_fingerprint: Option<String>,
}

fn is_given(initial: &InitialState) -> bool {
    *initial == InitialState::Given
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn matrix(name: &str, rows: &[Vec<f64>]) -> Result<DMatrix<f64>> {
    let ncols = rows.first().map_or(0, Vec::len);
    for (i, row) in rows.iter().enumerate() {
        if row.len() != ncols {
            return Err(KalmanError::Dimension {
                name: format!("{name} (row {})", i + 1),
                expected_rows: rows.len(),
                expected_cols: ncols,
                rows: rows.len(),
                cols: row.len(),
            });
        }
    }
    Ok(DMatrix::from_fn(rows.len(), ncols, |i, j| rows[i][j]))
}

impl ModelSpec {
    /// The spec of a model (every matrix written out, `B`/`D` omitted without inputs).
    pub fn from_model(model: &LinearGaussianModel) -> Self {
        let has_inputs = model.m() > 0;
        ModelSpec {
            a: rows_of(model.a()),
            b: has_inputs.then(|| rows_of(model.b())),
            c: rows_of(model.c()),
            d: has_inputs.then(|| rows_of(model.d())),
            q: rows_of(model.q()),
            r: rows_of(model.r()),
            s: model.has_cross_covariance().then(|| rows_of(model.s())),
            h: model
                .h()
                .iter()
                .any(|&v| v != 0.0)
                .then(|| model.h().iter().copied().collect()),
            mu: Some(model.mu().iter().copied().collect()),
            p1: Some(rows_of(model.p1())),
            diffuse: model.is_diffuse().then(|| rows_of(model.diffuse())),
            initial: InitialState::Given,
            metadata: None,
        }
    }

    /// The file's text: JSON with one row of a matrix per line.
    pub fn to_json(&self) -> String {
        let value = serde_json::to_value(self).expect("a model spec serialises");
        let mut out = String::from("{\n");
        let serde_json::Value::Object(map) = value else {
            unreachable!("a struct serialises to an object")
        };
        let last = map.len().saturating_sub(1);
        for (k, (key, v)) in map.iter().enumerate() {
            let text = match v {
                serde_json::Value::Array(rows) if rows.iter().any(|r| r.is_array()) => {
                    let lines: Vec<String> = rows.iter().map(|r| format!("    {r}")).collect();
                    format!("[\n{}\n  ]", lines.join(",\n"))
                }
                serde_json::Value::Object(_) => serde_json::to_string_pretty(v)
                    .expect("serialises")
                    .replace('\n', "\n  "),
                other => other.to_string(),
            };
            let comma = if k < last { "," } else { "" };
            out += &format!(
                "  {}: {text}{comma}\n",
                serde_json::Value::String(key.clone())
            );
        }
        out + "}\n"
    }

    /// The spec of a model's system, with its initial state described by `initial`
    /// instead of the matrices `mu`, `P1`, `A_d` (kept for [`InitialState::Given`]).
    pub fn with_initial(model: &LinearGaussianModel, initial: InitialState) -> Self {
        let mut spec = Self::from_model(model);
        if initial != InitialState::Given {
            spec.mu = None;
            spec.p1 = None;
            spec.diffuse = None;
            spec.initial = initial;
        }
        spec
    }

    /// Validates the spec and builds the model (see [`crate::ModelBuilder::build`]).
    ///
    /// # Errors
    /// Those of the builder; [`KalmanError::InitialConflict`] for `mu`, `p1` or
    /// `diffuse` beside an `initial` other than `given`;
    /// [`KalmanError::NotStationary`] for a stationary initial state of an unstable `A`.
    pub fn build(&self) -> Result<LinearGaussianModel> {
        if self.initial != InitialState::Given {
            let given = [
                ("mu", self.mu.is_some()),
                ("p1", self.p1.is_some()),
                ("diffuse", self.diffuse.is_some()),
            ];
            if let Some((key, _)) = given.iter().find(|(_, present)| *present) {
                return Err(KalmanError::InitialConflict { key });
            }
        }
        let mut builder = LinearGaussianModel::builder(
            matrix("A", &self.a)?,
            matrix("C", &self.c)?,
            matrix("Q", &self.q)?,
            matrix("R", &self.r)?,
        );
        if let Some(b) = &self.b {
            builder = builder.b(matrix("B", b)?);
        }
        if let Some(d) = &self.d {
            builder = builder.d(matrix("D", d)?);
        }
        if let Some(s) = &self.s {
            builder = builder.s(matrix("S", s)?);
        }
        if let Some(h) = &self.h {
            builder = builder.h(DVector::from_column_slice(h));
        }
        if let Some(mu) = &self.mu {
            builder = builder.mu(DVector::from_column_slice(mu));
        }
        if let Some(p1) = &self.p1 {
            builder = builder.p1(matrix("P1", p1)?);
        }
        if let Some(diffuse) = &self.diffuse {
            builder = builder.diffuse(matrix("diffuse", diffuse)?);
        }
        self.initial.apply(&builder.build()?)
    }
}
