//! `sysid tf`: a model's transfer functions: poles, and per channel the zeros, the
//! static gain and the polynomials.

use crate::error::CliError;
use crate::files::read_model_file;
use nalgebra::Complex;
use std::path::PathBuf;

/// Options of `sysid tf`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Model file (JSON, see docs/model-format.md).
    #[arg(long)]
    pub model: PathBuf,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}

fn complex_json(z: &Complex<f64>) -> serde_json::Value {
    serde_json::json!([z.re, z.im])
}

fn complex_text(z: &Complex<f64>) -> String {
    if z.im.abs() <= 1e-12 * z.norm().max(1.0) {
        format!("{:.6}", z.re)
    } else {
        format!("{:.6}{:+.6}i", z.re, z.im)
    }
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let stored = read_model_file(&o.model)?;
    let model = stored.model;
    if model.m() == 0 {
        return Err(CliError::BadOption {
            option: "--model",
            message: format!(
                "{} has no inputs: it has poles ({}) but no transfer function",
                o.model.display(),
                model
                    .poles()
                    .iter()
                    .map(complex_text)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    }
    let meta = stored.metadata.unwrap_or_default();
    let name = |names: &Vec<String>, k: usize, prefix: char| {
        names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("{prefix}{}", k + 1))
    };
    let poles = model.poles();
    let radius = poles.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let mut channels = Vec::new();
    let mut text = format!(
        "poles ({}, spectral radius {radius:.6}{}): {}",
        model.n(),
        if radius < 1.0 {
            ", stable"
        } else {
            ", UNSTABLE"
        },
        poles
            .iter()
            .map(complex_text)
            .collect::<Vec<_>>()
            .join(", ")
    );
    for i in 0..model.p() {
        for j in 0..model.m() {
            let tf = model
                .transfer_function(i, j)
                .expect("i < p and j < m by the loops");
            let (input, output) = (name(&meta.inputs, j, 'u'), name(&meta.outputs, i, 'y'));
            text += &format!(
                "\n{input} -> {output}: static gain {}; zeros {}",
                tf.gain
                    .map_or("infinite (a pole at 1)".to_string(), |g| format!("{g:.6}")),
                if tf.zeros.is_empty() {
                    "none".to_string()
                } else {
                    tf.zeros
                        .iter()
                        .map(complex_text)
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            );
            channels.push(serde_json::json!({
                "input": input, "output": output, "gain": tf.gain,
                "zeros": tf.zeros.iter().map(complex_json).collect::<Vec<_>>(),
                "numerator": tf.numerator, "denominator": tf.denominator,
            }));
        }
    }
    crate::report(
        o.json,
        serde_json::json!({
            "command": "tf", "model": o.model, "order": model.n(),
            "poles": poles.iter().map(complex_json).collect::<Vec<_>>(),
            "spectral_radius": radius, "channels": channels,
        }),
        || text,
    );
    Ok(())
}
