//! Reading data CSV and model JSON, and writing outputs without clobbering files.

use crate::error::CliError;
use nalgebra::DMatrix;
use std::fs::File;
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
    let spec: ModelSpec = serde_json::from_str(&text).map_err(|e| json_error(path, "model", &e))?;
    let model = spec.build().map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })?;
    let trend = crate::commands::detrend::Trend::stored(
        spec.metadata.as_ref().and_then(|m| m.detrend.as_ref()),
        model.m(),
        model.p(),
    )
    .map_err(|message| CliError::ModelEntry {
        path: path.to_path_buf(),
        message: format!("metadata: {message}"),
    })?;
    Ok(ModelFile {
        model,
        metadata: spec.metadata,
        initial: spec.initial,
        trend,
    })
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

/// Which columns of a data file are inputs and outputs.
#[derive(Debug, Clone, Default)]
pub struct ColumnChoice {
    /// Input column names; `None` means every column whose name starts with `u`.
    pub inputs: Option<Vec<String>>,
    /// Output column names; `None` means every column whose name starts with `y`.
    pub outputs: Option<Vec<String>>,
    /// Named outputs that are not all in the file mean a record without outputs (an
    /// inputs-only file to simulate), instead of an error.
    pub outputs_if_present: bool,
}

/// A data file read into a record, with its time column if it has one.
#[derive(Debug, Clone)]
pub struct DataFile {
    pub record: Record,
    pub input_names: Vec<String>,
    pub output_names: Vec<String>,
    /// The time column's values (a column named `t`, `time` or `date`), or the row
    /// numbers 1..T when it has none or its entries are not numbers.
    pub time: Vec<f64>,
    /// The time column's entries as written (`1959Q1`, `2001-03`, `0.5`), carried to
    /// the outputs; the row numbers when there is no time column.
    pub labels: Vec<String>,
    /// The sampling interval read from a numeric, evenly spaced time column.
    pub sample_time: Option<f64>,
    /// Every column of the file, in order.
    pub columns: Vec<String>,
    /// A linear trend removed from the record (a model fitted with `--detrend linear`),
    /// added back to outputs by [`DataFile::restored`].
    pub trend: Option<crate::commands::detrend::Trend>,
}

impl DataFile {
    /// Outputs of the model of the detrended record in the file's units: the removed
    /// outputs' trend added back (unchanged when nothing was removed).
    pub fn restored(&self, outputs: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.trend {
            Some(trend) => outputs + trend.outputs_at(&self.time),
            None => outputs.clone(),
        }
    }

    /// The measured outputs in the file's units.
    pub fn measured(&self) -> DMatrix<f64> {
        self.restored(&self.record.y)
    }

    /// The times of `steps` rows after the last, at the file's sampling interval (its
    /// sample time, or the mean spacing of its times).
    pub fn times_after(&self, steps: usize) -> Vec<f64> {
        let last = self.time.last().copied().unwrap_or(0.0);
        let spacing = self.sample_time.unwrap_or_else(|| match self.time.len() {
            0 | 1 => 1.0,
            n => (last - self.time[0]) / (n - 1) as f64,
        });
        (1..=steps).map(|j| last + spacing * j as f64).collect()
    }

    /// Refuses a file without an output column (for commands that fit or score).
    pub fn require_outputs(&self, path: &Path) -> Result<(), CliError> {
        if self.output_names.is_empty() {
            return Err(CliError::NoOutputColumn {
                path: path.to_path_buf(),
                available: column_list(&self.columns),
            });
        }
        Ok(())
    }

    /// Row `t`'s time as written in the file, as a CSV field (quoted if it holds a
    /// comma or a quote).
    pub fn label(&self, t: usize) -> String {
        let label = &self.labels[t];
        if label.contains([',', '"', ';', '\t']) {
            format!("\"{}\"", label.replace('"', "\"\""))
        } else {
            label.clone()
        }
    }
}

/// The delimiter of a CSV file: the most frequent of comma, semicolon and tab in its
/// first line (outside double quotes); a comma when none occurs.
fn sniff_delimiter(first_line: &str) -> u8 {
    let mut counts = [(b',', 0usize), (b';', 0), (b'\t', 0)];
    let mut quoted = false;
    for c in first_line.bytes() {
        if c == b'"' {
            quoted = !quoted;
        } else if !quoted {
            for (d, n) in counts.iter_mut() {
                if c == *d {
                    *n += 1;
                }
            }
        }
    }
    counts
        .iter()
        .filter(|(_, n)| *n > 0)
        .max_by_key(|(_, n)| *n)
        .map_or(b',', |(d, _)| *d)
}

/// The sampling interval of evenly spaced times (to 1e-6 relative), if positive.
fn even_spacing(time: &[f64]) -> Option<f64> {
    let dt = time.get(1)? - time[0];
    let even = time
        .windows(2)
        .all(|w| ((w[1] - w[0]) - dt).abs() <= 1e-6 * dt.abs().max(f64::MIN_POSITIVE));
    (dt > 0.0 && even).then_some(dt)
}

