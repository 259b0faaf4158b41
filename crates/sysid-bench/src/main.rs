//! `sysid-bench`: the experiment and benchmark runners (see the library's docs).

use clap::Parser;
use sysid_bench::Runner;

#[derive(Parser, Debug)]
#[command(
    name = "sysid-bench",
    about = "sysid experiment and benchmark runners (JSON lines)"
)]
struct Cli {
    #[command(subcommand)]
    runner: Runner,
    /// Accepted for uniformity: output is always JSON lines.
    #[arg(long, global = true)]
    json: bool,
}

fn main() {
    let cli = Cli::parse();
    if let Err(error) = sysid_bench::run(cli.runner) {
        eprintln!("sysid-bench: error: {error}");
        std::process::exit(2);
    }
}
