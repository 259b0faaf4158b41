//! `sysid`: the command line of the sysid workspace (the binary is `src/main.rs`; this
//! library holds the commands, and the parsers that the fuzz targets call).
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
mod data_file;
mod error;
mod files;
pub mod fuzzing;
mod progress;
mod resources;

use clap::{Args, Parser, Subcommand};
use error::CliError;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "sysid",
    version,
    about = "System identification from the command line",
    long_about = "System identification from the command line. Without a subcommand, runs \
                  the demo (`sysid demo`).",
    after_help = "Examples:\n  sysid demo                                   # the whole pipeline, figures in ./sysid-demo\n  sysid simulate lti2x2 --steps 200 --out d.csv --model-out true.json\n  sysid fit lti --data d.csv --order 8 --out fit.json --trace trace.csv\n  sysid plot trace.csv fit.json --out-dir figures\n\nShared flags mean the same everywhere: --seed, --threads, --json, --quiet, --force, --out / --out-dir.\nErrors are one line on stderr; exit code 2 for bad input, 1 for failures."
)]
struct Cli {
    /// Worker threads (default: one per core). Results never depend on it.
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// No progress bars or notes on stderr (results still go to stdout).
    #[arg(long, global = true)]
    quiet: bool,
    /// Exit with code 1 when the command printed a warning (a result that should not
    /// be trusted as it is: unconverged EM, a chain that has not mixed, a filter that
    /// lost the state...). The outputs are written as without it.
    #[arg(long, global = true)]
    strict: bool,
    #[command(subcommand)]
    command: Option<Command>,
}

/// Column selection shared by the commands that read data.
#[derive(Args, Debug, Clone)]
pub(crate) struct DataArgs {
    /// Data file (CSV with a header line).
    #[arg(long)]
    data: PathBuf,
    /// Input columns, comma separated (default: every column named u1, u2, ...).
    #[arg(long, value_delimiter = ',')]
    inputs: Option<Vec<String>>,
    /// Output columns, comma separated (default: every column named y1, y2, ...).
    #[arg(long, value_delimiter = ',')]
    outputs: Option<Vec<String>>,
    /// Use only the data rows START..=END (1-based, the header not counted; either
    /// side may be left out: `401:` is row 401 to the end), e.g. to fit on one segment
    /// of a file and validate on another.
    #[arg(long)]
    range: Option<String>,
    /// The sampling interval, in the units of the data's time (default: the spacing of
    /// an evenly spaced numeric time column); stored in fitted models, used by the
    /// frequency and time axes of their plots.
    #[arg(long)]
    ts: Option<f64>,
}

/// A model file and a record to run it on, with the record's initial state (`loglik`,
/// `filter`, `smooth`, `predict`, `forecast`, `resid`).
#[derive(Args, Debug, Clone)]
pub(crate) struct ModelOnData {
    /// Model file (JSON, see docs/model-format.md).
    #[arg(long)]
    model: PathBuf,
    #[command(flatten)]
    data: DataArgs,
    /// The initial state of the record: `model` (the model file's), `stationary` (the
    /// stationary law of a stable model's state noise) or `diffuse` (exact diffuse: the
    /// data determine x_1; Durbin and Koopman's diffuse log-likelihood).
    #[arg(long, default_value = "model")]
    initial: String,
}

