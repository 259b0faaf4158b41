//! `sysid fit lti --order n` at its defaults on 20 random stable systems (orders 2 and
//! 3, one or two inputs and outputs, T = 500, simulated with noise by numpy): the fit
//! converges, it ends at the maximum that scipy finds from the truth, and the
//! log-likelihood it reports is the one `sysid loglik` gives the file it writes.
//! Fixtures and the scipy reference: `tests/data/random_lti/`.

mod common;
use common::{json_of, s, scratch_dir, sysid};
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/random_lti")
}

/// A reference row: the system, its order, the offset `h` the fit held and scipy's
/// maxima.
struct Reference {
    system: String,
    order: usize,
    h: Vec<f64>,
    max_from_truth: f64,
    at_truth: f64,
    boundary: bool,
}

fn references() -> Vec<Reference> {
    let text = std::fs::read_to_string(fixtures().join("reference.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["systems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| Reference {
            system: row["system"].as_str().unwrap().to_string(),
            order: row["order"].as_u64().unwrap() as usize,
            h: row["h"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect(),
            max_from_truth: row["max_from_truth"].as_f64().unwrap(),
            at_truth: row["at_truth"].as_f64().unwrap(),
            // scipy's search from the truth ran to a vanishing R: the supremum is on
            // the boundary of the parameter set, not a maximum a fit can end at
            boundary: row["min_r_over_variance_at_max_from_truth"]
                .as_f64()
                .unwrap()
                < 1e-5,
        })
        .collect()
}

/// Systems where the fit ends at an interior maximum other than the one scipy reaches
/// from the truth (none of the three subspace starts lies in that one's basin), with
/// the gap measured when the reference was made.
const OTHER_MAXIMUM: [(&str, f64); 1] = [("17", 0.58)];

#[test]
fn fit_lti_converges_at_its_defaults_and_reports_the_written_models_likelihood() {
    let dir = scratch_dir();
    let mut warned = Vec::new();
    for r in references() {
        let data = fixtures().join(format!("sys{}.csv", r.system));
        let out = dir.join(format!("sys{}.json", r.system));
        let fit = json_of(&sysid(&[
            "fit",
            "lti",
            "--data",
            s(&data),
            "--order",
            &r.order.to_string(),
            "--out",
            s(&out),
            "--json",
        ]));
        let loglik = fit["loglik"].as_f64().unwrap();
        let file = json_of(&sysid(&[
            "loglik",
            "--model",
            s(&out),
            "--data",
            s(&data),
            "--json",
        ]))["loglik"]
            .as_f64()
            .unwrap();
        assert!(
            (loglik - file).abs() < 1e-6,
            "system {}: the fit reports {loglik}, its file scores {file}",
            r.system
        );
        let written: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let h: Vec<f64> = written["h"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(
            h.iter().zip(&r.h).all(|(a, b)| (a - b).abs() < 1e-9),
            "system {}: the fit held h = {h:?}, the reference {:?}: regenerate \
             tests/data/random_lti/reference.json (its README)",
            r.system,
            r.h
        );
        let warnings: Vec<String> = fit["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_str().unwrap().to_string())
            .collect();
        if !warnings.is_empty() {
            // the only honest warning here: the maximum lies where an output's noise
            // variance vanishes (scipy's searches head there too)
            assert!(
                warnings.iter().all(|w| w.contains("singular R")),
                "system {}: {warnings:?}",
                r.system
            );
            warned.push(r.system.clone());
        }
        let gap = r.max_from_truth - loglik;
        match OTHER_MAXIMUM.iter().find(|(k, _)| *k == r.system) {
            Some((_, known)) => assert!(
                (gap - known).abs() < 0.05,
                "system {}: {gap} below scipy's maximum from the truth (was {known})",
                r.system
            ),
            // a supremum on the boundary: the fit's interior maximum must still beat the
            // truth, as every maximum-likelihood estimate does
            None if r.boundary => assert!(
                loglik > r.at_truth,
                "system {}: {loglik} is below the truth's {}",
                r.system,
                r.at_truth
            ),
            None => assert!(
                gap < 0.01,
                "system {}: {loglik} is {gap} nats below scipy's maximum from the truth",
                r.system
            ),
        }
    }
    assert!(
        warned.len() <= 2,
        "the fits of {warned:?} warned (at most 2 of 20 expected)"
    );
}
