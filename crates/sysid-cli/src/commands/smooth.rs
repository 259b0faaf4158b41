//! `sysid filter` and `sysid smooth`: the Kalman filter's or the RTS smoother's state
//! estimates, in memory bounded for long records. The filter reads the data file block
//! by block and writes each block's rows as it goes (memory independent of the
//! record's length); the smoother keeps the record and one mean and standard deviation
//! per state and step, and smooths by checkpoints (`KalmanWorkspace::smooth_in_blocks`).

use super::{check_counts, check_range, in_data, parse_initial, parse_range};
use crate::StatesArgs;
use crate::data_file::{DataReader, Labels, Rows};
use crate::error::CliError;
use crate::files::{Output, create_output, fmt, read_model_file};
use std::io::Write;
use sysid::kalman::{
    BLOCK_STEPS, BlockFilter, FilterOutput, InitialState, KalmanWorkspace, stationary_input_window,
};

/// Which state estimates `sysid filter` and `sysid smooth` write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pass {
    /// `E[x_t | y_1..t]` (square-root Kalman filter).
    Filter,
    /// `E[x_t | y_1..T]` (RTS smoother).
    Smooth,
}

/// The most steps the first block of a streamed record holds (the stationary initial
/// state averages the record's first inputs over the system's memory).
const MAX_FIRST_BLOCK: usize = 1 << 20;

pub fn run(a: &StatesArgs, pass: Pass) -> Result<(), CliError> {
    crate::files::check_outputs(std::iter::once(a.out.as_path()), a.force)?;
    let (n, steps, loglik, warnings, diffuse) = match pass {
        Pass::Filter => filter(a)?,
        Pass::Smooth => smooth(a)?,
    };
    let (command, what) = match pass {
        Pass::Filter => ("filter", "filtered"),
        Pass::Smooth => ("smooth", "smoothed"),
    };
    for w in &warnings {
        crate::warn(w);
    }
    crate::report(
        a.json,
        serde_json::json!({
            "command": command, "loglik": loglik, "steps": steps, "states": n, "out": a.out,
            "diffuse_directions": diffuse, "warnings": warnings,
        }),
        || {
            format!(
                "loglik {loglik}; wrote {what} states to {}",
                a.out.display()
            )
        },
    );
    Ok(())
}

/// (states, steps, log-likelihood, warnings, diffuse directions) of a pass.
type Summary = (usize, usize, f64, Vec<String>, usize);

/// The header of the states file: `t, x1.., x1_sd..`.
fn write_header(
    w: &mut Output,
    n: usize,
    io: &impl Fn(std::io::Error) -> CliError,
) -> Result<(), CliError> {
    let mut header = vec!["t".to_string()];
    header.extend((1..=n).map(|i| format!("x{i}")));
    header.extend((1..=n).map(|i| format!("x{i}_sd")));
    writeln!(w, "{}", header.join(",")).map_err(io)
}

/// One row of the states file.
fn write_row(
    w: &mut Output,
    label: &str,
    mean: &[f64],
    sd: &[f64],
    line: &mut String,
) -> std::io::Result<()> {
    line.clear();
    line.push_str(label);
    for &v in mean.iter().chain(sd) {
        line.push(',');
        line.push_str(&fmt(v));
    }
    line.push('\n');
    w.write_all(line.as_bytes())
}