/// A model file, data, and where the states go (`filter`, `smooth`).
#[derive(Args, Debug)]
pub(crate) struct StatesArgs {
    #[command(flatten)]
    source: ModelOnData,
    /// Output CSV file (t, x1.., x1_sd..; a model file's state names instead of x1..).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing output file.
    #[arg(long)]
    force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The whole pipeline on the papers' systems (N4SID then EM on the seed-004 system,
    /// the seed-000 particle-EM study), a table and figures; about 12 s on 2 cores.
    #[command(
        after_help = "Examples:\n  sysid demo\n  sysid demo --out-dir /tmp/figures --force\n  sysid demo --full          # the paper's scale: 200 runs x 1000 iterations on T = 1000 (about 70 min on 2 cores)"
    )]
    Demo(commands::demo::Options),
    /// Simulate a canonical system and write its data as CSV (t, u1.., y1.., [x1..]), or
    /// a model file's response to a record's inputs (--model, --data).
    #[command(
        after_help = "Examples:\n  sysid simulate lti2x2 --steps 200 --seed 1 --out d.csv --model-out true.json\n  sysid simulate nlbench --steps 1000 --out nl.csv\n  sysid simulate wiener --steps 1000 --out w.csv\n  sysid simulate --model fit.json --data val.csv --out sim.csv          # noise-free, x0 by least squares\n  sysid simulate --model fit.json --data inputs.csv --noise --seed 3 --out sim.csv"
    )]
    Simulate(commands::simulate::Options),
    /// Identify a linear state-space model by N4SID and write it as JSON.
    #[command(
        after_help = "Examples:\n  sysid n4sid --data d.csv --order 8 --out n4sid.json\n  sysid n4sid --data d.csv --order auto --out n4sid.json --json   # singular values in the summary"
    )]
    N4sid(commands::n4sid::Options),
    /// Fit a model by maximum likelihood: `lti` (exact EM), `nlbench` and `affine`
    /// (particle EM or PSAEM), `wiener` (gradient EM, blind).
    #[command(
        after_help = "Examples:\n  sysid fit lti --data d.csv --order 8 --out fit.json --trace trace.csv\n  sysid fit lti --data d.csv --init start.json --fix D=0 --diag R --out fit.json\n  sysid fit nlbench --data nl.csv --max-iter 200 --particles 50 --out nl-fit.json\n  sysid fit nlbench --data nl.csv --method psaem --particles 15 --iters 2000 --estimate-noise=q --out nl-fit.json
  sysid fit lti --data d.csv --order 8 --min-variance 1e-8 --out fit.json\n  sysid fit wiener --data w.csv --max-iter 100 --out wiener.json"
    )]
    Fit(Box<commands::fit::FitCommand>),
    /// Print the exact log-likelihood of data under a model (square-root Kalman filter).
    #[command(
        after_help = "Examples:\n  sysid loglik --model true.json --data d.csv\n  sysid loglik --model fit.json --data d.csv --json\n  sysid loglik --model fit.json --data other.csv --initial diffuse"
    )]
    Loglik {
        #[command(flatten)]
        source: ModelOnData,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Kalman filter: write the filtered state means and standard deviations as CSV.
    #[command(
        after_help = "Examples:\n  sysid filter --model fit.json --data d.csv --out filtered.csv\n  sysid filter --model trend.json --data d.csv --initial diffuse --out filtered.csv"
    )]
    Filter(StatesArgs),
    /// RTS smoother: write the smoothed state means and standard deviations as CSV.
    #[command(
        after_help = "Examples:\n  sysid smooth --model fit.json --data d.csv --out smoothed.csv\n  sysid plot smoothed.csv --out-dir figures"
    )]
    Smooth(StatesArgs),
    /// k-step-ahead predicted outputs, their standard deviations and the prediction
    /// errors (innovations for k = 1), as CSV.
    #[command(
        after_help = "Examples:\n  sysid predict --model fit.json --data val.csv --out pred.csv\n  sysid predict --model fit.json --data val.csv --horizon 5 --out pred5.csv --json"
    )]
    Predict(commands::predict::Options),
    /// Fit per output of models' simulated (--horizon inf) or k-step predicted outputs
    /// on a record (MATLAB `compare`), with a figure.
    #[command(
        after_help = "Examples:\n  sysid compare --model n4sid.json fit.json --data val.csv\n  sysid compare --model fit.json --data val.csv --horizon 1 --burn-in 50 --out-dir figures"
    )]
    Compare(commands::compare::Options),
    /// Forecast outputs beyond the data, with prediction intervals (CSV).
    #[command(
        after_help = "Examples:\n  sysid forecast --model fit.json --data d.csv --steps 12 --out forecast.csv\n  sysid forecast --model fit.json --data d.csv --steps 50 --future-inputs u_next.csv --level 0.9 --out forecast.csv"
    )]
    Forecast(commands::forecast::Options),
    /// Transfer functions of a model: poles, and per channel the zeros, the static
    /// gain and the numerator and denominator polynomials in z.
    #[command(
        after_help = "Examples:\n  sysid tf --model fit.json\n  sysid tf --model fit.json --json"
    )]
    Tf(commands::tf::Options),
    /// Residual tests of a model on a record: autocorrelation of the one-step errors,
    /// cross-correlation with the inputs, Ljung-Box statistic and p-value, a figure.
    #[command(
        after_help = "Examples:\n  sysid resid --model fit.json --data val.csv\n  sysid resid --model fit.json --data val.csv --lags 25 --out resid.csv --out-dir figures --json"
    )]
    Resid(commands::resid::Options),
    /// Bootstrap particle filter: the log-likelihood estimate and filtered means.
    #[command(
        after_help = "Examples:\n  sysid pf --system nlbench --data nl.csv --particles 1000 --out filtered.csv\n  sysid pf --model fit.json --data d.csv --particles 500 --resample stratified --ess 0.5 --json"
    )]
    Pf(commands::particle::ParticleArgs),
    /// Particle smoother (Tanizaki, FFBSi, rejection FFBSi, genealogy): smoothed means
    /// and standard deviations.
    #[command(
        after_help = "Examples:\n  sysid psmooth --system nlbench --data nl.csv --method ffbsi-reject --paths 100 --out smoothed.csv\n  sysid psmooth --system nlbench --data nl.csv --method tanizaki --particles 50 --out smoothed.csv"
    )]
    Psmooth(commands::particle::SmoothArgs),
    /// Particle marginal Metropolis-Hastings: posterior of a canonical system's
    /// parameters (several chains in parallel, diagnostics, draws as CSV).
    #[command(
        after_help = "Examples:\n  sysid pmmh --system nlbench --data nl.csv --iters 10000 --particles 100 --chains 4 --out chains.csv\n  sysid pmmh --system lgss --data lg.csv --prior prior.json --out chains.json --json"
    )]
    Pmmh(commands::pmcmc::PmmhArgs),
    /// Particle Gibbs with ancestor sampling (or backward simulation, or plain):
    /// posterior of the parameters and the states.
    #[command(
        after_help = "Examples:\n  sysid pgas --system lgss --data lg.csv --iters 5000 --particles 10 --kernel as --out chains.csv\n  sysid pgas --system lgss --data lg.csv --guided --step conjugate\n  sysid pgas --system nlbench --data nl.csv --kernel bs --step mh"
    )]
    Pgas(commands::pmcmc::PgasArgs),
    /// Draw figures (SVG and PNG) from files written by sysid: EM traces, fitted
    /// models (Bode magnitude), smoothed or filtered states, data.
    #[command(
        after_help = "Examples:\n  sysid plot trace.csv --out-dir figures                 # log-likelihood and parameter trajectories\n  sysid plot n4sid.json fit.json true.json --out-dir figures   # Bode magnitudes, one curve per model\n  sysid plot smoothed.csv --truth d.csv --out-dir figures  # states with 95 % bands\n  sysid plot d.csv --out-dir figures                     # the data columns"
    )]
    Plot(commands::plot::Options),
    /// Run a benchmark or experiment runner (JSON lines), or `report` to regenerate
    /// docs/benchmarks.md.
    #[command(
        after_help = "Examples:\n  sysid bench kalman --reps 5\n  sysid bench nlbench-em --runs 16 --iters 200\n  sysid bench report --scale quick"
    )]
    Bench {
        #[command(subcommand)]
        runner: sysid_bench::Runner,
    },
}

