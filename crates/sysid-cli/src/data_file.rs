//! Reading data CSV: the whole file into a record ([`read_data`]), or row by row in
//! blocks ([`DataReader`]) for records longer than memory should hold.

use crate::error::CliError;
use nalgebra::DMatrix;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use sysid::kalman::Record;

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

/// The time labels of a record's rows: the time column's entries as written, or row
/// numbers. Stored as one string and offsets (a `String` per row took 56 bytes).
#[derive(Debug, Clone)]
pub enum Labels {
    /// Row numbers `first, first + 1, ...` (a file without a time column).
    Rows { first: usize, len: usize },
    /// The entries, concatenated; `ends[k]` is where entry `k` ends.
    Text { text: String, ends: Vec<usize> },
}

impl Default for Labels {
    fn default() -> Self {
        Labels::Text {
            text: String::new(),
            ends: Vec::new(),
        }
    }
}

impl Labels {
    /// Row `k`'s label as written.
    pub fn get(&self, k: usize) -> std::borrow::Cow<'_, str> {
        match self {
            Labels::Rows { first, .. } => (first + k).to_string().into(),
            Labels::Text { text, ends } => {
                let start = if k == 0 { 0 } else { ends[k - 1] };
                text[start..ends[k]].into()
            }
        }
    }

    fn push(&mut self, label: &str) {
        if let Labels::Text { text, ends } = self {
            text.push_str(label);
            ends.push(text.len());
        }
    }

    /// The labels of rows `from..from + len`.
    pub fn range(&self, from: usize, len: usize) -> Labels {
        match self {
            Labels::Rows { first, .. } => Labels::Rows {
                first: first + from,
                len,
            },
            Labels::Text { .. } => {
                let mut out = Labels::default();
                for k in from..from + len {
                    out.push(&self.get(k));
                }
                out
            }
        }
    }

    /// Row `k`'s label as a CSV field (quoted if it holds a comma or a quote).
    pub fn field(&self, k: usize) -> String {
        let label = self.get(k);
        if label.contains([',', '"', ';', '\t']) {
            format!("\"{}\"", label.replace('"', "\"\""))
        } else {
            label.into_owned()
        }
    }
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
    pub labels: Labels,
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
        self.labels.field(t)
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

/// A CSV reader over any source.
type CsvReader = csv::Reader<Box<dyn Read>>;