/// The filter, streamed: the data file is read block by block and each block's rows
/// written before the next is read.
fn filter(a: &StatesArgs) -> Result<Summary, CliError> {
    let source = &a.source;
    let path = source.data_path();
    let stored = read_model_file(&source.model)?;
    let data = &source.data;
    data.sample_time()?;
    let mut reader = DataReader::open(path, &data.choice(stored.metadata.as_ref(), false))?;
    let (m, p) = (stored.model.m(), stored.model.p());
    check_counts(
        (reader.input_names().len(), reader.output_names().len()),
        (m, p),
    )?;
    let initial = match parse_initial(&source.initial)? {
        InitialState::Given => stored.initial,
        chosen => chosen,
    };
    let (start, end) = match data.range.as_deref() {
        Some(range) => parse_range(range)?,
        None => (1, None),
    };
    if start == 0 || end.is_some_and(|end| end < start) {
        let mut rows = reader.empty_rows();
        let total = count_rows(&mut reader, &mut rows)?;
        check_range(start, end.unwrap_or(total), total)?;
    }
    // rows before the range are read (and checked) but not filtered
    let mut rows = reader.empty_rows();
    let mut skipped = 0;
    while skipped + 1 < start {
        rows.clear();
        match reader.read(&mut rows, (start - 1 - skipped).min(BLOCK_STEPS))? {
            0 => break,
            read => skipped += read,
        }
    }
    // the first block holds the inputs that a stationary initial state averages
    let mut blocks = Blocks {
        reader: &mut reader,
        trend: stored.trend.as_ref(),
        left: end.map(|end| end + 1 - start),
        times_by_row: None,
        path,
    };
    let first = stationary_input_window(&stored.model).clamp(BLOCK_STEPS, MAX_FIRST_BLOCK);
    let Some(record) = blocks.next(&mut rows, first, (m, p))? else {
        let total = skipped + count_rows(blocks.reader, &mut rows)?;
        check_range(start, end.unwrap_or(total), total)?;
        return Err(CliError::NoRows {
            path: path.to_path_buf(),
        });
    };
    let model = initial
        .apply_to_record(&stored.model, &record)
        .map_err(|e| CliError::Model {
            path: source.model.clone(),
            source: e,
        })?;
    let mut w = create_output(&a.out, a.force)?;
    let io = |source| CliError::Io {
        path: a.out.clone(),
        source,
    };
    let n = model.n();
    write_header(&mut w, n, &io)?;
    let mut filter = BlockFilter::new(&model);
    let mut warnings = Vec::new();
    let mut line = String::new();
    let mut record = Some(record);
    // a bar over the file's bytes: the rows are not counted before they are read
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    let progress = crate::progress::Progress::bytes(size, "filter", a.json);
    while let Some(block) = record {
        let first = filter.steps() == 0;
        let out = filter.push(&block).map_err(in_data(path))?;
        if first && out.diffuse_steps() > 0 {
            warnings.push(format!(
                "the diffuse initial state is not yet determined by the data in the first \
                 {} step(s): some of their filtered states have an infinite standard \
                 deviation (written as inf)",
                out.diffuse_steps()
            ));
        }
        write_filtered(&mut w, out, &rows.labels, &mut line).map_err(io)?;
        progress.set_position(blocks.reader.bytes_read());
        record = blocks.next(&mut rows, BLOCK_STEPS, (m, p))?;
    }
    progress.finish();
    if let Some(end) = end {
        let total = skipped + filter.steps() + count_rows(blocks.reader, &mut rows)?;
        check_range(start, end, total)?;
    }
    w.commit()?;
    Ok((
        n,
        filter.steps(),
        filter.loglik(),
        warnings,
        model.diffuse().ncols(),
    ))
}

/// Reads (and checks) the rest of a file, block by block; returns how many rows.
fn count_rows(reader: &mut DataReader, rows: &mut Rows) -> Result<usize, CliError> {
    let mut total = 0;
    loop {
        rows.clear();
        match reader.read(rows, BLOCK_STEPS)? {
            0 => return Ok(total),
            read => total += read,
        }
    }
}

/// The blocks of a streamed record: `left` rows more (all with `None`), a stored
/// linear trend removed at the rows' times.
struct Blocks<'r> {
    reader: &'r mut DataReader,
    trend: Option<&'r super::detrend::Trend>,
    left: Option<usize>,
    /// whether the trend is taken at the row numbers (a time column that is not
    /// numeric), decided by the first block
    times_by_row: Option<bool>,
    path: &'r std::path::Path,
}

