use super::{in_data, model_and_data};
use crate::DataArgs;
use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use std::path::Path;
use sysid::kalman::KalmanWorkspace;

pub fn run(
    model_path: &Path,
    data: &DataArgs,
    out: &Path,
    force: bool,
    json: bool,
) -> Result<(), CliError> {
    let (model, file) = model_and_data(model_path, data)?;
    let mut ws = KalmanWorkspace::new();
    let sm = ws
        .smooth(&model, &file.record)
        .map_err(in_data(&data.data))?;
    let n = model.n();
    let mut w = create_output(out, force)?;
    let io = |source| CliError::Io {
        path: out.to_path_buf(),
        source,
    };
    let mut header = vec!["t".to_string()];
    header.extend((1..=n).map(|i| format!("x{i}")));
    header.extend((1..=n).map(|i| format!("x{i}_sd")));
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for k in 0..sm.len() {
        let p = sm.covariance(k);
        let mut row = vec![fmt(file.time[k])];
        row.extend(sm.mean(k).iter().map(|&v| fmt(v)));
        row.extend((0..n).map(|i| fmt(p[(i, i)].max(0.0).sqrt())));
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.flush().map_err(io)?;
    if json {
        let s = serde_json::json!({
            "command": "smooth", "loglik": sm.loglik(), "steps": sm.len(), "states": n, "out": out,
        });
        crate::say(&s.to_string());
    } else {
        crate::say(&format!(
            "loglik {}; wrote smoothed states to {}",
            sm.loglik(),
            out.display()
        ));
    }
    Ok(())
}
