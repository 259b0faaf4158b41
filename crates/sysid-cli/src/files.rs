//! Reading data CSV and model JSON, and writing outputs without clobbering files.

pub use crate::data_file::{
    ColumnChoice, DataFile, parse_data, parse_rows, read_columns, read_data, read_rows,
};
use crate::error::CliError;
use std::io::Write;
use std::path::Path;
use sysid::kalman::{LinearGaussianModel, Metadata, ModelSpec, Record};
use sysid_output::PendingFile;

/// Where an output goes: a file written atomically, or standard output (`-`).
pub enum Output {
    /// A temporary file renamed into place by [`Output::commit`].
    File(PendingFile),
    /// Standard output, buffered.
    Stdout(std::io::BufWriter<std::io::Stdout>),
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Output::File(f) => f.write(buf),
            Output::Stdout(w) => w.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Output::File(f) => f.flush(),
            Output::Stdout(w) => w.flush(),
        }
    }
}

impl Output {
    /// Moves the file into place, or flushes standard output.
    pub fn commit(self) -> Result<(), CliError> {
        match self {
            Output::File(f) => Ok(f.commit()?),
            Output::Stdout(mut w) => w.flush().map_err(|source| CliError::Io {
                path: "-".into(),
                source,
            }),
        }
    }
}

/// Whether a path means standard output.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// Starts writing `path` atomically (a temporary file renamed into place by
/// [`Output::commit`]; an error part-way leaves nothing behind); refuses to replace
/// an existing file unless `force`. `-` is standard output: the command's summary then
/// goes to stderr ([`crate::claim_stdout`]).
pub fn create_output(path: &Path, force: bool) -> Result<Output, CliError> {
    if is_stdout(path) {
        crate::claim_stdout();
        return Ok(Output::Stdout(std::io::BufWriter::new(std::io::stdout())));
    }
    Ok(Output::File(PendingFile::create(path, force)?))
}

/// [`refuse_existing`] for outputs whose folder the command does not create: a folder
/// that does not exist is refused too, before any work.
pub fn check_outputs<'a>(
    paths: impl IntoIterator<Item = &'a Path>,
    force: bool,
) -> Result<(), CliError> {
    let paths: Vec<&Path> = paths.into_iter().collect();
    for path in &paths {
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(folder) = folder.filter(|f| !f.is_dir()) {
            return Err(CliError::NoFolder {
                path: path.to_path_buf(),
                folder: folder.to_path_buf(),
            });
        }
    }
    refuse_existing(paths, force)
}

