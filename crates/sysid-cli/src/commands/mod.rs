//! One module per subcommand.

pub mod compare;
pub mod demo;
pub mod detrend;
mod filter_trust;
pub mod fit;
pub mod forecast;
pub mod loglik;
pub mod n4sid;
pub mod nonlinear;
pub mod particle;
pub mod plot;
pub mod pmcmc;
pub mod predict;
pub mod resid;
pub mod simulate;
pub mod simulate_args;
pub mod simulate_model;
pub mod smooth;
pub mod systems;
pub mod tf;

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
        self.read_columns(metadata, false)
    }

    /// Reads the data file to run a model file on: the model's columns where none are
    /// chosen, its stored linear trend removed (added back by
    /// [`DataFile::restored`]). With `outputs_if_present`, a file without the model's
    /// outputs is read as inputs only.
    pub fn read_for_model(
        &self,
        stored: &crate::files::ModelFile,
        outputs_if_present: bool,
    ) -> Result<DataFile, CliError> {
        let mut file = self.read_columns(stored.metadata.as_ref(), outputs_if_present)?;
        if let Some(trend) = &stored.trend {
            check_column_counts(
                &file,
                stored.model.m(),
                if file.output_names.is_empty() {
                    0
                } else {
                    stored.model.p()
                },
            )?;
            trend
                .check_time_base(&file.time)
                .map_err(|e| CliError::BadOption {
                    option: "--data",
                    message: format!("{}: {e}", self.data.display()),
                })?;
            detrend::remove(trend, &mut file);
        }
        Ok(file)
    }

    /// Reads the data file for a nonlinear model file: the columns named as the
    /// model's inputs and outputs when the file has them (and none are chosen), else
    /// the default columns (u1, u2, ... and y1, y2, ...); their counts are checked
    /// against the model's.
    pub fn read_for_names(
        &self,
        inputs: &[String],
        outputs: &[String],
    ) -> Result<DataFile, CliError> {
        let file = if self.inputs.is_none() && self.outputs.is_none() {
            let names = Metadata {
                inputs: inputs.to_vec(),
                outputs: outputs.to_vec(),
                ..Metadata::default()
            };
            match self.read_columns(Some(&names), false) {
                Ok(file) => file,
                // the model's names are not the file's: a record with the default
                // column names (y1, u1, ...); any other fault (a bad cell) is the file's
                Err(CliError::UnknownColumn { .. }) => self.read()?,
                Err(other) => return Err(other),
            }
        } else {
            self.read()?
        };
        check_column_counts(&file, inputs.len(), outputs.len())?;
        Ok(file)
    }

    /// The columns to read: those chosen, or where none are, a model's (its
    /// metadata's names), else the default ones.
    pub fn choice(&self, metadata: Option<&Metadata>, outputs_if_present: bool) -> ColumnChoice {
        let named = |given: &Option<Vec<String>>, stored: Option<&Vec<String>>| {
            given
                .clone()
                .or_else(|| stored.filter(|names| !names.is_empty()).cloned())
        };
        ColumnChoice {
            inputs: named(&self.inputs, metadata.map(|m| &m.inputs)),
            outputs: named(&self.outputs, metadata.map(|m| &m.outputs)),
            outputs_if_present,
        }
    }

    /// `--ts`, checked.
    pub fn sample_time(&self) -> Result<Option<f64>, CliError> {
        match self.ts {
            Some(ts) if !(ts.is_finite() && ts > 0.0) => Err(CliError::BadOption {
                option: "--ts",
                message: format!("{ts} is not a positive sampling interval"),
            }),
            ts => Ok(ts),
        }
    }

    fn read_columns(
        &self,
        metadata: Option<&Metadata>,
        outputs_if_present: bool,
    ) -> Result<DataFile, CliError> {
        let file = read_data(&self.data, &self.choice(metadata, outputs_if_present))?;
        let mut file = match &self.range {
            None => file,
            Some(range) => rows(file, range)?,
        };
        if let Some(ts) = self.sample_time()? {
            file.sample_time = Some(ts);
        }
        Ok(file)
    }
}

/// `--range START:END` (1-based): the first row and, when given, the last.
pub fn parse_range(range: &str) -> Result<(usize, Option<usize>), CliError> {
    let (start, end) = range
        .split_once(':')
        .ok_or_else(|| bad_range(format!("{range:?} is not START:END (e.g. 1:400, 401:)")))?;
    let bound = |text: &str| -> Result<Option<usize>, CliError> {
        if text.trim().is_empty() {
            return Ok(None);
        }
        text.trim()
            .parse::<usize>()
            .map(Some)
            .map_err(|_| bad_range(format!("{text:?} is not a row number")))
    };
    Ok((bound(start)?.unwrap_or(1), bound(end)?))
}

fn bad_range(message: String) -> CliError {
    CliError::BadOption {
        option: "--range",
        message,
    }
}

