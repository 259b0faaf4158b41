use crate::DataArgs;
use crate::error::CliError;
use std::path::PathBuf;
use sysid::kalman::ModelSpec;
use sysid::subspace::{
    Criterion, Focus, InputMethod, N4sidOptions, Order, WeightedN4sid, Weighting, WeightingChoice,
    n4sid_weighted, stabilised_fit,
};

/// Options of `sysid n4sid`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order, or `auto`: every order 1..=min(p i - 1, 20) is identified and the
    /// one with the smallest information criterion (--criterion) is kept.
    #[arg(long, default_value = "auto")]
    pub order: String,
    /// Block rows of the Hankel matrices (default: max(10, ceil((n + 1) / p) + 1)).
    #[arg(long)]
    pub block_rows: Option<usize>,
    /// SVD weighting: `auto` (the default: MOESP, N4SID and CVA are all fitted and the
    /// stable model with the best one-step prediction fit on the data is kept; the
    /// three are reported), `moesp`, `n4sid` or `cva`.
    #[arg(long, default_value = "auto")]
    pub weighting: String,
    /// `mean` removes each signal's mean before the identification and folds the means
    /// into the written model's offset h (and mu), so that it describes the original
    /// signals; `linear` removes a straight line in time from each signal and stores
    /// the lines in the model, and the commands that use it remove them from a record
    /// and add the outputs' line back; `none` (the default): N4SID estimates the offset
    /// itself.
    #[arg(long, default_value = "none")]
    pub detrend: String,
    /// What B and D are fitted for: `prediction` (jointly with A, C on the state
    /// equations; consistent with the noise model) or `simulation` (least squares on the
    /// noise-free simulated output given A, C).
    #[arg(long, default_value = "prediction")]
    pub focus: String,
    /// Criterion of `--order auto`: `bic` (-2 ln L + k ln T) or `aic` (-2 ln L + 2 k).
    #[arg(long, default_value = "bic")]
    pub criterion: String,
    /// Enforce a stable A (Maciejowski's padded shift equation) when the estimate has
    /// a pole on or outside the unit circle; without it such a model is written with a
    /// warning.
    #[arg(long)]
    pub stable: bool,
    /// Where to write the model (JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print JSON (with all singular values) instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn parse_order(order: &str) -> Result<Order, CliError> {
    if order.eq_ignore_ascii_case("auto") {
        return Ok(Order::Auto);
    }
    order
        .parse()
        .map(Order::Fixed)
        .map_err(|_| CliError::BadOption {
            option: "--order",
            message: format!("expected a positive integer or 'auto', got {order:?}"),
        })
}