impl Blocks<'_> {
    /// The next block of at most `max` rows into `rows`, as a record of `(m, p)`
    /// columns; `None` at the end.
    fn next(
        &mut self,
        rows: &mut Rows,
        max: usize,
        (m, p): (usize, usize),
    ) -> Result<Option<sysid::kalman::Record>, CliError> {
        let wanted = self.left.unwrap_or(usize::MAX).min(max);
        rows.clear();
        let first_row = self.reader.rows_read() + 1;
        if wanted == 0 || self.reader.read(rows, wanted)? == 0 {
            return Ok(None);
        }
        let mut record = rows.record(m, p);
        if let Some(left) = &mut self.left {
            *left -= record.len();
        }
        if let Some(trend) = self.trend {
            let numeric = self.reader.numeric_time();
            let by_row = *self.times_by_row.get_or_insert(!numeric);
            if !by_row && !numeric {
                return Err(CliError::Csv {
                    path: self.path.to_path_buf(),
                    message: "the time column mixes numbers and text, so the linear trend \
                              stored with the model cannot be removed at its times"
                        .into(),
                });
            }
            if by_row {
                let times: Vec<f64> = (first_row..first_row + record.len())
                    .map(|r| r as f64)
                    .collect();
                trend.remove_from(&mut record, &times);
            } else {
                trend.remove_from(&mut record, &rows.times);
            }
        }
        Ok(Some(record))
    }
}

/// A block's filtered rows; a state the data do not determine yet has an infinite
/// standard deviation (written as inf).
fn write_filtered(
    w: &mut Output,
    out: &FilterOutput,
    labels: &Labels,
    line: &mut String,
) -> std::io::Result<()> {
    let mut sd = Vec::new();
    for k in 0..out.len() {
        let p = out.filtered_covariance(k);
        let undetermined = out.filtered_undetermined(k);
        sd.clear();
        sd.extend((0..p.nrows()).map(|i| match undetermined[i] {
            true => f64::INFINITY,
            false => p[(i, i)].max(0.0).sqrt(),
        }));
        write_row(
            w,
            &labels.field(k),
            out.filtered_mean(k).as_slice(),
            &sd,
            line,
        )?;
    }
    Ok(())
}

/// The smoother: by checkpoints (memory: the record and a mean and standard deviation
/// per state and step), or, for a diffuse initial state, over the whole record.
fn smooth(a: &StatesArgs) -> Result<Summary, CliError> {
    let spinner = crate::progress::Progress::spinner("smooth", a.json);
    let (model, file) = a.source.load()?;
    let path = a.source.data_path();
    let (n, t_len) = (model.n(), file.record.len());
    let bytes_per_step = if model.is_diffuse() {
        // the whole-record passes: seven n x n arrays and the means per step
        8.0 * (7 * n * n + 6 * n) as f64
    } else {
        8.0 * (2 * n) as f64
    };
    crate::resources::check_memory(
        "--data",
        &format!("the smoothed states of {t_len} steps of a {n}-state model"),
        bytes_per_step * t_len as f64,
    )?;
    let mut moments = vec![0.0; 2 * n * t_len];
    let loglik = if model.is_diffuse() {
        let mut ws = KalmanWorkspace::new();
        let sm = ws.smooth(&model, &file.record).map_err(in_data(path))?;
        for k in 0..t_len {
            let row = &mut moments[2 * n * k..2 * n * (k + 1)];
            row[..n].copy_from_slice(sm.mean(k).as_slice());
            let p = sm.covariance(k);
            for i in 0..n {
                row[n + i] = p[(i, i)].max(0.0).sqrt();
            }
        }
        sm.loglik()
    } else {
        KalmanWorkspace::new()
            .smooth_in_blocks(&model, &file.record, |k, mean, cov| {
                let row = &mut moments[2 * n * k..2 * n * (k + 1)];
                row[..n].copy_from_slice(mean);
                for i in 0..n {
                    row[n + i] = cov[i * n + i].max(0.0).sqrt();
                }
            })
            .map_err(in_data(path))?
    };
    spinner.finish();
    let mut w = create_output(&a.out, a.force)?;
    let io = |source| CliError::Io {
        path: a.out.clone(),
        source,
    };
    write_header(&mut w, n, &io)?;
    let mut line = String::new();
    for (k, row) in moments.chunks_exact(2 * n).enumerate() {
        write_row(&mut w, &file.label(k), &row[..n], &row[n..], &mut line).map_err(io)?;
    }
    w.commit()?;
    Ok((n, t_len, loglik, Vec::new(), model.diffuse().ncols()))
}
