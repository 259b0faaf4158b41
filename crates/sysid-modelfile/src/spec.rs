//! The model file: its TOML schema, and every check that turns a text into a
//! [`ModelSpec`] (with errors that give the line and column).

use crate::expr::{BinOp, Expr, Function, Node, Var, parse};
use serde::Deserialize;
use std::collections::BTreeMap;
use sysid_pmcmc::{ScalarPrior, Support};
use toml::Spanned;

/// The format version this library reads and writes.
pub const FORMAT: i64 = 1;

/// A model file that cannot be used: where, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{origin}:{line}:{column}: {message}")]
pub struct ModelFileError {
    /// The file (or the name of a built-in model).
    pub origin: String,
    /// 1-based line.
    pub line: usize,
    /// 1-based column (in characters).
    pub column: usize,
    /// What is wrong, on one line.
    pub message: String,
}

/// A named parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Its name in the equations.
    pub name: String,
    /// The value (the start of an estimation, or the value of a fixed parameter).
    pub value: f64,
    /// Held at `value` by every estimator.
    pub fixed: bool,
    /// Where the parameter lives (from `min` and `max`).
    pub support: Support,
    /// The prior for Bayesian methods, if the file gives one.
    pub prior: Option<ScalarPrior>,
}

/// A checked model:
/// ```text
/// x_{t+1,i} = f_i(x_t, u_t, t; theta) + w_{t,i},   w_{t,i} ~ N(0, q_i(theta))
/// y_{t,j}   = g_j(x_t, u_t, t; theta) + e_{t,j},   e_{t,j} ~ N(0, r_j(theta))
/// x_{0,i}   ~ N(m_i(theta), p_i(theta))
/// ```
/// with every noise term independent. Expressions refer to parameters by their index
/// in [`parameters`](Self::parameters) (fixed ones included).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    /// The model's name (optional in the file).
    pub name: Option<String>,
    /// State names.
    pub states: Vec<String>,
    /// Input names (columns of the data file).
    pub inputs: Vec<String>,
    /// Output names (columns of the data file).
    pub outputs: Vec<String>,
    /// Parameters, in the order of the file.
    pub parameters: Vec<Parameter>,
    /// `f_i`, one per state.
    pub transition: Vec<Expr>,
    /// `g_j`, one per output.
    pub observation: Vec<Expr>,
    /// `q_i`, one per state.
    pub process_noise: Vec<Expr>,
    /// `r_j`, one per output.
    pub measurement_noise: Vec<Expr>,
    /// `m_i`, one per state.
    pub initial_mean: Vec<Expr>,
    /// `p_i`, one per state.
    pub initial_variance: Vec<Expr>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    format: Spanned<i64>,
    #[serde(default)]
    name: Option<String>,
    states: Spanned<Vec<Spanned<String>>>,
    #[serde(default)]
    inputs: Vec<Spanned<String>>,
    outputs: Spanned<Vec<Spanned<String>>>,
    #[serde(default)]
    parameters: BTreeMap<String, Spanned<toml::Value>>,
    transition: Spanned<BTreeMap<String, Spanned<toml::Value>>>,
    observation: Spanned<BTreeMap<String, Spanned<toml::Value>>>,
    noise: Spanned<BTreeMap<String, Spanned<toml::Value>>>,
    initial: Spanned<BTreeMap<String, Spanned<RawInitial>>>,
    /// Free-form information written by sysid (the fit that produced the file); read
    /// and ignored.
    #[serde(default)]
    #[allow(dead_code)]
    metadata: Option<toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInitial {
    mean: Spanned<toml::Value>,
    variance: Spanned<toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParameter {
    value: f64,
    #[serde(default)]
    fixed: bool,
    min: Option<f64>,
    max: Option<f64>,
    prior: Option<ScalarPrior>,
}

/// Names an expression may not use for a state, input, output or parameter.
const RESERVED: [&str; 3] = ["t", "inf", "nan"];

/// Maps byte offsets of the file to lines and columns.
struct Locator<'a> {
    origin: &'a str,
    text: &'a str,
}

