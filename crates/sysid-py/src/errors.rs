//! Errors as Python exceptions: the classes of `sysid._errors` (`SysidError`,
//! `ModelFileError` with `.line` and `.column`, `DataError` and `OptionError`, both
//! also `ValueError`), built from a GIL-free [`Failure`] that a worker thread returns.

use pyo3::prelude::*;

/// A failure of a computation, made without the GIL, raised with it.
#[derive(Debug)]
pub(crate) enum Failure {
    /// Bad data: shapes, values, columns (`DataError`, a `ValueError`).
    Data(String),
    /// A bad option (`OptionError`, a `ValueError`), named as the Python keyword.
    Option { name: String, message: String },
    /// A keyword the method that runs does not read (`OptionError`); the message names
    /// it.
    Refused { name: String, message: String },
    /// A model file that cannot be read (`ModelFileError`).
    ModelFile {
        message: String,
        origin: String,
        line: usize,
        column: usize,
    },
    /// Anything else the library reports (`SysidError`).
    Sysid(String),
}

impl Failure {
    pub fn option(name: &str, message: impl Into<String>) -> Failure {
        Failure::Option {
            name: name.into(),
            message: message.into(),
        }
    }

    /// A library setting refused or out of range, named as the Python keyword (the
    /// library's setting names are the keywords).
    pub fn setting(e: &sysid::em::SettingError) -> Failure {
        match e {
            sysid::em::SettingError::Invalid { setting, reason } => {
                Failure::option(setting, reason.clone())
            }
            other => Failure::Refused {
                name: other.setting().to_string(),
                message: other.describe(str::to_string),
            },
        }
    }

    pub fn data(message: impl Into<String>) -> Failure {
        Failure::Data(message.into())
    }

    pub fn sysid(message: impl std::fmt::Display) -> Failure {
        Failure::Sysid(message.to_string())
    }

    pub fn model_file(e: &sysid::modelfile::ModelFileError) -> Failure {
        Failure::ModelFile {
            message: e.to_string(),
            origin: e.origin.clone(),
            line: e.line,
            column: e.column,
        }
    }

    fn raise(self, py: Python<'_>) -> PyResult<PyErr> {
        let errors = py.import("sysid._errors")?;
        let error = match self {
            Failure::Data(message) => errors.getattr("DataError")?.call1((message,))?,
            Failure::Option { name, message } => errors
                .getattr("OptionError")?
                .call1((format!("{name}: {message}"), name))?,
            Failure::Refused { name, message } => {
                errors.getattr("OptionError")?.call1((message, name))?
            }
            Failure::ModelFile {
                message,
                origin,
                line,
                column,
            } => errors
                .getattr("ModelFileError")?
                .call1((message, origin, line, column))?,
            Failure::Sysid(message) => errors.getattr("SysidError")?.call1((message,))?,
        };
        Ok(PyErr::from_value(error))
    }
}

impl From<Failure> for PyErr {
    fn from(failure: Failure) -> PyErr {
        Python::attach(|py| failure.raise(py).unwrap_or_else(|e| e))
    }
}
