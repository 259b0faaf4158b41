//! The command-line parser on arbitrary arguments (NUL-separated words).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let text = String::from_utf8_lossy(bytes);
    let args: Vec<String> = text.split('\0').map(str::to_string).collect();
    let _ = sysid_cli::fuzzing::parse_command_line(&args);
});
