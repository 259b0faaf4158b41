//! The rank-normalised diagnostics of Vehtari et al. (2021) against ArviZ 0.23.4
//! (`az.ess(method="bulk")`, `az.ess(method="tail")`, `az.rhat(method="rank")`) on
//! three fixed sets of 4 chains x 300 draws (`tests/data/vehtari_chains.csv`, written
//! by NumPy with the reference values in `tests/data/vehtari_arviz.json`): an AR(1)
//! with coefficient 0.9, a heavy-tailed exp(2 AR(1)), and chains that disagree.

use sysid_pmcmc::{bulk_ess, rank_rhat, tail_ess};

fn chains(column: usize) -> Vec<Vec<f64>> {
    let text = include_str!("data/vehtari_chains.csv");
    let mut out = vec![Vec::new(); 4];
    for line in text.lines().skip(1) {
        let fields: Vec<&str> = line.split(',').collect();
        let chain: usize = fields[0].parse().unwrap();
        out[chain].push(fields[2 + column].parse().unwrap());
    }
    out
}

fn reference(name: &str, what: &str) -> f64 {
    let v: serde_json::Value =
        serde_json::from_str(include_str!("data/vehtari_arviz.json")).unwrap();
    v["values"][name][what].as_f64().unwrap()
}

#[test]
fn bulk_and_tail_ess_and_rank_rhat_equal_arviz() {
    for (k, name) in ["a", "b", "c"].into_iter().enumerate() {
        let draws = chains(k);
        for (what, ours) in [
            ("bulk_ess", bulk_ess(&draws)),
            ("tail_ess", tail_ess(&draws)),
            ("rhat", rank_rhat(&draws)),
        ] {
            let theirs = reference(name, what);
            assert!(
                (ours - theirs).abs() <= 1e-9 * theirs.abs(),
                "{name} {what}: {ours} against ArviZ's {theirs}"
            );
        }
    }
}

#[test]
fn draws_that_never_change_have_no_diagnostics() {
    let stuck = vec![vec![0.5; 100]; 3];
    assert!(bulk_ess(&stuck).is_nan() && tail_ess(&stuck).is_nan() && rank_rhat(&stuck).is_nan());
    // a round-off wobble is still stuck
    let wobble: Vec<Vec<f64>> = (0..3)
        .map(|j| {
            (0..100)
                .map(|i| 25.0 + 1e-15 * ((i + j) % 3) as f64)
                .collect()
        })
        .collect();
    assert!(bulk_ess(&wobble).is_nan());
}
