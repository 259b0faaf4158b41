//! One module per subcommand.

pub mod compare;
pub mod demo;
pub mod fit;
pub mod fit_affine;
pub mod fit_wiener;
pub mod fix;
pub mod forecast;
pub mod loglik;
pub mod n4sid;
pub mod particle;
pub mod plot;
pub mod pmcmc;
pub mod predict;
pub mod resid;
pub mod simulate;
pub mod simulate_model;
pub mod smooth;

use crate::DataArgs;
use crate::error::CliError;
use crate::files::{ColumnChoice, DataFile, read_data, read_model_file};
use std::path::Path;
use sysid::kalman::{LinearGaussianModel, Metadata};

impl DataArgs {
    /// Reads the data file with the chosen columns.
    pub fn read(&self) -> Result<DataFile, CliError> {
        self.read_for(None)
    }

    /// Reads the data file with the chosen columns, or, where none are chosen, the
    /// columns a model was fitted on (its metadata's names).
    pub fn read_for(&self, metadata: Option<&Metadata>) -> Result<DataFile, CliError> {
        let named = |given: &Option<Vec<String>>, stored: Option<&Vec<String>>| {
            given
                .clone()
                .or_else(|| stored.filter(|names| !names.is_empty()).cloned())
        };
        read_data(
            &self.data,
            &ColumnChoice {
                inputs: named(&self.inputs, metadata.map(|m| &m.inputs)),
                outputs: named(&self.outputs, metadata.map(|m| &m.outputs)),
            },
        )
    }
}

/// Checks that a data file has as many input and output columns as the model.
pub fn check_columns(model: &LinearGaussianModel, file: &DataFile) -> Result<(), CliError> {
    check_column_counts(file, model.m(), model.p())
}

/// Checks that a data file has `inputs` input and `outputs` output columns.
pub fn check_column_counts(file: &DataFile, inputs: usize, outputs: usize) -> Result<(), CliError> {
    for (what, found, expected) in [
        ("input", file.input_names.len(), inputs),
        ("output", file.output_names.len(), outputs),
    ] {
        if found != expected {
            return Err(CliError::ColumnCount {
                what,
                found,
                expected,
            });
        }
    }
    Ok(())
}

/// Reads a model and a data file and checks that their columns match.
pub fn model_and_data(
    model: &Path,
    data: &DataArgs,
    initial: &str,
) -> Result<(LinearGaussianModel, DataFile), CliError> {
    let path = model;
    let (model, metadata) = read_model_file(path)?;
    let model = parse_initial(initial)?
        .apply(&model)
        .map_err(|source| CliError::Model {
            path: path.to_path_buf(),
            source,
        })?;
    let file = data.read_for(metadata.as_ref())?;
    check_columns(&model, &file)?;
    Ok((model, file))
}

/// The `--initial` option: `model` (the model file's initial state), `stationary` or
/// `diffuse`.
pub fn parse_initial(text: &str) -> Result<sysid::kalman::InitialState, CliError> {
    use sysid::kalman::InitialState;
    match text {
        "model" => Ok(InitialState::Given),
        "stationary" => Ok(InitialState::Stationary),
        "diffuse" => Ok(InitialState::Diffuse),
        other => Err(CliError::BadOption {
            option: "--initial",
            message: format!("unknown initial state {other:?} (known: model, stationary, diffuse)"),
        }),
    }
}

/// Wraps a Kalman error with the data file it concerns.
pub fn in_data(data: &Path) -> impl Fn(sysid::kalman::KalmanError) -> CliError + '_ {
    move |source| CliError::Kalman {
        context: data.display().to_string(),
        source,
    }
}
