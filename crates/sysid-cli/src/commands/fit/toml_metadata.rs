//! The `[metadata]` of a fitted model file.

use crate::files::fmt;

/// `key = value` lines for a model file's `[metadata]`: the scalar entries of
/// `summary` (numbers, strings, booleans; nested values are left out).
pub(super) fn metadata_lines(summary: &serde_json::Value) -> Vec<(String, String)> {
    let mut lines = vec![("fitted_by".to_string(), "\"sysid fit\"".to_string())];
    if let Some(map) = summary.as_object() {
        for (k, v) in map {
            let text = match v {
                serde_json::Value::Number(n) => n.as_f64().filter(|x| x.is_finite()).map(fmt),
                serde_json::Value::String(s) => Some(format!("{s:?}")),
                serde_json::Value::Bool(b) => Some(b.to_string()),
                _ => None,
            };
            if let Some(text) = text {
                lines.push((k.clone(), text));
            }
        }
    }
    lines
}
