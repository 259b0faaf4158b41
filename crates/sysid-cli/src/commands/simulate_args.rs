//! The options of `sysid simulate` (a built-in system, or a model with a record).

use std::path::PathBuf;

/// Options of `sysid simulate`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// System name: lgss, lti2x2, nlbench or wiener (the blind Wiener system; its
    /// input is not written, it is unobserved). Omit it to simulate a model file's
    /// response to a record's inputs (--model, --data).
    pub system: Option<String>,
    /// Model file whose response to the inputs of --data is simulated (noise-free unless
    /// --noise), written with the data's output names. A nonlinear model file
    /// (`.toml`) is simulated with its noise for --steps steps (or, with inputs, for the
    /// rows of --data), its outputs and (--states) states named as in the file.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Record whose inputs drive --model (its outputs, if any, fix the initial state by
    /// least squares and are compared with the simulation).
    #[arg(long, requires = "model")]
    pub data: Option<PathBuf>,
    /// With --model: use only the data rows START..=END (1-based), as the other
    /// commands' --range.
    #[arg(long, requires = "model")]
    pub range: Option<String>,
    /// With --model: the initial state, `estimate` (least squares against the record's
    /// outputs; the default when it has them), `model` (the model file's initial mean
    /// for this record: its mu, or for `"initial": "stationary"` the stationary mean at
    /// the record's first input) or `zero`.
    #[arg(long)]
    pub x0: Option<String>,
    /// With --model: one realisation with the model's process and measurement noise
    /// (seeded by --seed), started from the initial state chosen by --x0.
    #[arg(long)]
    pub noise: bool,
    /// With a nonlinear model file (`.toml`): the noise-free simulation (every noise
    /// term zero) from the file's initial means, instead of one noisy realisation.
    #[arg(long, requires = "model", conflicts_with = "noise")]
    pub noise_free: bool,
    /// Number of time steps.
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// Seed of the random generator (Xoshiro256++).
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the true states x1..xn.
    #[arg(long)]
    pub states: bool,
    /// Also write the true model as JSON to this file.
    #[arg(long)]
    pub model_out: Option<PathBuf>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}
