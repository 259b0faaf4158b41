use crate::DataArgs;
use crate::error::CliError;
use crate::files::write_output;
use std::path::PathBuf;
use sysid::kalman::ModelSpec;
use sysid::subspace::{N4sidOptions, Order, n4sid};

/// Options of `sysid n4sid`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order, or `auto` (the largest drop of the log singular values).
    #[arg(long, default_value = "auto")]
    pub order: String,
    /// Block rows of the Hankel matrices (default: max(10, ceil((n + 1) / p) + 1)).
    #[arg(long)]
    pub block_rows: Option<usize>,
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

pub fn run(o: &Options) -> Result<(), CliError> {
    let order = parse_order(&o.order)?;
    let file = o.data.read()?;
    let result = n4sid(
        &file.record,
        &N4sidOptions {
            order,
            block_rows: o.block_rows,
        },
    )?;
    let text =
        serde_json::to_string_pretty(&ModelSpec::from_model(&result.model)).expect("serialises");
    write_output(&o.out, o.force, &(text + "\n"))?;
    if o.json {
        crate::say(
            &serde_json::json!({
                "command": "n4sid", "order": result.order, "block_rows": result.block_rows,
                "singular_values": result.singular_values, "spectral_radius": result.spectral_radius,
                "out": o.out,
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
            "order {} (block rows {}), spectral radius {:.4}; singular values {} ...; wrote {}",
            result.order,
            result.block_rows,
            result.spectral_radius,
            shown.join(" "),
            o.out.display()
        ));
    }
    Ok(())
}
