//! The model-file reader (JSON parse, then validation) on arbitrary text.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(text) = std::str::from_utf8(bytes) {
        let _ = sysid_cli::fuzzing::parse_model_file(text);
    }
});
