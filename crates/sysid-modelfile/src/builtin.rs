//! The built-in systems as model files: `--system NAME` is a shortcut for them.

use crate::{ModelFile, ModelFileError};

/// The shipped model files: name and text.
pub const BUILTIN: [(&str, &str); 3] = [
    ("nlbench", include_str!("../models/nlbench.toml")),
    ("lgss", include_str!("../models/lgss.toml")),
    ("pendulum", include_str!("../models/pendulum.toml")),
];

/// The names of the built-in model files.
pub fn names() -> Vec<&'static str> {
    BUILTIN.iter().map(|(n, _)| *n).collect()
}

/// The text of the built-in model `name`.
pub fn text(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// The built-in model `name`, parsed.
///
/// # Errors
/// Never for a shipped file (a test parses every one); `None` for an unknown name.
pub fn model(name: &str) -> Option<Result<ModelFile, ModelFileError>> {
    text(name).map(|t| ModelFile::parse(t, &format!("built-in {name}")))
}
