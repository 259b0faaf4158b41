//! Every `sysid` command the README's tour and `docs/guide.md` show is run here, in
//! order, as a user would type it (from the repository's root: the data paths are the
//! repository's fixtures), and must succeed.

mod common;
use common::{assert_clean_figures, scratch_dir, svg_texts};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The `sysid` lines of the first ```sh block after the line containing `marker`.
fn commands(file: &str, marker: &str) -> Vec<String> {
    let text = std::fs::read_to_string(root().join(file)).unwrap();
    let after = &text[text
        .find(marker)
        .unwrap_or_else(|| panic!("{file}: no {marker:?}"))..];
    let block = after
        .split("```sh\n")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap();
    let lines: Vec<String> = block
        .lines()
        .map(|l| l.split(" #").next().unwrap().trim().to_string())
        .filter(|l| l.starts_with("sysid "))
        .collect();
    assert!(
        !lines.is_empty(),
        "{file}: no sysid command after {marker:?}"
    );
    lines
}

/// Runs each command in a fresh folder, as `sysid` from the repository's root.
fn run_all(lines: &[String]) -> PathBuf {
    run_checked(lines, false)
}

/// [`run_all`], and with `no_warnings` every command must also print no warning (the
/// README's examples use settings whose results can be trusted).
fn run_checked(lines: &[String], no_warnings: bool) -> PathBuf {
    let dir = scratch_dir();
    let data = root().join("crates/sysid-cli/tests/data/");
    let models = root().join("examples/models/");
    let examples = root().join("examples/data/");
    for line in lines {
        let args: Vec<String> = line
            .split_whitespace()
            .skip(1)
            .map(|a| {
                a.replace("crates/sysid-cli/tests/data/", data.to_str().unwrap())
                    .replace("examples/models/", models.to_str().unwrap())
                    .replace("examples/data/", examples.to_str().unwrap())
            })
            .collect();
        let out = Command::new(env!("CARGO_BIN_EXE_sysid"))
            .args(&args)
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "`{line}` failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !no_warnings || !stderr.contains("warning"),
            "`{line}` warned: {stderr}"
        );
    }
    dir
}

#[test]
fn the_readme_tour_runs() {
    let dir = run_checked(&commands("README.md", "## A 30-second tour"), true);
    for file in ["fit.json", "smoothed.csv", "nl.json", "chains.csv"] {
        assert!(dir.join(file).exists(), "{file}");
    }
    // the figures: titles, axes and legends, phase beside magnitude, a long record
    // shown whole and in a stated window
    assert_eq!(assert_clean_figures(&dir.join("figures")), 3);
    for (figure, expected) in [
        (
            "bode",
            &[
                "G11 (u1 to y1): magnitude",
                "G22 (u2 to y2): phase",
                "phase (degrees)",
                "n4sid",
                "true",
            ][..],
        ),
        ("trace-trace", &["log-likelihood", "EM iteration"][..]),
        (
            "nl-smoothed-states",
            &[
                "state x1",
                "state x1, rows 1-100 of 1000",
                "95 % band",
                "true state",
                "estimate",
            ][..],
        ),
    ] {
        let texts =
            svg_texts(&std::fs::read_to_string(dir.join(format!("figures/{figure}.svg"))).unwrap());
        for text in expected {
            assert!(
                texts.iter().any(|t| t == text),
                "{figure}: no {text:?} in {texts:?}"
            );
        }
    }
}

/// The `sysid` lines of every ```sh block of a file, in order.
fn all_commands(file: &str) -> Vec<String> {
    let text = std::fs::read_to_string(root().join(file)).unwrap();
    text.split("```sh\n")
        .skip(1)
        .flat_map(|block| block.split("```").next().unwrap().lines())
        .map(|l| l.split(" #").next().unwrap().trim().to_string())
        .filter(|l| l.starts_with("sysid "))
        .collect()
}

#[test]
fn every_command_of_the_guide_runs() {
    let walkthrough = commands("docs/guide.md", "<!-- walkthrough");
    assert!(walkthrough.len() >= 8, "{walkthrough:?}");
    let lines = all_commands("docs/guide.md");
    assert!(walkthrough.iter().all(|l| lines.contains(l)));
    let dir = run_all(&lines);
    let svg = std::fs::read_to_string(dir.join("heat-figures/bode.svg")).unwrap();
    assert!(
        svg.contains("heat1: 95 % band"),
        "the structural model's band"
    );
    // every figure of the guide: no round-off tick labels
    assert!(assert_clean_figures(&dir) >= 6);
    for (figure, expected) in [
        (
            "heat-figures/step",
            &["step response, u1 to y1", "heat-n4sid", "heat"][..],
        ),
        (
            "heat-figures/resid",
            &[
                "autocorrelation of y1's errors",
                "95 % bound of white noise",
            ][..],
        ),
        (
            "osc-figures/osc-states-states",
            // the oscillator's own state names (p, v), as simulate --model writes them
            &["state p", "state v", "95 % band", "true state"][..],
        ),
        (
            "tanks-figures/compare",
            &[
                "y: measured and the models' simulation",
                "measured (min-max envelope)",
            ][..],
        ),
        (
            "heat-figures/compare",
            &["y1: measured and the models' simulation", "measured"][..],
        ),
    ] {
        let texts = svg_texts(&std::fs::read_to_string(dir.join(format!("{figure}.svg"))).unwrap());
        for text in expected {
            assert!(
                texts.iter().any(|t| t == text),
                "{figure}: no {text:?} in {texts:?}"
            );
        }
    }
    for file in [
        "heat.json",
        "heat-figures/compare.svg",
        "heat-figures/resid.png",
        "heat1.json",
        "heat-pred5.csv",
        "nile-forecast.csv",
        "tanks-fit.toml",
    ] {
        assert!(dir.join(file).exists(), "{file}");
    }
}
