//! `sysid`: the command line of the sysid workspace (see the `sysid_cli` library).

fn main() -> std::process::ExitCode {
    sysid_cli::main_with(std::env::args_os())
}
