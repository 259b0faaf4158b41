//! Entry points for the fuzz targets (`fuzz/`): the command line's parsers on arbitrary
//! input. Each returns the one-line error a user would see, and must never panic.

use std::path::Path;

/// Parses `bytes` as a data file (CSV, default columns) into a record.
pub fn parse_data_file(bytes: &[u8]) -> Result<(), String> {
    crate::files::parse_data(
        std::io::Cursor::new(bytes.to_vec()),
        Path::new("fuzz.csv"),
        &crate::files::ColumnChoice::default(),
    )
    .map(|_| ())
    .map_err(|e| e.to_string())
}

/// Parses `bytes` as a numeric table (what `sysid plot` reads).
pub fn parse_table(bytes: &[u8]) -> Result<(), String> {
    let (header, rows) =
        crate::files::parse_rows(std::io::Cursor::new(bytes.to_vec()), Path::new("fuzz.csv"))
            .map_err(|e| e.to_string())?;
    for (_, row) in rows {
        debug_assert_eq!(row.len(), header.len());
    }
    Ok(())
}

/// Parses and validates `text` as a model file (JSON).
pub fn parse_model_file(text: &str) -> Result<(), String> {
    crate::files::parse_model(text, Path::new("fuzz.json"))
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// Parses and checks `text` as a nonlinear model file (TOML); when it is valid,
/// simulates its model for 5 steps (inputs 0) and evaluates its densities there.
pub fn parse_nonlinear_model(text: &str) -> Result<(), String> {
    use sysid::smc::{ObservationDensity, TransitionDensity};
    let model = sysid::modelfile::ModelFile::parse(text, "fuzz.toml").map_err(|e| e.to_string())?;
    let smc = model.at(&model.free_values()).map_err(|e| e.reason)?;
    let inputs = vec![0.0; 5 * smc.input_dim()];
    let (states, outputs) = smc.simulate(5, &inputs, 1).map_err(|e| e.reason)?;
    let (n, p, m) = (smc.spec().states.len(), smc.output_dim(), smc.input_dim());
    let u = vec![0.0; m];
    let _ = smc.log_observation(0, &states[..n], &u, &outputs[..p]);
    let _ = smc.log_transition(0, &states[..n], &u, &states[n..2 * n]);
    let _ = model.affine();
    let _ = model.gradient();
    Ok(())
}

/// Parses a command line (without running it).
pub fn parse_command_line(args: &[String]) -> Result<(), String> {
    use clap::Parser;
    let argv = std::iter::once("sysid".to_string()).chain(args.iter().cloned());
    crate::Cli::try_parse_from(argv)
        .map(|_| ())
        .map_err(|e| e.to_string())
}
