//! A fit that loses likelihood on the way does not write the worse estimate, and says
//! which parameters the data cannot separate (the cascaded tanks' first try).

mod common;
use common::{json_of, s, scratch_dir, sysid};
use std::path::Path;

#[test]
fn the_robust_fit_never_returns_less_than_a_point_it_scored() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = scratch_dir();
    let out = dir.join("fit.toml");
    let run = sysid(&[
        "fit",
        "--model",
        s(&root.join("tests/data/cascaded_tanks_kp_free.toml")),
        "--data",
        s(&root.join("../../examples/data/cascaded_tanks_est.csv")),
        "--max-iter",
        "100",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let loglik = summary["loglik"].as_f64().unwrap();
    let best_start = summary["starts"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["loglik"].as_f64())
        .fold(f64::NEG_INFINITY, f64::max);
    // the refinement ends thousands of nats lower; the answer is the best scored point
    assert!(loglik >= best_start, "{loglik} < a start's {best_start}");
    let warnings: Vec<&str> = summary["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("that point is returned instead")),
        "{warnings:?}"
    );
    let inseparable = warnings
        .iter()
        .find(|w| w.contains("cannot be separated by these data"))
        .unwrap_or_else(|| panic!("{warnings:?}"));
    for name in ["k1", "k2", "kp"] {
        assert!(inseparable.contains(name), "{inseparable}");
    }
    // the written file is that estimate: its noise did not run away
    let written = std::fs::read_to_string(&out).unwrap();
    let r: f64 = written
        .lines()
        .find(|l| l.starts_with("r = "))
        .and_then(|l| l.split("value = ").nth(1))
        .and_then(|v| v.split([' ', ',']).next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(r < 1.0, "r = {r}");
}