impl Locator<'_> {
    fn error(&self, offset: usize, message: impl Into<String>) -> ModelFileError {
        let offset = offset.min(self.text.len());
        let before = &self.text[..offset];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |k| k + 1);
        ModelFileError {
            origin: self.origin.to_string(),
            line,
            column: self.text[line_start..offset].chars().count() + 1,
            message: message.into(),
        }
    }

    /// The offset of the first character inside the string literal at `start`.
    fn string_body(&self, start: usize) -> usize {
        let rest = &self.text[start.min(self.text.len())..];
        if rest.starts_with("\"\"\"") || rest.starts_with("'''") {
            let after = start + 3;
            // a newline right after the opening delimiter is not part of the string
            if self.text[after..].starts_with("\r\n") {
                after + 2
            } else if self.text[after..].starts_with('\n') {
                after + 1
            } else {
                after
            }
        } else {
            start + 1
        }
    }
}

/// An expression of the file: its text (or a number) and where it starts.
struct Source {
    expr: Expr,
    /// Offset of the expression's first character in the file.
    base: usize,
}

/// Where an expression sits, for messages and for what it may reference.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Role {
    Mean,
    Variance,
}

struct Names<'a> {
    states: &'a [String],
    inputs: &'a [String],
    parameters: &'a [String],
}

impl Names<'_> {
    fn resolve(&self, name: &str) -> Option<Var> {
        if name == "t" {
            return Some(Var::Time);
        }
        let find = |list: &[String]| list.iter().position(|n| n == name);
        find(self.states)
            .map(Var::State)
            .or_else(|| find(self.inputs).map(Var::Input))
            .or_else(|| find(self.parameters).map(Var::Param))
    }
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The support of `min`/`max`.
fn support_of(min: Option<f64>, max: Option<f64>) -> Result<Support, String> {
    match (min, max) {
        (None, None) => Ok(Support::Real),
        (Some(0.0), None) => Ok(Support::Positive),
        (Some(lo), Some(hi)) if lo.is_finite() && hi.is_finite() && lo < hi => {
            Ok(Support::Interval(lo, hi))
        }
        (Some(lo), Some(hi)) => Err(format!(
            "min = {lo} and max = {hi} do not make an interval (need finite min < max)"
        )),
        (Some(lo), None) => Err(format!(
            "min = {lo} without max: give both min and max, or only min = 0 (positive)"
        )),
        (None, Some(_)) => Err("max without min: give both min and max".into()),
    }
}

impl ModelSpec {
    /// Reads and checks a model file's text; `origin` names it in errors.
    ///
    /// # Errors
    /// The first problem found, with its line and column.
    pub fn parse(text: &str, origin: &str) -> Result<ModelSpec, ModelFileError> {
        let at = Locator { origin, text };
        let raw: RawFile = toml::from_str(text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            at.error(offset, e.message().trim().replace('\n', "; "))
        })?;
        if *raw.format.get_ref() != FORMAT {
            return Err(at.error(
                raw.format.span().start,
                format!(
                    "format {} is not known to this sysid (it reads format {FORMAT})",
                    raw.format.get_ref()
                ),
            ));
        }

        // names: valid, not reserved, unique across states, inputs, outputs, parameters
        let mut parameter_entries: Vec<(String, Spanned<toml::Value>)> =
            raw.parameters.into_iter().collect();
        parameter_entries.sort_by_key(|(_, v)| v.span().start);
        let mut seen: BTreeMap<String, &'static str> = BTreeMap::new();
        let mut check_name = |name: &str,
                              offset: usize,
                              kind: &'static str|
         -> Result<(), ModelFileError> {
            if !is_identifier(name) {
                return Err(at.error(
                    offset,
                    format!(
                        "{kind} name {name:?} is not a name (letters, digits and _, \
                             not starting with a digit)"
                    ),
                ));
            }
            if RESERVED.contains(&name) || Function::from_name(name).is_some() {
                return Err(at.error(
                    offset,
                    format!("{kind} name {name:?} is reserved (t is the time; functions)"),
                ));
            }
            if let Some(other) = seen.insert(name.to_string(), kind) {
                return Err(at.error(offset, format!("{name:?} is both a {other} and a {kind}")));
            }
            Ok(())
        };
        if raw.states.get_ref().is_empty() {
            return Err(at.error(raw.states.span().start, "states: give at least one state"));
        }
        if raw.outputs.get_ref().is_empty() {
            return Err(at.error(
                raw.outputs.span().start,
                "outputs: give at least one output",
            ));
        }
        for s in raw.states.get_ref() {
            check_name(s.get_ref(), s.span().start, "state")?;
        }
        for s in &raw.inputs {
            check_name(s.get_ref(), s.span().start, "input")?;
        }
        for s in raw.outputs.get_ref() {
            check_name(s.get_ref(), s.span().start, "output")?;
        }
        for (name, v) in &parameter_entries {
            check_name(name, v.span().start, "parameter")?;
        }
        let states: Vec<String> = raw
            .states
            .get_ref()
            .iter()
            .map(|s| s.get_ref().clone())
            .collect();
        let inputs: Vec<String> = raw.inputs.iter().map(|s| s.get_ref().clone()).collect();
        let outputs: Vec<String> = raw
            .outputs
            .get_ref()
            .iter()
            .map(|s| s.get_ref().clone())
            .collect();
        let parameter_names: Vec<String> =
            parameter_entries.iter().map(|(n, _)| n.clone()).collect();
        let names = Names {
            states: &states,
            inputs: &inputs,
            parameters: &parameter_names,
        };