/// The subspace options shared by `n4sid` and `fit lti --init n4sid`.
pub fn subspace_options(
    order: Order,
    block_rows: Option<usize>,
    weighting: &str,
    focus: &str,
    criterion: &str,
    stable: bool,
) -> Result<N4sidOptions, CliError> {
    let focus = match focus.to_ascii_lowercase().as_str() {
        "prediction" => Focus::Prediction,
        "simulation" => Focus::Simulation,
        _ => {
            return Err(CliError::BadOption {
                option: "--focus",
                message: format!("unknown focus {focus:?} (known: prediction, simulation)"),
            });
        }
    };
    let weighting = Weighting::parse(weighting).ok_or_else(|| CliError::BadOption {
        option: "--weighting",
        message: format!("unknown weighting {weighting:?} (known: n4sid, moesp, cva)"),
    })?;
    let criterion = match criterion.to_ascii_lowercase().as_str() {
        "bic" => Criterion::Bic,
        "aic" => Criterion::Aic,
        _ => {
            return Err(CliError::BadOption {
                option: "--criterion",
                message: format!("unknown criterion {criterion:?} (known: bic, aic)"),
            });
        }
    };
    Ok(N4sidOptions {
        order,
        block_rows,
        weighting,
        focus,
        stable,
        criterion,
    })
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let choice = WeightingChoice::parse(&o.weighting).ok_or_else(|| CliError::BadOption {
        option: "--weighting",
        message: format!(
            "unknown weighting {:?} (known: auto, n4sid, moesp, cva)",
            o.weighting
        ),
    })?;
    let options = subspace_options(
        parse_order(&o.order)?,
        o.block_rows,
        match choice {
            WeightingChoice::Fixed(w) => w.name(),
            WeightingChoice::Auto => "moesp",
        },
        &o.focus,
        &o.criterion,
        o.stable,
    )?;
    crate::files::check_outputs(std::iter::once(o.out.as_path()), o.force)?;
    let mut file = o.data.read()?;
    file.require_outputs(&o.data.data)?;
    let trend = super::detrend::apply(&mut file, super::detrend::parse(&o.detrend)?)?;
    let spinner = crate::progress::Progress::spinner("n4sid", o.json);
    let weighted = n4sid_weighted(&file.record, &options, choice);
    spinner.finish();
    let WeightedN4sid { result, candidates } = weighted?;
    let described = super::detrend::written_model(&result.model, trend.as_ref())?;
    let mut spec = ModelSpec::from_model(&described);
    let chosen = result.order_scores.iter().find(|s| s.order == result.order);
    spec.metadata = Some(sysid::kalman::Metadata {
        order: Some(result.order),
        loglik: chosen.map(|s| s.loglik),
        parameters: chosen.map(|s| s.parameters),
        detrend: trend.as_ref().map(super::detrend::Trend::describe),
        ..crate::files::metadata_of(&file, &o.data.data)
    });
    crate::files::write_model(&o.out, o.force, &spec)?;
    let stabilised = stabilised_fit(&file.record, &result, &options);
    let mut warnings: Vec<String> = result
        .warnings(&options)
        .iter()
        .map(ToString::to_string)
        .collect();
    if let Some(s) = stabilised.as_ref().filter(|s| s.destroyed()) {
        warnings.push(format!(
            "stabilising destroyed the model: its simulation fit on the data is {:.1} % \
             (one-step prediction {:.1} %, {} before stabilising); do not use it to \
             simulate: try another order, or --weighting auto (a weighting that is stable \
             without help)",
            s.simulation_fit,
            s.prediction_fit,
            s.unstabilised_prediction_fit
                .map_or("not available".to_string(), |f| format!("{f:.1} %"))
        ));
    }
    let scores: Vec<serde_json::Value> = result
        .order_scores
        .iter()
        .map(|s| {
            serde_json::json!({
                "order": s.order, "loglik": s.loglik, "parameters": s.parameters,
                "criterion": s.criterion, "spectral_radius": s.spectral_radius,
            })
        })
        .collect();
    if o.json {
        crate::say(
            &serde_json::json!({
                "command": "n4sid", "order": result.order, "block_rows": result.block_rows,
                "weighting": result.weighting.name(),
                "singular_values": result.singular_values, "spectral_radius": result.spectral_radius,
                "stable": result.spectral_radius < 1.0, "stabilised": result.stabilised,
                "input_method": match result.input_method {
                    InputMethod::Simulation => "simulation",
                    InputMethod::StateEquations => "state_equations",
                },
                "order_scores": scores, "warnings": warnings, "out": o.out,
                "stabilised_fit": stabilised.as_ref().map(|s| serde_json::json!({
                    "simulation_fit": s.simulation_fit, "prediction_fit": s.prediction_fit,
                    "unstabilised_prediction_fit": s.unstabilised_prediction_fit,
                    "destroyed": s.destroyed(),
                })),
                "weightings": candidates.iter().map(|c| serde_json::json!({
                    "weighting": c.weighting.name(), "order": c.order,
                    "spectral_radius": c.spectral_radius, "stable": c.usable(),
                    "prediction_fit": c.prediction_fit, "error": c.error,
                })).collect::<Vec<_>>(),
            })
            .to_string(),
        );
    } else {
        let shown: Vec<String> = result
            .singular_values
            .iter()
            .take(12)
            .map(|s| format!("{s:.4e}"))
            .collect();
        crate::say(&format!(
            "order {} (block rows {}, {} weighting), spectral radius {:.4}; singular values {} ...; wrote {}",
            result.order,
            result.block_rows,
            result.weighting.name(),
            result.spectral_radius,
            shown.join(" "),
            o.out.display()
        ));
        if let Some(s) = &stabilised {
            crate::say(&format!(
                "stabilised: simulation fit {:.2} %, one-step prediction fit {:.2} % on the \
                 data (before stabilising: {})",
                s.simulation_fit,
                s.prediction_fit,
                s.unstabilised_prediction_fit
                    .map_or("not available".to_string(), |f| format!("{f:.2} %"))
            ));
        }
        if !candidates.is_empty() {
            let rows: Vec<String> = candidates
                .iter()
                .map(|c| match (c.order, c.spectral_radius, c.prediction_fit) {
                    (Some(n), Some(r), Some(f)) => format!(
                        "{} order {n}, radius {r:.4}{}, one-step fit {f:.2} %",
                        c.weighting.name(),
                        if r < 1.0 { "" } else { " (unstable)" }
                    ),
                    _ => format!(
                        "{}: {}",
                        c.weighting.name(),
                        c.error.as_deref().unwrap_or("failed")
                    ),
                })
                .collect();
            crate::say(&format!(
                "weighting auto (kept {}): {}",
                result.weighting.name(),
                rows.join("; ")
            ));
        }
        if !result.order_scores.is_empty() {
            let table: Vec<String> = result
                .order_scores
                .iter()
                .map(|s| format!("{}:{:.1}", s.order, s.criterion))
                .collect();
            crate::say(&format!(
                "{} by order (smallest kept): {}",
                o.criterion.to_ascii_uppercase(),
                table.join(" ")
            ));
        }
    }
    for w in &warnings {
        crate::warn(w);
    }
    Ok(())
}
