use std::path::PathBuf;
use sysid::kalman::KalmanError;
use thiserror::Error;

/// Everything the command line can report; each message names the place.
#[derive(Debug, Error)]
pub enum CliError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// An input file (data, model, prior) that could not be opened or read.
    #[error("{path}: {source}")]
    Input {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: refusing to overwrite an existing file (use --force)")]
    WouldOverwrite { path: PathBuf },
    /// An output whose folder does not exist (refused before any work).
    #[error("{path}: the folder {folder} does not exist; create it first")]
    NoFolder { path: PathBuf, folder: PathBuf },
    #[error("{path}: given for two outputs of this command; choose a file for each")]
    SameOutput { path: PathBuf },
    /// EM could not evaluate its start (e.g. a start with a singular `R` on
    /// noise-free data); nothing was written.
    #[error("fit: {message}")]
    FitFailedAtStart {
        /// What failed, why, and the option that avoids it.
        message: String,
    },
    #[error("{0}")]
    Plot(sysid_plot::PlotError),
    /// An output file that cannot be written as asked (not a regular file).
    #[error("{0}")]
    Output(sysid_output::OutputError),
    #[error("{path}: the file is empty (expected a header line)")]
    EmptyFile { path: PathBuf },
    #[error("{path}, line 1: column {position} repeats the name {column:?}")]
    DuplicateColumn {
        path: PathBuf,
        column: String,
        position: usize,
    },
    #[error("{path}: no data rows after the header")]
    NoRows { path: PathBuf },
    #[error(
        "{path}: no input or output column: expected u1, u2, ... and y1, y2, ... (or choose \
         them with --inputs and --outputs); the file has {available}"
    )]
    NoSignalColumns { path: PathBuf, available: String },
    #[error(
        "{path}: no output column: expected y1, y2, ... (or choose them with --outputs); the \
         file has {available}"
    )]
    NoOutputColumn { path: PathBuf, available: String },
    #[error("{path}, line {line}: expected {expected} fields as in the header, found {found}")]
    Ragged {
        path: PathBuf,
        line: u64,
        expected: usize,
        found: usize,
    },
    #[error("{path}, line {line}, column {column}: cannot read {value:?} as a number")]
    NotANumber {
        path: PathBuf,
        line: u64,
        column: String,
        value: String,
    },
    #[error("{path}, line {line}, column {column}: {value} is not allowed in {role} columns")]
    NotAllowed {
        path: PathBuf,
        line: u64,
        column: String,
        value: String,
        role: &'static str,
    },
    #[error("{path}: no column named {column:?} (columns are: {available})")]
    UnknownColumn {
        path: PathBuf,
        column: String,
        available: String,
    },
    #[error("{path}: {message}")]
    Csv { path: PathBuf, message: String },
    #[error("{path}, line {line}, column {column}: invalid {what} JSON: {message}")]
    Json {
        path: PathBuf,
        what: &'static str,
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{path}: {source}")]
    Model { path: PathBuf, source: KalmanError },
    /// A model file's entry that parses but does not fit the model (e.g. its stored
    /// detrend has the wrong number of signals).
    #[error("{path}: {message}")]
    ModelEntry { path: PathBuf, message: String },
    #[error("{context}: {source}")]
    Kalman {
        context: String,
        source: KalmanError,
    },
    /// A nonlinear model file that cannot be used (its line and column are in the
    /// message).
    #[error("{0}")]
    ModelFile(#[from] sysid::modelfile::ModelFileError),
    /// Ctrl-C stopped a run; what it had was written.
    #[error("interrupted (Ctrl-C) after iteration {iteration}: wrote the result so far ({})", written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))]
    Interrupted {
        /// The last iteration completed.
        iteration: usize,
        /// The files written.
        written: Vec<PathBuf>,
    },
    #[error("unknown system {name:?} (known: {known})")]
    UnknownSystem { name: String, known: String },
    /// A fit setting the method that runs does not read, or one out of its range,
    /// named by its flag.
    #[error("{}", .0.describe(flag))]
    Setting(#[from] sysid::em::SettingError),
    #[error("{option}: {message}")]
    BadOption {
        option: &'static str,
        message: String,
    },
    /// Exact EM lowered the likelihood: a failure of the computation, not of the
    /// input (the better model was written).
    #[error("fit: {0}")]
    LikelihoodDecreased(String),
    /// EM failed mid-run; the last good model and the trace so far were written.
    #[error("fit: {message}")]
    FitFailedMidRun {
        /// What failed, and what was kept.
        message: String,
        /// Whether the failure is the input's (exit 2) rather than the computation's.
        input: bool,
    },
    #[error("{0}")]
    Subspace(#[from] sysid::subspace::SubspaceError),
    #[error("{0}")]
    Em(#[from] sysid::em::linear::LinearEmError),
    #[error("{context}: {source}")]
    Smc {
        context: String,
        source: sysid::smc::SmcError,
    },
    #[error("{context}: {source}")]
    AffineEm {
        context: String,
        source: sysid::em::affine::AffineEmError,
    },
    #[error("{context}: {source}")]
    GradientEm {
        context: String,
        source: sysid::em::gradient::GradientEmError,
    },
    #[error("{context}: {source}")]
    Pmcmc {
        context: String,
        source: sysid::pmcmc::PmcmcError,
    },
    #[error("the data have {found} {what} columns but the model has {expected}")]
    ColumnCount {
        what: &'static str,
        found: usize,
        expected: usize,
    },
}

/// Exit code of bad input (data, model files, options): 2.
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code of a failure while running (I/O, numerical breakdown): 1.
pub const EXIT_FAILURE: u8 = 1;
/// Exit code after Ctrl-C (128 + SIGINT), with the result so far written.
pub const EXIT_INTERRUPTED: u8 = 130;

impl CliError {
    /// [`EXIT_BAD_INPUT`] when the user's data, model file or options are at fault,
    /// else [`EXIT_FAILURE`].
    pub fn exit_code(&self) -> u8 {
        if matches!(self, CliError::Interrupted { .. }) {
            return EXIT_INTERRUPTED;
        }
        use sysid::em::affine::AffineEmError;
        use sysid::em::linear::LinearEmError;
        use sysid::smc::SmcError;
        use sysid::subspace::SubspaceError;
        let smc_input = |e: &SmcError| {
            matches!(
                e,
                SmcError::InvalidOption { .. }
                    | SmcError::DimensionMismatch { .. }
                    | SmcError::NonFiniteData { .. }
            )
        };
        let bad_input = match self {
            // an input file that cannot be read is the user's input; an output that
            // cannot be written (a full disk, a missing folder) is a failure
            CliError::Input { .. } => true,
            CliError::Io { .. } | CliError::LikelihoodDecreased(_) => false,
            CliError::FitFailedMidRun { input, .. } => *input,
            CliError::FitFailedAtStart { .. } => true,
            // the data or the model is at fault, not the computation
            CliError::Kalman { source, .. } => matches!(
                source,
                KalmanError::NonFiniteData { .. }
                    | KalmanError::Overflow { .. }
                    | KalmanError::Dimension { .. }
                    | KalmanError::EmptyRecord { .. }
                    | KalmanError::LengthMismatch { .. }
                    | KalmanError::Matrix(_)
                    | KalmanError::InitialCovarianceTooLarge { .. }
                    | KalmanError::DiffuseNotIdentified { .. }
            ),
            CliError::Plot(e) => !matches!(
                e,
                sysid_plot::PlotError::Output(sysid_output::OutputError::Io { .. })
                    | sysid_plot::PlotError::Draw { .. }
            ),
            CliError::Subspace(e) => !matches!(e, SubspaceError::Numerical(_)),
            CliError::Em(e) => match e {
                LinearEmError::Kalman(
                    KalmanError::InitialCovarianceTooLarge { .. }
                    | KalmanError::DiffuseNotIdentified { .. },
                ) => true,
                LinearEmError::Kalman(_) | LinearEmError::Linalg(_) => false,
                _ => true,
            },
            CliError::Smc { source, .. } => smc_input(source),
            CliError::AffineEm { source, .. } => match source {
                AffineEmError::Smc(e) => smc_input(e),
                AffineEmError::InvalidParams(_)
                | AffineEmError::Unsupported(_)
                | AffineEmError::NoSteps { .. } => true,
                _ => false,
            },
            CliError::GradientEm { source, .. } => {
                use sysid::em::gradient::GradientEmError;
                match source {
                    GradientEmError::Smc(e) => smc_input(e),
                    GradientEmError::InvalidParams(_) | GradientEmError::InvalidOption(_) => true,
                    _ => false,
                }
            }
            CliError::Pmcmc { source, .. } => {
                use sysid::pmcmc::PmcmcError;
                match source {
                    PmcmcError::Smc { source, .. } => smc_input(source),
                    PmcmcError::ParameterStep { .. } => false,
                    _ => true,
                }
            }
            _ => true,
        };
        if bad_input {
            EXIT_BAD_INPUT
        } else {
            EXIT_FAILURE
        }
    }
}

impl From<sysid_output::OutputError> for CliError {
    fn from(e: sysid_output::OutputError) -> CliError {
        match e {
            sysid_output::OutputError::Io { path, source } => CliError::Io { path, source },
            sysid_output::OutputError::WouldOverwrite { path } => CliError::WouldOverwrite { path },
            other => CliError::Output(other),
        }
    }
}

impl From<sysid_plot::PlotError> for CliError {
    fn from(e: sysid_plot::PlotError) -> CliError {
        match e {
            sysid_plot::PlotError::Output(e) => CliError::from(e),
            other => CliError::Plot(other),
        }
    }
}

/// The command line's flag of a library setting: `max_iter` is `--max-iter`.
pub fn flag(setting: &str) -> String {
    format!("--{}", setting.replace('_', "-"))
}