/// Refuses rows `start..=end` of a file of `total` rows unless they are within it.
pub fn check_range(start: usize, end: usize, total: usize) -> Result<(), CliError> {
    if start == 0 || start > end || end > total {
        return Err(bad_range(format!(
            "rows {start} to {end} are not within the file's 1 to {total}"
        )));
    }
    Ok(())
}

/// The rows `START..=END` (1-based) of a data file, from `--range START:END`.
pub fn rows(mut file: DataFile, range: &str) -> Result<DataFile, CliError> {
    let total = file.record.len();
    let (start, end) = parse_range(range)?;
    let end = end.unwrap_or(total);
    check_range(start, end, total)?;
    let (from, len) = (start - 1, end - start + 1);
    file.record = sysid::kalman::Record::new(
        file.record.u.columns(from, len).clone_owned(),
        file.record.y.columns(from, len).clone_owned(),
    );
    file.time = file.time[from..from + len].to_vec();
    file.labels = file.labels.range(from, len);
    Ok(file)
}

/// Checks that a data file has as many input and output columns as the model.
pub fn check_columns(model: &LinearGaussianModel, file: &DataFile) -> Result<(), CliError> {
    check_column_counts(file, model.m(), model.p())
}

/// Checks that a data file has `inputs` input and `outputs` output columns.
pub fn check_column_counts(file: &DataFile, inputs: usize, outputs: usize) -> Result<(), CliError> {
    check_counts(
        (file.input_names.len(), file.output_names.len()),
        (inputs, outputs),
    )
}

/// Checks that the (inputs, outputs) columns `found` are those `expected`.
pub fn check_counts(found: (usize, usize), expected: (usize, usize)) -> Result<(), CliError> {
    for (what, found, expected) in [
        ("input", found.0, expected.0),
        ("output", found.1, expected.1),
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
    let stored = read_model_file(path)?;
    let file = data.read_for_model(&stored, false)?;
    let model = stored.model;
    check_columns(&model, &file)?;
    // `model`: the file's own initial state (a stationary one, at this record's first
    // input)
    let initial = match parse_initial(initial)? {
        sysid::kalman::InitialState::Given => stored.initial,
        chosen => chosen,
    };
    let model = initial
        .apply_to_record(&model, &file.record)
        .map_err(|source| CliError::Model {
            path: path.to_path_buf(),
            source,
        })?;
    Ok((model, file))
}

/// The `--initial` option: `model` (the model file's initial state), `stationary` or
/// `diffuse`.
pub fn parse_initial(text: &str) -> Result<sysid::kalman::InitialState, CliError> {
    text.parse().map_err(|message| CliError::BadOption {
        option: "--initial",
        message,
    })
}

impl crate::ModelOnData {
    /// Reads the model and the data, checks that their columns match, and gives the
    /// model the chosen initial state.
    pub fn load(&self) -> Result<(LinearGaussianModel, DataFile), CliError> {
        model_and_data(&self.model, &self.data, &self.initial)
    }

    /// The data file, for errors.
    pub fn data_path(&self) -> &Path {
        &self.data.data
    }

    /// The model file's path.
    pub fn model_path(&self) -> &Path {
        &self.model
    }

    /// A nonlinear model file (`.toml`) and the record read by its column names.
    pub fn load_model_file(&self) -> Result<(sysid::modelfile::ModelFile, DataFile), CliError> {
        let model = nonlinear::read(&self.model)?;
        let file = self
            .data
            .read_for_names(&model.spec().inputs, &model.spec().outputs)?;
        Ok((model, file))
    }
}

/// Wraps a Kalman error with the data file it concerns.
pub fn in_data(data: &Path) -> impl Fn(sysid::kalman::KalmanError) -> CliError + '_ {
    move |source| CliError::Kalman {
        context: data.display().to_string(),
        source,
    }
}

/// A library error of a record's computation: an out-of-range option named as the
/// command line spells it (`options` pairs the library's name with the flag), a
/// diverging simulation blamed on the model, anything else on the data file.
pub fn kalman_error<'a>(
    model: &'a Path,
    data: &'a Path,
    options: &'a [(&'static str, &'static str)],
) -> impl Fn(sysid::kalman::KalmanError) -> CliError + 'a {
    use sysid::kalman::KalmanError;
    move |source| match source {
        KalmanError::BadOption { name, message } => CliError::BadOption {
            option: options
                .iter()
                .find(|(library, _)| *library == name)
                .map_or(name, |(_, flag)| *flag),
            message,
        },
        KalmanError::SimulationDiverges { .. } => CliError::Model {
            path: model.to_path_buf(),
            source,
        },
        source => in_data(data)(source),
    }
}

/// After a run's outputs are written: Ctrl-C's error (exit 130, naming what was
/// written) when it stopped the run, else `Ok`.
pub fn interrupted<E>(
    termination: &sysid::em::Termination<E>,
    written: impl IntoIterator<Item = std::path::PathBuf>,
) -> Result<(), CliError> {
    match termination {
        sysid::em::Termination::Interrupted { iteration } => Err(CliError::Interrupted {
            iteration: *iteration,
            written: written.into_iter().collect(),
        }),
        _ => Ok(()),
    }
}