        // parameters
        let mut parameters = Vec::new();
        for (name, value) in &parameter_entries {
            let offset = value.span().start;
            let p = match value.get_ref() {
                toml::Value::Integer(v) => Parameter {
                    name: name.clone(),
                    value: *v as f64,
                    fixed: true,
                    support: Support::Real,
                    prior: None,
                },
                toml::Value::Float(v) => Parameter {
                    name: name.clone(),
                    value: *v,
                    fixed: true,
                    support: Support::Real,
                    prior: None,
                },
                toml::Value::Table(_) => {
                    let raw: RawParameter =
                        value
                            .get_ref()
                            .clone()
                            .try_into()
                            .map_err(|e: toml::de::Error| {
                                at.error(
                                    offset,
                                    format!("parameter {name}: {}", e.message().trim()),
                                )
                            })?;
                    let support = support_of(raw.min, raw.max)
                        .map_err(|m| at.error(offset, format!("parameter {name}: {m}")))?;
                    Parameter {
                        name: name.clone(),
                        value: raw.value,
                        fixed: raw.fixed,
                        support,
                        prior: raw.prior,
                    }
                }
                other => {
                    return Err(at.error(
                        offset,
                        format!(
                            "parameter {name}: expected a number (fixed) or a table such as \
                             {{ value = 0.5, min = 0, max = 1 }}, found a {}",
                            other.type_str()
                        ),
                    ));
                }
            };
            if !p.value.is_finite() {
                return Err(at.error(offset, format!("parameter {name}: the value is not finite")));
            }
            if !p.fixed && !p.support.contains(p.value) {
                return Err(at.error(
                    offset,
                    format!(
                        "parameter {name}: the value {} is outside its bounds ({})",
                        p.value,
                        describe_support(p.support)
                    ),
                ));
            }
            if let Some(prior) = &p.prior {
                check_prior(prior, &p)
                    .map_err(|m| at.error(offset, format!("parameter {name}: {m}")))?;
            }
            parameters.push(p);
        }