/// A CSV reader over `reader` with the delimiter of its first line, and the checked
/// header (not empty, no duplicate name, a byte-order mark removed).
fn open_csv(
    reader: impl Read + 'static,
    path: &Path,
) -> Result<(CsvReader, Vec<String>), CliError> {
    let mut buffered = BufReader::new(reader);
    let mut first_line = Vec::new();
    buffered
        .read_until(b'\n', &mut first_line)
        .map_err(|source| CliError::Input {
            path: path.to_path_buf(),
            source,
        })?;
    let delimiter = sniff_delimiter(&String::from_utf8_lossy(&first_line));
    let source: Box<dyn Read> = Box::new(std::io::Cursor::new(first_line).chain(buffered));
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(delimiter)
        .trim(csv::Trim::All)
        .from_reader(source);
    let mut first = csv::StringRecord::new();
    let empty = || CliError::EmptyFile {
        path: path.to_path_buf(),
    };
    if !reader.read_record(&mut first).map_err(csv_error(path))? {
        return Err(empty());
    }
    let mut header: Vec<String> = first.iter().map(str::to_string).collect();
    // a byte-order mark (spreadsheet exports) is not part of the first name
    if let Some(first) = header.first_mut() {
        *first = first.trim_start_matches('\u{feff}').trim().to_string();
    }
    if header.iter().all(String::is_empty) {
        return Err(empty());
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
    Ok((reader, header))
}

fn csv_error(path: &Path) -> impl Fn(csv::Error) -> CliError + '_ {
    move |e| CliError::Csv {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Reads the next non-blank row into `row` (false at the end); refuses a row whose
/// length differs from the header's.
fn next_row(
    reader: &mut CsvReader,
    row: &mut csv::StringRecord,
    columns: usize,
    path: &Path,
) -> Result<bool, CliError> {
    loop {
        if !reader.read_record(row).map_err(csv_error(path))? {
            return Ok(false);
        }
        if row.len() == 1 && row[0].is_empty() {
            continue; // blank line
        }
        if row.len() != columns {
            return Err(CliError::Ragged {
                path: path.to_path_buf(),
                line: row.position().map_or(0, |p| p.line()),
                expected: columns,
                found: row.len(),
            });
        }
        return Ok(true);
    }
}

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
    reader: impl Read + 'static,
    path: &Path,
) -> Result<(Vec<String>, Vec<NumberedRow>), CliError> {
    let (mut reader, header) = open_csv(reader, path)?;
    let mut rows = Vec::new();
    let mut row = csv::StringRecord::new();
    while next_row(&mut reader, &mut row, header.len(), path)? {
        rows.push((row.position().map_or(0, |p| p.line()), row.clone()));
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

/// Rows of a data file: inputs and outputs column-major (one column per row), the
/// labels, and the numeric times (NaN for a label that is not a number).
#[derive(Debug, Clone, Default)]
pub struct Rows {
    pub u: Vec<f64>,
    pub y: Vec<f64>,
    pub labels: Labels,
    pub times: Vec<f64>,
}

impl Rows {
    /// Forgets the rows, keeping the buffers.
    pub fn clear(&mut self) {
        self.u.clear();
        self.y.clear();
        self.times.clear();
        self.labels = match self.labels {
            Labels::Rows { first, len } => Labels::Rows {
                first: first + len,
                len: 0,
            },
            Labels::Text { .. } => Labels::default(),
        };
    }

    /// The rows as a record of `m` inputs and `p` outputs.
    pub fn record(&self, m: usize, p: usize) -> Record {
        let steps = self.times.len();
        Record::new(
            DMatrix::from_column_slice(m, steps, &self.u),
            DMatrix::from_column_slice(p, steps, &self.y),
        )
    }
}

/// A data file read row by row: the header and the column choice are checked on
/// [`open`](Self::open), the rows parsed block by block by [`read`](Self::read) with
/// the checks of [`read_data`].
pub struct DataReader {
    path: PathBuf,
    reader: CsvReader,
    row: csv::StringRecord,
    header: Vec<String>,
    input_cols: Vec<usize>,
    output_cols: Vec<usize>,
    time_col: Option<usize>,
    /// the last row's line, numeric time and label, while every time so far is a number
    last_time: Option<(f64, String)>,
    numeric_time: bool,
    rows: usize,
}

impl DataReader {
    /// Opens `path` and checks its header against `choice`.
    pub fn open(path: &Path, choice: &ColumnChoice) -> Result<Self, CliError> {
        let file = File::open(path).map_err(|source| CliError::Input {
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(file, path, choice)
    }

    /// [`open`](Self::open) on the bytes of `reader`; errors name `path`.
    pub fn new(
        reader: impl Read + 'static,
        path: &Path,
        choice: &ColumnChoice,
    ) -> Result<Self, CliError> {
        let (reader, header) = open_csv(reader, path)?;
        let input_cols = select(path, &header, &choice.inputs, 'u')?;
        let output_cols = match &choice.outputs {
            Some(names)
                if choice.outputs_if_present && names.iter().any(|n| !header.contains(n)) =>
            {
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
        Ok(DataReader {
            path: path.to_path_buf(),
            reader,
            row: csv::StringRecord::new(),
            header,
            input_cols,
            output_cols,
            time_col,
            last_time: None,
            numeric_time: true,
            rows: 0,
        })
    }

    /// The chosen input columns' names.
    pub fn input_names(&self) -> Vec<String> {
        self.input_cols
            .iter()
            .map(|&c| self.header[c].clone())
            .collect()
    }

    /// The chosen output columns' names.
    pub fn output_names(&self) -> Vec<String> {
        self.output_cols
            .iter()
            .map(|&c| self.header[c].clone())
            .collect()
    }

    /// The rows read so far.
    pub fn rows_read(&self) -> usize {
        self.rows
    }

    /// The bytes of the file read so far (for a progress bar over its size).
    pub fn bytes_read(&self) -> u64 {
        self.reader.position().byte()
    }

    /// Whether the file has a time column whose entries, so far, are all numbers.
    pub fn numeric_time(&self) -> bool {
        self.time_col.is_some() && self.numeric_time
    }

    /// Empty rows to read into, labelled as this file's.
    pub fn empty_rows(&self) -> Rows {
        Rows {
            labels: match self.time_col {
                None => Labels::Rows {
                    first: self.rows + 1,
                    len: 0,
                },
                Some(_) => Labels::default(),
            },
            ..Rows::default()
        }
    }

    /// Appends up to `max` rows to `rows`; returns how many (0 at the end of the file).
    pub fn read(&mut self, rows: &mut Rows, max: usize) -> Result<usize, CliError> {
        let mut count = 0;
        while count < max
            && next_row(
                &mut self.reader,
                &mut self.row,
                self.header.len(),
                &self.path,
            )?
        {
            self.parse_row(rows)?;
            count += 1;
        }
        Ok(count)
    }

    fn parse_row(&mut self, rows: &mut Rows) -> Result<(), CliError> {
        let line = self.row.position().map_or(0, |p| p.line());
        let (path, header, row) = (&self.path, &self.header, &self.row);
        let number = |col: usize, role: &'static str, allow_missing: bool| {
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
        for &c in &self.input_cols {
            rows.u.push(number(c, "input", false)?);
        }
        for &c in &self.output_cols {
            rows.y.push(number(c, "output", true)?);
        }
        self.rows += 1;
        let Some(c) = self.time_col else {
            if let Labels::Rows { len, .. } = &mut rows.labels {
                *len += 1;
            }
            rows.times.push(self.rows as f64);
            return Ok(());
        };
        let label = &row[c];
        rows.labels.push(label);
        let time = label.parse::<f64>().ok().filter(|v| v.is_finite());
        rows.times.push(time.unwrap_or(f64::NAN));
        match time {
            None => self.numeric_time = false,
            Some(time) if self.numeric_time => {
                // a numeric time that does not increase is a sorting or merging mistake
                if let Some((before, before_label)) = &self.last_time
                    && time <= *before
                {
                    return Err(CliError::Csv {
                        path: path.to_path_buf(),
                        message: format!(
                            "line {line}, column {}: time {label} does not increase (the row \
                             before has {before_label}); sort the rows",
                            header[c],
                        ),
                    });
                }
                self.last_time = Some((time, label.to_string()));
            }
            Some(_) => {}
        }
        Ok(())
    }
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
    reader: impl Read + 'static,
    path: &Path,
    choice: &ColumnChoice,
) -> Result<DataFile, CliError> {
    let mut reader = DataReader::new(reader, path, choice)?;
    let mut rows = reader.empty_rows();
    let steps = reader.read(&mut rows, usize::MAX)?;
    if steps == 0 {
        return Err(CliError::NoRows {
            path: path.to_path_buf(),
        });
    }
    // a numeric time column gives the times (and perhaps the sample time); any other is
    // kept as labels, with the row numbers as times
    let (m, p) = (reader.input_cols.len(), reader.output_cols.len());
    let record = rows.record(m, p);
    let (time, sample_time) = if reader.numeric_time() {
        let dt = even_spacing(&rows.times);
        (std::mem::take(&mut rows.times), dt)
    } else {
        ((1..=steps).map(|t| t as f64).collect(), None)
    };
    Ok(DataFile {
        record,
        labels: rows.labels,
        sample_time,
        columns: reader.header.clone(),
        input_names: reader.input_names(),
        output_names: reader.output_names(),
        time,
        trend: None,
    })
}
