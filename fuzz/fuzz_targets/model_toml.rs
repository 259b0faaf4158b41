//! The nonlinear model-file reader (TOML, expressions, checks), then the model it
//! builds simulated for a few steps, on arbitrary text.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(text) = std::str::from_utf8(bytes) {
        let _ = sysid_cli::fuzzing::parse_nonlinear_model(text);
    }
});
