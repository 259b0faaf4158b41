//! `sysid`: the command line of the sysid workspace.
//!
//! ```text
//! sysid simulate lti2x2 --steps 200 --seed 1 --out data.csv --model-out true.json
//! sysid loglik --model true.json --data data.csv
//! sysid smooth --model true.json --data data.csv --out smoothed.csv
//! sysid simulate nlbench --steps 1000 --seed 1 --out nl.csv
//! sysid pf --system nlbench --data nl.csv --particles 1000 --out filtered.csv
//! sysid psmooth --system nlbench --data nl.csv --method ffbsi-reject --paths 100 --out smoothed.csv
//! sysid pmmh --system nlbench --data nl.csv --iters 10000 --particles 100 --chains 4 --out chains.csv
//! sysid pgas --system lgss --data lg.csv --iters 5000 --particles 10 --kernel as
//! ```
//! Errors are one line on stderr and a non-zero exit code; existing files are never
//! replaced without `--force`.

mod commands;
mod error;
mod files;

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "sysid",
    version,
    about = "System identification from the command line"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Column selection shared by the commands that read data.
#[derive(Args, Debug, Clone)]
pub struct DataArgs {
    /// Data file (CSV with a header line).
    #[arg(long)]
    data: PathBuf,
    /// Input columns, comma separated (default: every column named u1, u2, ...).
    #[arg(long, value_delimiter = ',')]
    inputs: Option<Vec<String>>,
    /// Output columns, comma separated (default: every column named y1, y2, ...).
    #[arg(long, value_delimiter = ',')]
    outputs: Option<Vec<String>>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Simulate a canonical system and write its data as CSV (t, u1.., y1.., [x1..]).
    Simulate(commands::simulate::Options),
    /// Identify a linear state-space model by N4SID and write it as JSON.
    N4sid(commands::n4sid::Options),
    /// Fit a model to data by maximum likelihood (`fit lti`: exact EM).
    Fit(commands::fit::Options),
    /// Print the exact log-likelihood of data under a model (square-root Kalman filter).
    Loglik {
        /// Model file (JSON, see docs/model-format.md).
        #[arg(long)]
        model: PathBuf,
        #[command(flatten)]
        data: DataArgs,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Bootstrap particle filter: the log-likelihood estimate and filtered means.
    Pf(commands::particle::ParticleArgs),
    /// Particle smoother (Tanizaki, FFBSi, rejection FFBSi, genealogy): smoothed means
    /// and standard deviations.
    Psmooth(commands::particle::SmoothArgs),
    /// Particle marginal Metropolis-Hastings: posterior of a canonical system's
    /// parameters (several chains in parallel, diagnostics, draws as CSV).
    Pmmh(commands::pmcmc::PmmhArgs),
    /// Particle Gibbs with ancestor sampling (or backward simulation, or plain):
    /// posterior of the parameters and the states.
    Pgas(commands::pmcmc::PgasArgs),
    /// Smooth the states (RTS) and write their means and standard deviations as CSV.
    Smooth {
        /// Model file (JSON, see docs/model-format.md).
        #[arg(long)]
        model: PathBuf,
        #[command(flatten)]
        data: DataArgs,
        /// Output CSV file (t, x1.., x1_sd..).
        #[arg(long)]
        out: PathBuf,
        /// Replace an existing output file.
        #[arg(long)]
        force: bool,
        /// Print a machine-readable summary.
        #[arg(long)]
        json: bool,
    },
}

/// Prints one line on stdout; a closed stdout (e.g. `| head -1`) ends the program
/// quietly, as for any Unix filter, instead of panicking.
pub fn say(line: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{line}").and_then(|_| out.flush()).is_err() {
        std::process::exit(0);
    }
}

/// Prints a command's summary: `value` as one JSON line under `--json`, else `text`.
pub fn report(json: bool, value: serde_json::Value, text: impl FnOnce() -> String) {
    if json {
        say(&value.to_string());
    } else {
        say(&text());
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(options) => commands::simulate::run(&options),
        Command::N4sid(options) => commands::n4sid::run(&options),
        Command::Fit(options) => commands::fit::run(&options),
        Command::Pf(options) => commands::particle::run_filter(&options),
        Command::Psmooth(options) => commands::particle::run_smoother(&options),
        Command::Pmmh(options) => commands::pmcmc::run_pmmh(&options),
        Command::Pgas(options) => commands::pmcmc::run_pgas(&options),
        Command::Loglik { model, data, json } => commands::loglik::run(&model, &data, json),
        Command::Smooth {
            model,
            data,
            out,
            force,
            json,
        } => commands::smooth::run(&model, &data, &out, force, json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sysid: error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}
