//! The CSV readers (data files and numeric tables) on arbitrary bytes: an error or a
//! record, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = sysid_cli::fuzzing::parse_data_file(bytes);
    let _ = sysid_cli::fuzzing::parse_table(bytes);
});
