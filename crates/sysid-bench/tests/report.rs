//! `sysid-bench report` checks where it will write before its runners take their
//! minutes (it used to run the whole report, then fail on the folder).

use std::process::Command;
use std::time::Instant;

#[test]
fn a_report_into_a_missing_folder_is_refused_at_once() {
    let started = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_sysid-bench"))
        .args(["report", "--out", "/no/such/folder/benchmarks.md"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("/no/such/folder does not exist"), "{err}");
    assert!(!err.contains("report: "), "no runner ran: {err}");
    assert!(started.elapsed().as_secs_f64() < 5.0);
}