/// Prints one line on stdout; a closed stdout (e.g. `| head -1`) ends the program
/// quietly, as for any Unix filter, instead of panicking.
/// Set when an output goes to standard output (`--out -`): the summary then goes to
/// stderr, so that stdout carries the data alone.
static STDOUT_CLAIMED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Marks standard output as taken by an output file (`-`).
pub(crate) fn claim_stdout() {
    STDOUT_CLAIMED.store(true, std::sync::atomic::Ordering::Relaxed);
}

pub(crate) fn say(line: &str) {
    use std::io::Write;
    if STDOUT_CLAIMED.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!("{line}");
        return;
    }
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{line}").and_then(|_| out.flush()).is_err() {
        std::process::exit(0);
    }
}

/// Prints a warning about a result that should not be trusted as it is (stderr, so
/// that `--json` output stays one object; the same text goes in its `warnings`).
pub(crate) fn warn(line: &str) {
    WARNINGS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    eprintln!("sysid: warning: {line}");
}

/// Warnings printed by the current command (for `--strict`).
static WARNINGS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Prints a command's summary: `value` as one JSON line under `--json`, else `text`.
pub(crate) fn report(json: bool, value: serde_json::Value, text: impl FnOnce() -> String) {
    if json {
        say(&value.to_string());
    } else {
        say(&text());
    }
}

