//! The exact log-likelihood a linear fit reports: each record's, with the initial state
//! that the written model gives a record.

use nalgebra::DVector;
use sysid_kalman::{InitialState, KalmanError, KalmanWorkspace, LinearGaussianModel, Record};

/// The log-likelihood of a set of independent records under a model whose initial
/// state is applied to each record as a model file's `initial` key says: the model's
/// own (`Given`), the stationary law with the steady state of the record's early inputs
/// (`Stationary`), or exactly diffuse (`Diffuse`). This is what `sysid loglik` computes
/// for a written model, so a fit that maximises it reports the number the file gives.
///
/// With `Stationary`, the steady state averages the first `H` inputs, `H` the model's
/// memory ([`sysid_kalman::stationary_input_memory`]), so the objective moves
/// smoothly with `A` ([`sysid_kalman::early_input_mean`]).
///
/// # Example
/// ```
/// use nalgebra::{DMatrix, dmatrix};
/// use sysid_em::linear::LinearObjective;
/// use sysid_kalman::{InitialState, KalmanWorkspace, LinearGaussianModel, Record};
/// let model = LinearGaussianModel::builder(dmatrix![0.8], dmatrix![1.0], dmatrix![0.5], dmatrix![0.1])
///     .build()?;
/// let record = Record::new(DMatrix::zeros(0, 3), dmatrix![0.3, -0.1, 0.4]);
/// let records = [record];
/// let objective = LinearObjective::new(&records, InitialState::Stationary);
/// let mut ws = KalmanWorkspace::new();
/// let direct = ws.loglik(&InitialState::Stationary.apply(&model)?, &records[0])?;
/// assert_eq!(objective.loglik(&model, &mut ws)?, direct);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct LinearObjective<'a> {
    records: &'a [Record],
    initial: InitialState,
}

impl<'a> LinearObjective<'a> {
    /// The log-likelihood of `records` with `initial` applied to each.
    pub fn new(records: &'a [Record], initial: InitialState) -> Self {
        LinearObjective { records, initial }
    }

    /// The records.
    pub fn records(&self) -> &'a [Record] {
        self.records
    }

    /// The initial-state treatment.
    pub fn initial(&self) -> InitialState {
        self.initial
    }

    /// `model` with the initial state of record `index`.
    ///
    /// # Errors
    /// [`KalmanError::NotStationary`] for a stationary treatment of an unstable `A`.
    pub fn model_for(
        &self,
        model: &LinearGaussianModel,
        index: usize,
    ) -> Result<LinearGaussianModel, KalmanError> {
        match self.initial {
            InitialState::Given => Ok(model.clone()),
            initial => initial.apply_to_record(model, &self.records[index]),
        }
    }

    /// The log-likelihood of the records at `model`.
    ///
    /// # Errors
    /// As [`LinearObjective::model_for`], or the filter's.
    pub fn loglik(
        &self,
        model: &LinearGaussianModel,
        ws: &mut KalmanWorkspace,
    ) -> Result<f64, KalmanError> {
        let mut total = 0.0;
        for (i, record) in self.records.iter().enumerate() {
            total += ws.loglik_of_record(&self.model_for(model, i)?, record, i)?;
        }
        Ok(total)
    }

    /// The log-likelihood and, in `moments`, every observed value's one-step mean and
    /// log standard deviation, record after record
    /// ([`KalmanWorkspace::scalar_moments`]).
    ///
    /// # Errors
    /// As [`LinearObjective::loglik`].
    pub fn loglik_and_moments(
        &self,
        model: &LinearGaussianModel,
        ws: &mut KalmanWorkspace,
        moments: &mut Vec<f64>,
        scratch: &mut Vec<f64>,
    ) -> Result<f64, KalmanError> {
        moments.clear();
        let mut total = 0.0;
        for (i, record) in self.records.iter().enumerate() {
            let applied = self.model_for(model, i)?;
            total += ws.scalar_moments(&applied, record, i, scratch)?;
            moments.extend_from_slice(scratch);
        }
        Ok(total)
    }

    /// The observed values of the records (the length of the moments over two).
    pub fn observed(&self) -> usize {
        self.records
            .iter()
            .map(|r| r.y.iter().filter(|v| !v.is_nan()).count())
            .sum()
    }

    /// The outputs' sample variances of the first record (the scale of the data).
    pub fn output_variances(&self) -> Option<DVector<f64>> {
        self.records.first().map(Record::output_variances)
    }
}