fn is_missing(field: &str) -> bool {
    matches!(field, "" | "NaN" | "nan" | "NA" | "na")
}

fn select(
    path: &Path,
    header: &[String],
    chosen: &Option<Vec<String>>,
    prefix: char,
) -> Result<Vec<usize>, CliError> {
    match chosen {
        None => Ok((0..header.len())
            .filter(|&i| {
                let h = &header[i];
                h.starts_with(prefix) && h[1..].chars().all(|c| c.is_ascii_digit()) && h.len() > 1
            })
            .collect()),
        Some(names) => names
            .iter()
            .map(|name| {
                header
                    .iter()
                    .position(|h| h == name)
                    .ok_or_else(|| CliError::UnknownColumn {
                        path: path.to_path_buf(),
                        column: name.clone(),
                        available: column_list(header),
                    })
            })
            .collect(),
    }
}

/// A file's column names for a message: all of them up to [`LISTED_COLUMNS`], else the
/// first ones and the count (a message stays one readable line).
pub fn column_list(names: &[String]) -> String {
    if names.len() <= LISTED_COLUMNS {
        return names.join(", ");
    }
    format!(
        "{}, ... ({} columns)",
        names[..LISTED_COLUMNS].join(", "),
        names.len()
    )
}

/// The most column names a message lists.
const LISTED_COLUMNS: usize = 20;

/// A CSV row with its line number.
pub type NumberedRow = (u64, csv::StringRecord);

/// A CSV file's header and its non-blank rows with their line numbers (1-based, the
/// header is line 1); refuses an empty file and rows whose length differs from the
/// header's.
pub fn read_rows(path: &Path) -> Result<(Vec<String>, Vec<NumberedRow>), CliError> {
    let file = File::open(path).map_err(|source| CliError::Input {
        path: path.to_path_buf(),
        source,
    })?;
    parse_rows(file, path)
}