/// Worker threads of the current pool (the global one sized by `--threads`).
pub(crate) fn threads() -> usize {
    rayon::current_num_threads()
}

fn run(cli: Cli) -> Result<(), CliError> {
    progress::set_quiet(cli.quiet);
    // rayon's own count (RAYON_NUM_THREADS or the processors) without --threads
    let mut threads = 0;
    if let Some(asked) = cli.threads {
        if asked == 0 {
            return Err(CliError::BadOption {
                option: "--threads",
                message: "must be at least 1".into(),
            });
        }
        let (capped_count, capped) = resources::capped_threads(asked);
        if let Some(note) = capped {
            warn(&note);
        }
        threads = capped_count;
    }
    // workers evaluate model files' expression trees, whose deepest allowed form needs
    // more than the default 2 MiB in a release build
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(sysid::modelfile::expr::STACK_BYTES)
        .build_global()
        .map_err(|e| CliError::BadOption {
            option: "--threads",
            message: e.to_string(),
        })?;
    match cli.command {
        None => commands::demo::run(&commands::demo::Options::default()),
        Some(Command::Demo(options)) => commands::demo::run(&options),
        Some(Command::Simulate(options)) => commands::simulate::run(&options),
        Some(Command::N4sid(options)) => commands::n4sid::run(&options),
        Some(Command::Fit(options)) => commands::fit::run(*options),
        Some(Command::Predict(options)) => commands::predict::run(&options),
        Some(Command::Compare(options)) => commands::compare::run(&options),
        Some(Command::Resid(options)) => commands::resid::run(&options),
        Some(Command::Tf(options)) => commands::tf::run(&options),
        Some(Command::Forecast(options)) => commands::forecast::run(&options),
        Some(Command::Pf(options)) => commands::particle::run_filter(&options),
        Some(Command::Psmooth(options)) => commands::particle::run_smoother(&options),
        Some(Command::Pmmh(options)) => commands::pmcmc::run_pmmh(&options),
        Some(Command::Pgas(options)) => commands::pmcmc::run_pgas(&options),
        Some(Command::Plot(options)) => commands::plot::run(&options),
        Some(Command::Loglik { source, json }) => commands::loglik::run(&source, json),
        Some(Command::Filter(a)) => commands::smooth::run(&a, commands::smooth::Pass::Filter),
        Some(Command::Smooth(a)) => commands::smooth::run(&a, commands::smooth::Pass::Smooth),
        Some(Command::Bench { runner }) => {
            sysid_bench::run(runner).map_err(|message| CliError::BadOption {
                option: "bench",
                message,
            })
        }
    }
}