        // the equations
        let expression = |value: &Spanned<toml::Value>,
                          role: Role,
                          what: &str|
         -> Result<Source, ModelFileError> {
            let offset = value.span().start;
            let source = match value.get_ref() {
                toml::Value::Integer(v) => Source {
                    expr: Expr::num(*v as f64),
                    base: offset,
                },
                toml::Value::Float(v) if v.is_finite() => Source {
                    expr: Expr::num(*v),
                    base: offset,
                },
                toml::Value::String(text) => {
                    let base = at.string_body(offset);
                    let expr = parse(text, &|n| names.resolve(n))
                        .map_err(|e| at.error(base + e.span.0, format!("{what}: {}", e.message)))?;
                    Source { expr, base }
                }
                other => {
                    return Err(at.error(
                        offset,
                        format!(
                            "{what}: expected an expression in quotes or a number, found a {}",
                            other.type_str()
                        ),
                    ));
                }
            };
            if role == Role::Variance {
                let state_or_input = |e: &Expr| {
                    matches!(e.node, Node::Var(Var::State(_) | Var::Input(_) | Var::Time))
                };
                if source.expr.any(&state_or_input) {
                    let bad = find(&source.expr, &state_or_input);
                    return Err(at.error(
                        source.base + bad.span.0,
                        format!(
                            "{what}: may depend only on parameters and numbers, not on states, \
                             inputs or t"
                        ),
                    ));
                }
            }
            Ok(source)
        };
        let by_name =
            |table: &Spanned<BTreeMap<String, Spanned<toml::Value>>>,
             section: &str,
             wanted: &[(&String, &str)]|
             -> Result<Vec<Spanned<toml::Value>>, ModelFileError> {
                for (key, value) in table.get_ref() {
                    if !wanted.iter().any(|(n, _)| *n == key) {
                        let kinds: Vec<&str> = wanted.iter().map(|(_, k)| *k).collect();
                        let mut kinds = kinds;
                        kinds.dedup();
                        return Err(at.error(
                        value.span().start,
                        format!(
                            "[{section}] has an entry for {key:?}, which is not a {} (known: {})",
                            kinds.join(" or "),
                            wanted.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", ")
                        ),
                    ));
                    }
                }
                wanted
                    .iter()
                    .map(|(name, kind)| {
                        table.get_ref().get(*name).cloned().ok_or_else(|| {
                            at.error(
                                table.span().start,
                                format!("[{section}] has no entry for the {kind} {name}"),
                            )
                        })
                    })
                    .collect()
            };
        let state_keys: Vec<(&String, &str)> = states.iter().map(|s| (s, "state")).collect();
        let output_keys: Vec<(&String, &str)> = outputs.iter().map(|s| (s, "output")).collect();
        let noise_keys: Vec<(&String, &str)> =
            state_keys.iter().chain(&output_keys).copied().collect();
        let transition_values = by_name(&raw.transition, "transition", &state_keys)?;
        let observation_values = by_name(&raw.observation, "observation", &output_keys)?;
        let noise_values = by_name(&raw.noise, "noise", &noise_keys)?;

        let mut sources: Vec<(Source, Role, String)> = Vec::new();
        for (name, v) in states.iter().zip(&transition_values) {
            let what = format!("transition of {name}");
            sources.push((expression(v, Role::Mean, &what)?, Role::Mean, what));
        }
        for (name, v) in outputs.iter().zip(&observation_values) {
            let what = format!("observation of {name}");
            sources.push((expression(v, Role::Mean, &what)?, Role::Mean, what));
        }
        for (name, v) in states.iter().chain(&outputs).zip(&noise_values) {
            let what = format!("noise variance of {name}");
            sources.push((expression(v, Role::Variance, &what)?, Role::Variance, what));
        }
        for (key, value) in raw.initial.get_ref() {
            if !states.contains(key) {
                return Err(at.error(
                    value.span().start,
                    format!(
                        "[initial] has an entry for {key:?}, which is not a state (known: {})",
                        states.join(", ")
                    ),
                ));
            }
        }
        let mut initial_sources = Vec::new();
        for name in &states {
            let Some(entry) = raw.initial.get_ref().get(name) else {
                return Err(at.error(
                    raw.initial.span().start,
                    format!(
                        "[initial] has no entry for the state {name} \
                         (e.g. {name} = {{ mean = 0, variance = 1 }})"
                    ),
                ));
            };
            let e = entry.get_ref();
            let mean = format!("initial mean of {name}");
            let var = format!("initial variance of {name}");
            initial_sources.push((
                expression(&e.mean, Role::Variance, &mean)?,
                Role::Variance,
                mean,
            ));
            initial_sources.push((
                expression(&e.variance, Role::Variance, &var)?,
                Role::Variance,
                var,
            ));
        }
        sources.extend(initial_sources);

        // every parameter is used; noise-variance parameters are positive
        for (k, p) in parameters.iter_mut().enumerate() {
            let used = sources.iter().any(|(s, _, _)| s.expr.uses(Var::Param(k)));
            if !used {
                let offset = parameter_entries[k].1.span().start;
                return Err(at.error(
                    offset,
                    format!(
                        "parameter {} appears in no equation (remove it, or use it)",
                        p.name
                    ),
                ));
            }
            let is_variance = |(s, _, what): &(Source, Role, String)| {
                what.contains("variance") && s.expr.node == Node::Var(Var::Param(k))
            };
            if !p.fixed && p.support == Support::Real && sources.iter().any(is_variance) {
                // a variance is positive: no bounds given means (0, inf)
                p.support = Support::Positive;
                if p.value <= 0.0 {
                    let offset = parameter_entries[k].1.span().start;
                    return Err(at.error(
                        offset,
                        format!(
                            "parameter {} is a variance; its value must be positive",
                            p.name
                        ),
                    ));
                }
            }
        }

        // divisions by something that may be zero
        for (s, _, what) in &sources {
            if let Some(bad) = find_opt(&s.expr, &|e| divides_by_possible_zero(e, &parameters)) {
                let Node::Bin(BinOp::Div, _, den) = &bad.node else {
                    continue;
                };
                let message = match den.node {
                    Node::Var(Var::Param(k)) if !parameters[k].fixed => format!(
                        "{what}: division by the parameter {}, which may be 0 within its \
                         bounds ({}): give bounds that exclude 0 (e.g. min = 0)",
                        parameters[k].name,
                        describe_support(parameters[k].support)
                    ),
                    _ => format!("{what}: division by zero"),
                };
                return Err(at.error(s.base + den.span.0, message));
            }
        }

        let mut iter = sources.into_iter().map(|(s, _, _)| s);
        let mut take = |k: usize| -> Vec<Source> { iter.by_ref().take(k).collect() };
        let (n, p) = (states.len(), outputs.len());
        let transition = take(n);
        let observation = take(p);
        let process_noise = take(n);
        let measurement_noise = take(p);
        let initial = take(2 * n);
        let values: Vec<f64> = parameters.iter().map(|p| p.value).collect();

        // values at the start: variances positive, every expression finite
        let scalar = |s: &Source, what: &str| -> Result<f64, ModelFileError> {
            let lookup = |v: Var| match v {
                Var::Param(k) => values[k],
                _ => f64::NAN,
            };
            check_finite(&at, s, what, &lookup, "at the parameters' values")?;
            Ok(s.expr.eval(&lookup))
        };
        let mut start_state = Vec::new();
        for (k, name) in states.iter().enumerate() {
            let mean = scalar(&initial[2 * k], &format!("initial mean of {name}"))?;
            let var = scalar(&initial[2 * k + 1], &format!("initial variance of {name}"))?;
            if var < 0.0 {
                return Err(at.error(
                    initial[2 * k + 1].base,
                    format!("initial variance of {name} is {var} at the parameters' values"),
                ));
            }
            start_state.push(mean);
        }
        for (s, name) in process_noise
            .iter()
            .chain(&measurement_noise)
            .zip(states.iter().chain(&outputs))
        {
            let v = scalar(s, &format!("noise variance of {name}"))?;
            if v <= 0.0 {
                return Err(at.error(
                    s.base,
                    format!(
                        "noise variance of {name} is {v} at the parameters' values; it must be \
                         positive"
                    ),
                ));
            }
        }
        let at_start = |v: Var| match v {
            Var::State(i) => start_state[i],
            Var::Input(_) | Var::Time => 0.0,
            Var::Param(k) => values[k],
        };
        let where_ = "at the start (states at their initial means, inputs 0, t = 0)";
        for (s, name) in transition.iter().zip(&states) {
            check_finite(&at, s, &format!("transition of {name}"), &at_start, where_)?;
        }
        for (s, name) in observation.iter().zip(&outputs) {
            check_finite(&at, s, &format!("observation of {name}"), &at_start, where_)?;
        }

        let exprs = |v: Vec<Source>| v.into_iter().map(|s| s.expr).collect::<Vec<_>>();
        let (initial_mean, initial_variance): (Vec<Expr>, Vec<Expr>) = initial
            .chunks(2)
            .map(|c| (c[0].expr.clone(), c[1].expr.clone()))
            .unzip();
        Ok(ModelSpec {
            name: raw.name,
            states,
            inputs,
            outputs,
            parameters,
            transition: exprs(transition),
            observation: exprs(observation),
            process_noise: exprs(process_noise),
            measurement_noise: exprs(measurement_noise),
            initial_mean,
            initial_variance,
        })
    }

    /// The name of a variable in the equations.
    pub fn var_name(&self, v: Var) -> String {
        match v {
            Var::State(i) => self.states[i].clone(),
            Var::Input(i) => self.inputs[i].clone(),
            Var::Time => "t".into(),
            Var::Param(k) => self.parameters[k].name.clone(),
        }
    }

    /// Indices of the parameters that estimators move.
    pub fn free(&self) -> Vec<usize> {
        (0..self.parameters.len())
            .filter(|&k| !self.parameters[k].fixed)
            .collect()
    }
}

