//! One library, every face: `sysid psmooth` and `sysid pgas` give the numbers of the
//! library calls they stand for (the particle filter and a `PathSmoother` with the
//! filter's diagnostics; `particle_gibbs` with the family's conjugate step), to the bit.

mod common;

use common::{assert_ok, json_of, s, scratch_dir, sysid};
use std::path::{Path, PathBuf};
use sysid::models::{LgssConjugate, LgssFamily, Nlbench};
use sysid::pmcmc::{ChainRun, GibbsOptions, IndependentPrior, ModelFamily, particle_gibbs};
use sysid::smc::{
    FilterDiagnostics, FilterOptions, ParticleFilter, PathSmoother, Series, Smoother,
};

/// `sysid simulate SYSTEM --steps STEPS --seed SEED`: the record's outputs (one per
/// step) and its path.
fn simulated(dir: &Path, system: &str, steps: usize, seed: u64) -> (PathBuf, Vec<f64>) {
    let path = dir.join(format!("{system}.csv"));
    assert_ok(&sysid(&[
        "simulate",
        system,
        "--steps",
        &steps.to_string(),
        "--seed",
        &seed.to_string(),
        "--out",
        s(&path),
    ]));
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let y = header.iter().position(|h| *h == "y1").unwrap();
    let outputs = lines
        .map(|l| l.split(',').nth(y).unwrap().parse().unwrap())
        .collect();
    (path, outputs)
}

/// A CSV column the binary wrote, by name.
fn column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let j = lines
        .next()
        .unwrap()
        .split(',')
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    lines
        .map(|l| l.split(',').nth(j).unwrap().parse().unwrap())
        .collect()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn psmooth_equals_the_filter_a_path_smoother_and_the_diagnostics() {
    let dir = scratch_dir();
    let (data, y) = simulated(&dir, "nlbench", 150, 5);
    let out = dir.join("smoothed.csv");
    for method in ["ffbsi", "genealogy"] {
        let run = sysid(&[
            "psmooth",
            "--system",
            "nlbench",
            "--data",
            s(&data),
            "--particles",
            "200",
            "--paths",
            "30",
            "--method",
            method,
            "--seed",
            "3",
            "--repeats",
            "3",
            "--out",
            s(&out),
            "--force",
            "--json",
        ]);
        let summary = json_of(&run);
        let model = Nlbench::truth();
        let series = Series::new(&y, 1).unwrap();
        let mut pf = ParticleFilter::new(FilterOptions {
            particles: 200,
            store_history: true,
            variance_block: Some(sysid::smc::VARIANCE_SPAN),
            ..Default::default()
        })
        .unwrap();
        let filtered = pf.run(&model, &series, 3).unwrap();
        let smoother = PathSmoother::from_name(method, 30, false).unwrap();
        let (paths, stats) = smoother
            .trajectories(&model, pf.history().unwrap(), &series, 4)
            .unwrap();
        assert_eq!(
            summary["loglik"].as_f64().unwrap().to_bits(),
            filtered.loglik.to_bits(),
            "{method}"
        );
        assert_eq!(summary["paths"], paths.paths());
        assert_eq!(summary["density_evaluations"], stats.density_evaluations);
        assert_eq!(bits(&column(&out, "x1")), bits(&paths.means()), "{method}");
        assert_eq!(
            bits(&column(&out, "x1_sd")),
            bits(&paths.std_devs()),
            "{method}"
        );
        let diagnostics = FilterDiagnostics::diagnose(&model, &series, &pf, &filtered, 3, 3, || {});
        assert_eq!(
            summary["diagnostics"]["loglik_sd"]
                .as_f64()
                .map(f64::to_bits),
            diagnostics.loglik_sd.map(f64::to_bits)
        );
        let warnings: Vec<String> = diagnostics
            .warnings
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(summary["warnings"], serde_json::json!(warnings));
    }
    // an unknown smoother is refused by both, naming the choices
    assert!(PathSmoother::from_name("rts", 30, false).is_err());
    let bad = sysid(&[
        "psmooth",
        "--system",
        "nlbench",
        "--data",
        s(&data),
        "--method",
        "rts",
    ]);
    common::assert_one_line_error(
        &bad,
        &["--method", "tanizaki, ffbsi, ffbsi-reject, genealogy"],
    );
}

#[test]
fn pgas_equals_particle_gibbs_with_the_conjugate_step() {
    let dir = scratch_dir();
    let (data, y) = simulated(&dir, "lgss", 120, 2);
    let chains_file = dir.join("chains.json");
    let run = sysid(&[
        "pgas",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "200",
        "--burn-in",
        "50",
        "--chains",
        "2",
        "--seed",
        "4",
        "--out",
        s(&chains_file),
        "--json",
    ]);
    let summary = json_of(&run);
    let family = LgssFamily::default();
    let prior = IndependentPrior::new(
        &family.parameter_names(),
        LgssFamily::DEFAULT_PRIORS.to_vec(),
    )
    .unwrap();
    let step = LgssConjugate::from_priors(prior.priors()).unwrap();
    let series = Series::new(&y, 1).unwrap();
    let options = GibbsOptions {
        iterations: 200,
        burn_in: 50,
        ..GibbsOptions::default()
    };
    let chains = particle_gibbs(
        &family,
        &prior,
        &step,
        &series,
        &[0.5, 1.0, 1.0],
        &options,
        &ChainRun::new(2, 4),
    )
    .unwrap();
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&chains_file).unwrap()).unwrap();
    assert_eq!(written["chains"], serde_json::to_value(&chains).unwrap());
    let report = sysid::pmcmc::ChainReport::of(&chains);
    let warnings: Vec<String> = report.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
}

#[test]
fn simulate_model_file_equals_the_library_realisation() {
    use sysid::modelfile::ModelFile;
    let dir = scratch_dir();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/models/oscillator.toml");
    let out = dir.join("osc.csv");
    assert_ok(&sysid(&[
        "simulate",
        "--model",
        s(&path),
        "--steps",
        "120",
        "--seed",
        "3",
        "--states",
        "--out",
        s(&out),
    ]));
    let file = ModelFile::read(&path).unwrap();
    let (states, outputs) = file
        .at(&file.free_values())
        .unwrap()
        .simulate(120, &[], 3)
        .unwrap();
    assert_eq!(bits(&column(&out, "y")), bits(&outputs));
    let p: Vec<f64> = states.chunks_exact(2).map(|x| x[0]).collect();
    assert_eq!(bits(&column(&out, "p")), bits(&p));
}

#[test]
fn a_wiener_estimate_is_json_and_says_what_it_is() {
    let dir = scratch_dir();
    let (data, _) = simulated(&dir, "wiener", 100, 3);
    let refused = sysid(&[
        "fit",
        "wiener",
        "--data",
        s(&data),
        "--iters",
        "2",
        "--particles",
        "10",
        "--out",
        s(&dir.join("w.toml")),
    ]);
    common::assert_one_line_error(&refused, &["--out", "name it .json"]);
    assert!(!dir.join("w.toml").exists());
    let json = dir.join("w.json");
    assert_ok(&sysid(&[
        "fit",
        "wiener",
        "--data",
        s(&data),
        "--iters",
        "2",
        "--particles",
        "10",
        "--out",
        s(&json),
    ]));
    let pf = sysid(&["pf", "--model", s(&json), "--data", s(&data)]);
    common::assert_one_line_error(
        &pf,
        &["`sysid fit wiener` estimate", "no command runs as a model"],
    );
}
