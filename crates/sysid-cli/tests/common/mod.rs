//! Helpers shared by the CLI tests: scratch folders, running the binary, checking the
//! one-line error contract.
#![allow(dead_code)]

pub mod signals;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh folder under the system temp dir, unique per process and call.
pub fn scratch_dir() -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "sysid-cli-test-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::SeqCst)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the `sysid` binary.
pub fn sysid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs the `sysid` binary on `args`, sends it SIGINT (Ctrl-C) after `after`, and
/// returns its output and the seconds from the signal to its exit.
#[cfg(unix)]
pub fn interrupted_after(args: &[&str], after: std::time::Duration) -> (Output, f64) {
    use std::process::Stdio;
    let child = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(after);
    let sent = std::time::Instant::now();
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    (out, sent.elapsed().as_secs_f64())
}

/// A path as `&str`.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Asserts a bad-input failure: exit code 2 and exactly one stderr line containing
/// every `needle`.
pub fn assert_one_line_error(out: &Output, needles: &[&str]) {
    assert!(
        !out.status.success(),
        "expected failure, stdout {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "stderr should be one line: {err}");
    assert_eq!(out.status.code(), Some(2), "bad input exits with 2: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr {err:?} should contain {n:?}");
    }
}

/// Asserts success, showing stderr otherwise.
pub fn assert_ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The JSON summary a successful command printed on stdout.
pub fn json_of(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Simulates a canonical system through the CLI into `dir/<system>.csv`.
pub fn simulate(dir: &Path, system: &str, steps: usize, seed: u64) -> PathBuf {
    let data = dir.join(format!("{system}.csv"));
    let steps = steps.to_string();
    let seed = seed.to_string();
    let out = sysid(&[
        "simulate",
        system,
        "--steps",
        &steps,
        "--seed",
        &seed,
        "--out",
        s(&data),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    data
}

/// The names of a directory's entries, sorted.
pub fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The text elements of an SVG figure (titles, axis labels, tick labels, legends).
pub fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|part| {
            let body = part.split_once('>')?.1;
            let text = body.split("</text>").next()?.trim();
            Some(
                text.replace("&apos;", "'")
                    .replace("&quot;", "\"")
                    .replace("&lt;", "<")
                    .replace("&gt;", ">")
                    .replace("&amp;", "&"),
            )
        })
        .collect()
}

/// Checks every SVG figure under `dir` (recursively): it has text, and no tick label
/// is a round-off residue such as `-1.11e-16` where 0 is meant.
pub fn assert_clean_figures(dir: &Path) -> usize {
    let mut checked = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            checked += assert_clean_figures(&path);
            continue;
        }
        if path.extension().is_none_or(|e| e != "svg") {
            continue;
        }
        let texts = svg_texts(&std::fs::read_to_string(&path).unwrap());
        assert!(texts.len() >= 4, "{}: {texts:?}", path.display());
        for text in &texts {
            if let Ok(v) = text.parse::<f64>() {
                assert!(
                    v == 0.0 || v.abs() > 1e-12,
                    "{}: tick label {text:?}",
                    path.display()
                );
            }
        }
        checked += 1;
    }
    checked
}