/// `(0, inf)`, `(a, b)` or `unbounded`.
pub(crate) fn describe_support(s: Support) -> String {
    match s {
        Support::Real => "unbounded".into(),
        Support::Positive => "min = 0".into(),
        Support::Interval(a, b) => format!("min = {a}, max = {b}"),
    }
}

/// A division whose denominator is a number 0, a fixed parameter at 0, or a free
/// parameter whose bounds contain 0.
fn divides_by_possible_zero(e: &Expr, parameters: &[Parameter]) -> bool {
    let Node::Bin(BinOp::Div, _, den) = &e.node else {
        return false;
    };
    match den.node {
        Node::Num(v) => v == 0.0,
        Node::Var(Var::Param(k)) => {
            let p = &parameters[k];
            if p.fixed {
                p.value == 0.0
            } else {
                match p.support {
                    Support::Real => true,
                    Support::Positive => false,
                    Support::Interval(a, b) => a < 0.0 && b > 0.0 || a == 0.0 && b == 0.0,
                }
            }
        }
        _ => false,
    }
}

/// The first sub-expression (pre-order) satisfying `pred`.
fn find<'e>(e: &'e Expr, pred: &impl Fn(&Expr) -> bool) -> &'e Expr {
    find_opt(e, pred).unwrap_or(e)
}

