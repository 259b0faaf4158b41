//! Writing a model file: the canonical text of a spec (numbers with full round-trip
//! precision, expressions as parsed).

use crate::expr::{Expr, Node};
use crate::spec::{FORMAT, ModelSpec};
use std::fmt::Write;
use sysid_pmcmc::Support;

fn number(v: f64) -> String {
    // `{:?}` is the shortest text that reads back to the same bits, and always has a
    // '.' or an exponent (TOML then reads a float)
    format!("{v:?}")
}

fn string_list(names: &[String]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("{n:?}")).collect();
    format!("[{}]", quoted.join(", "))
}

fn expression(spec: &ModelSpec, e: &Expr) -> String {
    match e.node {
        Node::Num(v) => number(v),
        _ => format!("\"{}\"", e.display(&|v| spec.var_name(v))),
    }
}

fn prior_text(prior: &sysid_pmcmc::ScalarPrior) -> String {
    match toml::Value::try_from(prior) {
        Ok(toml::Value::Table(table)) => {
            let entries: Vec<String> = table
                .iter()
                .map(|(k, v)| match v {
                    toml::Value::Float(f) => format!("{k} = {}", number(*f)),
                    toml::Value::Integer(i) => format!("{k} = {i}"),
                    toml::Value::String(text) => format!("{k} = {text:?}"),
                    other => format!("{k} = {other:?}"),
                })
                .collect();
            format!("{{ {} }}", entries.join(", "))
        }
        _ => "{}".into(),
    }
}

/// The text of `spec`, with `metadata` (`key`, TOML value text) in `[metadata]`.
pub(crate) fn to_toml(spec: &ModelSpec, metadata: &[(String, String)]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# sysid model file (docs/model-format.md)");
    let _ = writeln!(s, "format = {FORMAT}");
    if let Some(name) = &spec.name {
        let _ = writeln!(s, "name = {name:?}");
    }
    let _ = writeln!(s, "states = {}", string_list(&spec.states));
    if !spec.inputs.is_empty() {
        let _ = writeln!(s, "inputs = {}", string_list(&spec.inputs));
    }
    let _ = writeln!(s, "outputs = {}", string_list(&spec.outputs));
    let _ = writeln!(s, "\n[parameters]");
    for p in &spec.parameters {
        let mut fields = vec![format!("value = {}", number(p.value))];
        if p.fixed {
            fields.push("fixed = true".into());
        }
        match p.support {
            Support::Real => {}
            Support::Positive => fields.push("min = 0.0".into()),
            Support::Interval(a, b) => {
                fields.push(format!("min = {}", number(a)));
                fields.push(format!("max = {}", number(b)));
            }
        }
        if let Some(prior) = &p.prior {
            fields.push(format!("prior = {}", prior_text(prior)));
        }
        let _ = writeln!(s, "{} = {{ {} }}", p.name, fields.join(", "));
    }
    let _ = writeln!(s, "\n[transition]");
    for (name, e) in spec.states.iter().zip(&spec.transition) {
        let _ = writeln!(s, "{name} = {}", expression(spec, e));
    }
    let _ = writeln!(s, "\n[observation]");
    for (name, e) in spec.outputs.iter().zip(&spec.observation) {
        let _ = writeln!(s, "{name} = {}", expression(spec, e));
    }
    let _ = writeln!(s, "\n[noise]");
    let variances = spec.process_noise.iter().chain(&spec.measurement_noise);
    for (name, e) in spec.states.iter().chain(&spec.outputs).zip(variances) {
        let _ = writeln!(s, "{name} = {}", expression(spec, e));
    }
    let _ = writeln!(s, "\n[initial]");
    for ((name, m), v) in spec
        .states
        .iter()
        .zip(&spec.initial_mean)
        .zip(&spec.initial_variance)
    {
        let _ = writeln!(
            s,
            "{name} = {{ mean = {}, variance = {} }}",
            expression(spec, m),
            expression(spec, v)
        );
    }
    if !metadata.is_empty() {
        let _ = writeln!(s, "\n[metadata]");
        for (k, v) in metadata {
            let _ = writeln!(s, "{k} = {v}");
        }
    }
    s
}