/// [`read_rows`] on the bytes of `reader`; errors name `path`.
pub fn parse_rows(
    file: impl std::io::Read,
    path: &Path,
) -> Result<(Vec<String>, Vec<NumberedRow>), CliError> {
    let mut bytes = Vec::new();
    let mut file = file;
    file.read_to_end(&mut bytes)
        .map_err(|source| CliError::Input {
            path: path.to_path_buf(),
            source,
        })?;
    let first_line = bytes.split(|&b| b == b'\n').next().unwrap_or(&[]);
    let delimiter = sniff_delimiter(&String::from_utf8_lossy(first_line));
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(delimiter)
        .trim(csv::Trim::All)
        .from_reader(bytes.as_slice());
    let csv_err = |e: csv::Error| CliError::Csv {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut records = reader.records();
    let header: Vec<String> = match records.next() {
        None => {
            return Err(CliError::EmptyFile {
                path: path.to_path_buf(),
            });
        }
        Some(r) => r.map_err(csv_err)?.iter().map(str::to_string).collect(),
    };
    // a byte-order mark (spreadsheet exports) is not part of the first name
    let mut header = header;
    if let Some(first) = header.first_mut() {
        *first = first.trim_start_matches('\u{feff}').trim().to_string();
    }
    if header.iter().all(String::is_empty) {
        return Err(CliError::EmptyFile {
            path: path.to_path_buf(),
        });
    }
    // one pass with a set (the pairwise search took 17.7 s on 100 000 columns)
    let mut seen = std::collections::HashSet::with_capacity(header.len());
    if let Some((i, name)) = header
        .iter()
        .enumerate()
        .find(|(_, h)| !seen.insert(h.as_str()))
    {
        return Err(CliError::DuplicateColumn {
            path: path.to_path_buf(),
            column: name.clone(),
            position: i + 1,
        });
    }
    let mut rows = Vec::new();
    for row in records {
        let row = row.map_err(csv_err)?;
        let line = row.position().map_or(0, |p| p.line());
        if row.len() == 1 && row[0].is_empty() {
            continue; // blank line
        }
        if row.len() != header.len() {
            return Err(CliError::Ragged {
                path: path.to_path_buf(),
                line,
                expected: header.len(),
                found: row.len(),
            });
        }
        rows.push((line, row));
    }
    Ok((header, rows))
}

/// A numeric CSV file (e.g. one written by sysid): the header and the columns, with
/// empty, `NaN` or `NA` cells as NaN; any other non-number is an error naming the line.
pub fn read_columns(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), CliError> {
    let (header, rows) = read_rows(path)?;
    if rows.is_empty() {
        return Err(CliError::NoRows {
            path: path.to_path_buf(),
        });
    }
    let mut columns = vec![Vec::with_capacity(rows.len()); header.len()];
    for (line, row) in &rows {
        for (c, field) in row.iter().enumerate() {
            let value = if is_missing(field) {
                f64::NAN
            } else {
                field.parse().map_err(|_| CliError::NotANumber {
                    path: path.to_path_buf(),
                    line: *line,
                    column: header[c].clone(),
                    value: field.to_string(),
                })?
            };
            columns[c].push(value);
        }
    }
    Ok((header, columns))
}

/// Reads a CSV data file with a header. Output cells that are empty, `NaN` or `NA` are
/// missing; input cells must be finite numbers. Errors name the file, the line
/// (1-based, the header is line 1) and the column.
pub fn read_data(path: &Path, choice: &ColumnChoice) -> Result<DataFile, CliError> {
    let file = File::open(path).map_err(|source| CliError::Input {
        path: path.to_path_buf(),
        source,
    })?;
    parse_data(file, path, choice)
}

/// [`read_data`] on the bytes of `reader`; errors name `path`.
pub fn parse_data(
    reader: impl std::io::Read,
    path: &Path,
    choice: &ColumnChoice,
) -> Result<DataFile, CliError> {
    let (header, rows) = parse_rows(reader, path)?;
    let input_cols = select(path, &header, &choice.inputs, 'u')?;
    let output_cols = match &choice.outputs {
        Some(names) if choice.outputs_if_present && names.iter().any(|n| !header.contains(n)) => {
            Vec::new()
        }
        _ => select(path, &header, &choice.outputs, 'y')?,
    };
    if input_cols.is_empty() && output_cols.is_empty() {
        return Err(CliError::NoSignalColumns {
            path: path.to_path_buf(),
            available: column_list(&header),
        });
    }
    let time_col = header
        .iter()
        .position(|h| matches!(h.to_ascii_lowercase().as_str(), "t" | "time" | "date"));
    // a column chosen twice, or as a signal and the time
    let chosen: Vec<usize> = input_cols.iter().chain(&output_cols).copied().collect();
    for (k, &c) in chosen.iter().enumerate() {
        let problem = if chosen[..k].contains(&c) {
            Some(if input_cols.contains(&c) && output_cols.contains(&c) {
                "is chosen as both an input and an output"
            } else {
                "is chosen twice"
            })
        } else if Some(c) == time_col {
            Some("is the time column, not a signal")
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(CliError::Csv {
                path: path.to_path_buf(),
                message: format!("column {} {problem} (--inputs/--outputs)", header[c]),
            });
        }
    }
    let (mut u, mut y, mut labels, mut lines) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (line, row) in rows {
        lines.push(line);
        let number =
            |col: usize, role: &'static str, allow_missing: bool| -> Result<f64, CliError> {
                let field = &row[col];
                if allow_missing && is_missing(field) {
                    return Ok(f64::NAN);
                }
                let value: f64 = field.parse().map_err(|_| CliError::NotANumber {
                    path: path.to_path_buf(),
                    line,
                    column: header[col].clone(),
                    value: field.to_string(),
                })?;
                if !value.is_finite() {
                    return Err(CliError::NotAllowed {
                        path: path.to_path_buf(),
                        line,
                        column: header[col].clone(),
                        value: field.to_string(),
                        role,
                    });
                }
                Ok(value)
            };
        for &c in &input_cols {
            u.push(number(c, "input", false)?);
        }
        for &c in &output_cols {
            y.push(number(c, "output", true)?);
        }
        if let Some(c) = time_col {
            labels.push(row[c].to_string());
        }
    }
    let steps = if output_cols.is_empty() {
        u.len() / input_cols.len().max(1)
    } else {
        y.len() / output_cols.len()
    };
    if steps == 0 {
        return Err(CliError::NoRows {
            path: path.to_path_buf(),
        });
    }
    // a numeric time column gives the times (and perhaps the sample time); any other is
    // kept as labels, with the row numbers as times
    let numeric: Option<Vec<f64>> = labels
        .iter()
        .map(|l| l.parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect();
    let (time, sample_time) = match numeric.filter(|v| !v.is_empty()) {
        Some(values) => {
            // a numeric time that does not increase is a sorting or merging mistake
            if let Some(k) = (1..values.len()).find(|&k| values[k] <= values[k - 1]) {
                return Err(CliError::Csv {
                    path: path.to_path_buf(),
                    message: format!(
                        "line {}, column {}: time {} does not increase (the row before has {}); \
                         sort the rows",
                        lines[k],
                        header[time_col.unwrap_or(0)],
                        labels[k],
                        labels[k - 1]
                    ),
                });
            }
            let dt = even_spacing(&values);
            (values, dt)
        }
        None => ((1..=steps).map(|t| t as f64).collect(), None),
    };
    if labels.is_empty() {
        labels = (1..=steps).map(|t| t.to_string()).collect();
    }
    let name = |cols: &[usize]| cols.iter().map(|&c| header[c].clone()).collect();
    Ok(DataFile {
        labels,
        sample_time,
        columns: header.clone(),
        record: Record::new(
            DMatrix::from_vec(input_cols.len(), steps, u),
            DMatrix::from_vec(output_cols.len(), steps, y),
        ),
        input_names: name(&input_cols),
        output_names: name(&output_cols),
        time,
        trend: None,
    })
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

#[cfg(test)]
mod format_tests {
    use super::fmt;

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