fn find_opt<'e>(e: &'e Expr, pred: &impl Fn(&Expr) -> bool) -> Option<&'e Expr> {
    if pred(e) {
        return Some(e);
    }
    match &e.node {
        Node::Num(_) | Node::Var(_) => None,
        Node::Neg(a) => find_opt(a, pred),
        Node::Bin(_, a, b) => find_opt(a, pred).or_else(|| find_opt(b, pred)),
        Node::Call(_, args) => args.iter().find_map(|a| find_opt(a, pred)),
    }
}

fn check_finite(
    at: &Locator,
    s: &Source,
    what: &str,
    lookup: &impl Fn(Var) -> f64,
    where_: &str,
) -> Result<(), ModelFileError> {
    if let Some(bad) = s.expr.first_non_finite(lookup) {
        let v = bad.eval(lookup);
        return Err(at.error(s.base + bad.span.0, format!("{what}: yields {v} {where_}")));
    }
    Ok(())
}

/// A parameter's prior checked when the file is read: its settings (a positive sd or
/// scale, a shape above 0, `low < high`, finite numbers); for a free parameter, a
/// bounded prior (beta, uniform) that covers the parameter's range, and mass at its
/// value. (A prior on (0, inf) over an unbounded parameter stays allowed: the samplers
/// reject the proposals below 0.)
fn check_prior(prior: &ScalarPrior, p: &Parameter) -> Result<(), String> {
    prior.check(&p.name).map_err(|e| match e {
        sysid_pmcmc::PmcmcError::InvalidPrior { reason, .. } => format!("prior: {reason}"),
        other => format!("prior: {other}"),
    })?;
    if p.fixed {
        return Ok(());
    }
    let (low, high) = range_of(prior.support());
    let (min, max) = range_of(p.support);
    if matches!(prior.support(), Support::Interval(..)) && (min < low || max > high) {
        return Err(format!(
            "prior: the prior lives on ({low}, {high}) but the parameter's bounds allow \
             ({min}, {max}): give it min = {low}, max = {high}"
        ));
    }
    if !prior.support().contains(p.value) || !prior.log_density(p.value).is_finite() {
        return Err(format!("prior: no mass at the value {}", p.value));
    }
    Ok(())
}

/// The interval a support spans.
fn range_of(support: Support) -> (f64, f64) {
    match support {
        Support::Real => (f64::NEG_INFINITY, f64::INFINITY),
        Support::Positive => (0.0, f64::INFINITY),
        Support::Interval(a, b) => (a, b),
    }
}