/// Checks a command's outputs before any work: one file given for two outputs, an
/// existing path that is not a regular file (a directory, device, fifo or symbolic
/// link such as `/dev/stdout`), and, without `force`, an existing file are refused, so a refused command writes nothing (the final write checks
/// again, atomically, through [`create_output`]).
pub fn refuse_existing<'a>(
    paths: impl IntoIterator<Item = &'a Path>,
    force: bool,
) -> Result<(), CliError> {
    let paths: Vec<&Path> = paths.into_iter().collect();
    let identities: Vec<std::path::PathBuf> = paths.iter().map(|p| identity(p)).collect();
    for (i, id) in identities.iter().enumerate() {
        if identities[..i].contains(id) {
            return Err(CliError::SameOutput {
                path: paths[i].to_path_buf(),
            });
        }
    }
    for path in paths {
        if is_stdout(path) {
            crate::claim_stdout();
            continue;
        }
        if !sysid_output::is_replaceable(path) {
            return Err(CliError::Output(sysid_output::OutputError::NotAFile {
                path: path.to_path_buf(),
            }));
        }
        if !force && path.exists() {
            return Err(CliError::WouldOverwrite {
                path: path.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// The file a path names, for telling two spellings of one file apart: the canonical
/// form of its directory (when it exists) joined with its name.
fn identity(path: &Path) -> std::path::PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    match (absolute.parent(), absolute.file_name()) {
        (Some(dir), Some(name)) => std::fs::canonicalize(dir)
            .map(|d| d.join(name))
            .unwrap_or(absolute),
        _ => absolute,
    }
}

/// Writes `contents` atomically through [`create_output`].
pub fn write_output(path: &Path, force: bool, contents: &str) -> Result<(), CliError> {
    let mut w = create_output(path, force)?;
    w.write_all(contents.as_bytes())
        .map_err(|source| CliError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    w.commit()
}

/// The error of a JSON file `path` (a `what` file) that does not parse: its line,
/// column and serde's message without serde's own position suffix.
pub fn json_error(path: &Path, what: &'static str, e: &serde_json::Error) -> CliError {
    CliError::Json {
        path: path.to_path_buf(),
        what,
        line: e.line(),
        column: e.column(),
        message: e
            .to_string()
            .split(" at line")
            .next()
            .unwrap_or_default()
            .to_string(),
    }
}

/// Reads and validates a model file (JSON, `docs/model-format.md`).
pub fn read_model(path: &Path) -> Result<LinearGaussianModel, CliError> {
    Ok(read_model_file(path)?.model)
}

/// A model file's contents.
pub struct ModelFile {
    pub model: LinearGaussianModel,
    pub metadata: Option<Metadata>,
    /// How the file describes a record's initial state.
    pub initial: sysid::kalman::InitialState,
    /// The linear trend the model was fitted without (`--detrend linear`), to remove
    /// from a record before running the model on it.
    pub trend: Option<crate::commands::detrend::Trend>,
}

/// Reads and validates a model file, with its metadata if it has any.
pub fn read_model_file(path: &Path) -> Result<ModelFile, CliError> {
    let text = std::fs::read_to_string(path).map_err(|source| CliError::Input {
        path: path.to_path_buf(),
        source,
    })?;
    let spec: ModelSpec =
        serde_json::from_str(&text).map_err(|e| not_a_linear_model(path, &text, &e))?;
    let model = spec.build().map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })?;
    let trend = crate::commands::detrend::Trend::stored(
        spec.metadata.as_ref().and_then(|m| m.detrend.as_ref()),
        model.m(),
        model.p(),
    )
    .map_err(|e| CliError::ModelEntry {
        path: path.to_path_buf(),
        message: format!("metadata: {e}"),
    })?;
    Ok(ModelFile {
        model,
        metadata: spec.metadata,
        initial: spec.initial,
        trend,
    })
}

/// The error for a file that is not a linear model file: what it is instead, when it
/// is an estimate another command wrote or a nonlinear model file, with the command
/// that reads it; else the JSON error.
fn not_a_linear_model(path: &Path, text: &str, error: &serde_json::Error) -> CliError {
    let json = serde_json::from_str::<serde_json::Value>(text).ok();
    let system = json
        .as_ref()
        .and_then(|v| v.get("system"))
        .and_then(|s| s.as_str());
    let message = match system {
        Some("wiener") => {
            "a `sysid fit wiener` estimate (JSON), not a model file: the blind Wiener \
             system's parameters and their magnitude error, which no command runs as a model"
                .to_string()
        }
        Some(system) => format!(
            "a `sysid fit {system}` estimate (JSON), not a linear model file: fit again with \
             --out FILE.toml for a model file, which pf, psmooth, pmmh, pgas and simulate \
             --model read"
        ),
        None if json.is_none() && text.contains("[parameters]") => {
            "a nonlinear model file (TOML) without the .toml extension: rename it to .toml"
                .to_string()
        }
        None => return json_error(path, "model", error),
    };
    CliError::ModelEntry {
        path: path.to_path_buf(),
        message,
    }
}

/// Parses and validates the text of a model file; errors name `path`.
pub fn parse_model(text: &str, path: &Path) -> Result<LinearGaussianModel, CliError> {
    let spec: ModelSpec = serde_json::from_str(text).map_err(|e| json_error(path, "model", &e))?;
    spec.build().map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes a model file (one row of a matrix per line).
pub fn write_model(path: &Path, force: bool, spec: &ModelSpec) -> Result<(), CliError> {
    write_output(path, force, &spec.to_json())
}

/// FNV-1a (64 bits) over the bits of a record's inputs and outputs, in hexadecimal.
pub fn fingerprint(record: &Record) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for v in record.u.iter().chain(record.y.iter()) {
        for byte in v.to_bits().to_le_bytes() {
            hash ^= u64::from(byte);
            hash = hash.wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("{hash:016x}")
}

/// The metadata of a model fitted on `file` (`path`) by this command line.
pub fn metadata_of(file: &DataFile, path: &Path) -> Metadata {
    let command: Vec<String> = std::env::args().collect();
    Metadata {
        inputs: file.input_names.clone(),
        outputs: file.output_names.clone(),
        command: Some(command.join(" ")),
        data: Some(path.display().to_string()),
        data_fingerprint: Some(fingerprint(&file.record)),
        sample_time: file.sample_time,
        ..Metadata::default()
    }
}

/// Formats a float for CSV and messages: the shortest representation that reads back
/// to the same bits, in scientific notation outside `[1e-5, 1e16)` (Rust's `{}` wrote
/// 1e-300 with 300 digits and 1.8e150 as a 151-digit integer), `0` for both zeros,
/// `NaN` for missing.
pub fn fmt(v: f64) -> String {
    if v.is_nan() {
        "NaN".to_string()
    } else if v == 0.0 {
        "0".to_string()
    } else if v.is_infinite() || (1e-5..1e16).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Formats a float for a person to read: four significant digits (an estimate's
/// standard error is rarely known better than to two).
pub fn short(v: f64) -> String {
    if !v.is_finite() || v == 0.0 {
        return fmt(v);
    }
    let magnitude = v.abs().log10().floor();
    if (-3.0..6.0).contains(&magnitude) {
        let decimals = (3.0 - magnitude).max(0.0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

#[cfg(test)]
mod format_tests {
    use super::{fmt, short};

    /// Four significant digits, in plain notation where that is short.
    #[test]
    fn short_numbers_have_four_significant_digits() {
        assert_eq!(short(0.5114633136309759), "0.5115");
        assert_eq!(short(0.013350165779812961), "0.01335");
        assert_eq!(short(1234.5678), "1235");
        assert_eq!(short(-2.5e-7), "-2.500e-7");
        assert_eq!(short(0.0), "0");
    }

    /// Every value reads back to the same bits, and the extremes stay short.
    #[test]
    fn numbers_are_short_and_round_trip() {
        for (v, text) in [
            (1e-300, "1e-300"),
            (1.8e150, "1.8e150"),
            (-0.0, "0"),
            (0.1 + 0.2, "0.30000000000000004"),
            (12345.5, "12345.5"),
            (-2.5e-7, "-2.5e-7"),
            (f64::INFINITY, "inf"),
            (f64::NAN, "NaN"),
        ] {
            assert_eq!(fmt(v), text);
        }
        let mut x = 1.2345e-320_f64;
        while x < 1e300 {
            for v in [x, -x, x * std::f64::consts::PI] {
                let back: f64 = fmt(v).parse().unwrap();
                assert_eq!(back.to_bits(), v.to_bits(), "{v:e}");
                assert!(fmt(v).len() <= 24, "{}", fmt(v));
            }
            x *= 7.77;
        }
    }
}