/// For an option that `sysid fit`'s model class (or model-file form) does not take:
/// which fit forms do take it, read from the command line's own definition.
fn fit_option_elsewhere(args: &[std::ffi::OsString], e: &clap::Error) -> Option<String> {
    use clap::CommandFactory;
    use clap::error::{ContextKind, ContextValue};
    if e.kind() != clap::error::ErrorKind::UnknownArgument {
        return None;
    }
    let words: Vec<&str> = args.iter().filter_map(|a| a.to_str()).collect();
    let at = words.iter().position(|w| *w == "fit")?;
    let Some(ContextValue::String(given)) = e.get(ContextKind::InvalidArg) else {
        return None;
    };
    let flag = given.split('=').next()?.strip_prefix("--")?;
    let cli = Cli::command();
    let fit = cli.find_subcommand("fit")?;
    let takes = |c: &clap::Command| c.get_arguments().any(|a| a.get_long() == Some(flag));
    let mut users: Vec<String> = fit
        .get_subcommands()
        .filter(|c| takes(c))
        .map(|c| format!("fit {}", c.get_name()))
        .collect();
    if takes(fit) {
        users.push("fit --model".into());
    }
    let class = words
        .get(at + 1)
        .filter(|w| fit.find_subcommand(w).is_some());
    let what = match class {
        Some(c) => format!("fit {c}"),
        None => "a model file (fit --model)".into(),
    };
    (!users.is_empty()).then(|| {
        format!(
            "--{flag}: does not apply to {what}; it is an option of {}",
            users.join(", ")
        )
    })
}

/// Prints `--help` and `--version` as clap does; any other parse error as one line
/// (clap's message with its indented details joined, without the usage block) and exit
/// code 2, the contract of every bad input.
fn command_line_error(e: &clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = e.print();
        return if e.use_stderr() {
            ExitCode::from(error::EXIT_BAD_INPUT)
        } else {
            ExitCode::SUCCESS
        };
    }
    let text = e.render().to_string();
    let message: Vec<&str> = text
        .lines()
        .take_while(|l| !l.trim().is_empty())
        .map(str::trim)
        .collect();
    let message = message.join(" ");
    eprintln!(
        "sysid: error: {}",
        message.strip_prefix("error: ").unwrap_or(&message)
    );
    ExitCode::from(error::EXIT_BAD_INPUT)
}

/// The command line, with the flags of `sysid fit` that were given (not defaulted)
/// recorded: a fit refuses a given flag its method does not read.
fn parse(args: &[std::ffi::OsString]) -> Result<Cli, clap::Error> {
    use clap::{CommandFactory, FromArgMatches};
    let matches = Cli::command().try_get_matches_from(args)?;
    let mut cli = Cli::from_arg_matches(&matches)?;
    if let (Some(Command::Fit(fit)), Some(mut at)) =
        (&mut cli.command, matches.subcommand_matches("fit"))
    {
        loop {
            fit.given.extend(
                at.ids()
                    .filter(|id| {
                        at.value_source(id.as_str()) == Some(clap::parser::ValueSource::CommandLine)
                    })
                    .map(|id| id.to_string()),
            );
            match at.subcommand() {
                Some((_, inner)) => at = inner,
                None => break,
            }
        }
    }
    Ok(cli)
}

/// Runs the command line on `args` (the program name first) and returns the exit code:
/// 0 on success, 2 for bad input, 1 for other failures, with a one-line error on stderr.
pub fn main_with(args: impl IntoIterator<Item = std::ffi::OsString>) -> ExitCode {
    let args: Vec<std::ffi::OsString> = args.into_iter().collect();
    let cli = match parse(&args) {
        Ok(cli) => cli,
        Err(e) => {
            if let Some(message) = fit_option_elsewhere(&args, &e) {
                eprintln!("sysid: error: {message}");
                return ExitCode::from(error::EXIT_BAD_INPUT);
            }
            return command_line_error(&e);
        }
    };
    let strict = cli.strict;
    progress::watch_interrupts();
    WARNINGS.store(0, std::sync::atomic::Ordering::Relaxed);
    let result = run(cli);
    let warnings = WARNINGS.load(std::sync::atomic::Ordering::Relaxed);
    match result {
        Ok(()) if strict && warnings > 0 => {
            eprintln!(
                "sysid: error: --strict: {warnings} warning{} above",
                if warnings == 1 { "" } else { "s" }
            );
            ExitCode::from(error::EXIT_FAILURE)
        }
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sysid: error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}
