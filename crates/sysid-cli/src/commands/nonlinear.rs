//! Nonlinear model files on the command line: `--model FILE.toml` and the built-in
//! systems shipped as model files (`--system NAME`).

use crate::error::CliError;
use std::path::Path;
use sysid::modelfile::{ModelFile, builtin};

/// Whether `path` names a nonlinear model file (`.toml`); other model files are the
/// linear Gaussian JSON of docs/model-format.md.
pub fn is_model_file(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
}

/// Reads and checks a nonlinear model file (a one-line error with line and column).
pub fn read(path: &Path) -> Result<ModelFile, CliError> {
    if let Err(source) = std::fs::metadata(path) {
        return Err(CliError::Input {
            path: path.to_path_buf(),
            source,
        });
    }
    Ok(ModelFile::read(path)?)
}

/// The built-in system `name` as a model file.
pub fn system(name: &str) -> Result<ModelFile, CliError> {
    match builtin::model(name) {
        Some(model) => Ok(model?),
        None => Err(CliError::UnknownSystem {
            name: name.into(),
            known: builtin::names().join(", "),
        }),
    }
}
