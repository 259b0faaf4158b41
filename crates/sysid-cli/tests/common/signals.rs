//! The library side of the face tests: a CSV read without the command line's reader.

use nalgebra::DMatrix;
use std::path::{Path, PathBuf};
use sysid::em::linear::Signals;
use sysid::kalman::Record;

/// A file of `crates/sysid-cli/tests/data`.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// A CSV with a header `t,u1..,y1..` (or without `t`) as `Signals`, rows `from..to`
/// (0-based, end excluded).
pub fn read_csv(path: &Path, rows: Option<(usize, usize)>) -> Signals {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let table: Vec<Vec<f64>> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let (from, to) = rows.unwrap_or((0, table.len()));
    let table = &table[from..to];
    let columns = |prefix: char| -> Vec<usize> {
        (0..header.len())
            .filter(|&j| header[j].starts_with(prefix))
            .collect()
    };
    let (u, y) = (columns('u'), columns('y'));
    let matrix =
        |cols: &[usize]| DMatrix::from_fn(cols.len(), table.len(), |i, t| table[t][cols[i]]);
    let time: Vec<f64> = match header.iter().position(|h| *h == "t") {
        Some(j) => table.iter().map(|row| row[j]).collect(),
        None => (from + 1..=to).map(|t| t as f64).collect(),
    };
    let names = |cols: &[usize]| cols.iter().map(|&j| header[j].to_string()).collect();
    Signals::new(Record::new(matrix(&u), matrix(&y)))
        .with_time(time)
        .unwrap()
        .with_names(names(&u), names(&y))
        .unwrap()
}
