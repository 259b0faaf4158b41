//! Every setting of a model file's fit either reaches the options of the method that
//! runs or is refused with a message naming that method; none is dropped.

use sysid_em::affine::AffineMethod;
use sysid_em::{FitSettings, SettingError};
use sysid_modelfile::{Criterion, FileFitError, FileFitMethod, ModelFile, fit_defaults};

const AFFINE: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../examples/models/oscillator.toml"
));
const NOT_AFFINE: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../examples/models/cascaded_tanks.toml"
));

/// Each setting alone, at a value other than its default.
fn each_setting() -> Vec<(&'static str, FitSettings)> {
    let one = |f: fn(&mut FitSettings)| {
        let mut s = FitSettings::default();
        f(&mut s);
        s
    };
    vec![
        ("particles", one(|s| s.particles = Some(37))),
        (
            "smoother",
            one(|s| s.smoother = Some("ffbsi-reject".into())),
        ),
        ("max_iter", one(|s| s.max_iter = Some(7))),
        ("starts", one(|s| s.starts = Some(3))),
        ("polish", one(|s| s.polish = Some(false))),
        ("extrapolate", one(|s| s.extrapolate = Some(false))),
        ("patience", one(|s| s.patience = Some(9))),
        ("spread", one(|s| s.spread = Some(0.9))),
    ]
}

/// The methods, as (file, criterion, method setting, what runs, what it reads).
fn cases() -> Vec<(
    ModelFile,
    Criterion,
    Option<AffineMethod>,
    &'static [&'static str],
)> {
    let affine = ModelFile::parse(AFFINE, "oscillator.toml").unwrap();
    let other = ModelFile::parse(NOT_AFFINE, "cascaded_tanks.toml").unwrap();
    assert!(affine.affine().is_some() && other.affine().is_none());
    vec![
        (
            affine.clone(),
            Criterion::Likelihood,
            Some(AffineMethod::Robust),
            &[
                "particles",
                "smoother",
                "max_iter",
                "starts",
                "polish",
                "extrapolate",
            ],
        ),
        (
            affine.clone(),
            Criterion::Likelihood,
            Some(AffineMethod::Em),
            &["particles", "smoother", "max_iter"],
        ),
        (
            affine.clone(),
            Criterion::Likelihood,
            Some(AffineMethod::Psaem),
            &["particles", "max_iter"],
        ),
        (
            other.clone(),
            Criterion::Likelihood,
            Some(AffineMethod::Robust),
            &["starts", "polish"],
        ),
        (
            other.clone(),
            Criterion::Likelihood,
            Some(AffineMethod::Em),
            &["particles", "max_iter"],
        ),
        (
            affine,
            Criterion::Simulation,
            None,
            &["starts", "patience", "spread"],
        ),
        (
            other,
            Criterion::Simulation,
            None,
            &["starts", "patience", "spread"],
        ),
    ]
}

#[test]
fn every_setting_reaches_the_method_or_is_refused_naming_it() {
    for (file, criterion, method, reads) in cases() {
        let base = FitSettings {
            method,
            ..FitSettings::default()
        };
        let at_defaults = file.fit_method(criterion, &base).unwrap();
        for (name, setting) in each_setting() {
            let settings = FitSettings { method, ..setting };
            let got = file.fit_method(criterion, &settings);
            let case = format!("{} {criterion} {method:?}: {name}", file.origin());
            if reads.contains(&name) {
                let chosen = got.unwrap_or_else(|e| panic!("{case}: refused: {e}"));
                assert_ne!(chosen, at_defaults, "{case}: the setting changed nothing");
                assert_eq!(
                    std::mem::discriminant(&chosen),
                    std::mem::discriminant(&at_defaults),
                    "{case}: another method"
                );
            } else {
                match got {
                    Err(FileFitError::Setting(e @ SettingError::NotApplicable { .. })) => {
                        assert_eq!(e.setting(), name, "{case}");
                        let text = e.to_string();
                        assert!(
                            text.starts_with(&format!("{name} does not apply to ")),
                            "{case}: {text}"
                        );
                        let what = match at_defaults {
                            FileFitMethod::ParticleEm(ref o) => o.options().method.description(),
                            FileFitMethod::Direct(_) => "the direct likelihood search",
                            FileFitMethod::GradientEm(_) => "gradient EM",
                            FileFitMethod::Simulation(_) => "the simulation-error fit",
                        };
                        assert!(text.contains(what), "{case}: {text} does not name {what}");
                    }
                    other => panic!("{case}: not refused: {other:?}"),
                }
            }
        }
    }
}

#[test]
fn the_method_setting_is_refused_by_the_simulation_error_fit() {
    let file = ModelFile::parse(NOT_AFFINE, "cascaded_tanks.toml").unwrap();
    let settings = FitSettings {
        method: Some(AffineMethod::Em),
        ..FitSettings::default()
    };
    let e = file
        .fit_method(Criterion::Simulation, &settings)
        .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("method does not apply to the simulation-error fit"),
        "{e}"
    );
}

#[test]
fn the_defaults_are_the_methods_own() {
    let d = fit_defaults();
    let file = ModelFile::parse(AFFINE, "oscillator.toml").unwrap();
    // every setting given at its default gives the options of no setting at all
    let robust = FitSettings {
        patience: None,
        spread: None,
        ..d.clone()
    };
    assert_eq!(
        file.fit_method(Criterion::Likelihood, &robust).unwrap(),
        file.fit_method(Criterion::Likelihood, &FitSettings::default())
            .unwrap()
    );
    let simulation = FitSettings {
        starts: d.starts,
        patience: d.patience,
        spread: d.spread,
        ..FitSettings::default()
    };
    assert_eq!(
        file.fit_method(Criterion::Simulation, &simulation).unwrap(),
        file.fit_method(Criterion::Simulation, &FitSettings::default())
            .unwrap()
    );
    let other = ModelFile::parse(NOT_AFFINE, "cascaded_tanks.toml").unwrap();
    for method in [AffineMethod::Robust, AffineMethod::Em] {
        let reads = match method {
            AffineMethod::Robust => FitSettings {
                method: Some(method),
                starts: d.starts,
                polish: d.polish,
                ..FitSettings::default()
            },
            _ => FitSettings {
                method: Some(method),
                particles: d.particles,
                max_iter: d.max_iter,
                ..FitSettings::default()
            },
        };
        assert_eq!(
            other.fit_method(Criterion::Likelihood, &reads).unwrap(),
            other
                .fit_method(
                    Criterion::Likelihood,
                    &FitSettings {
                        method: Some(method),
                        ..FitSettings::default()
                    }
                )
                .unwrap()
        );
    }
}

#[test]
fn names_parse_and_print_alike() {
    for name in Criterion::NAMES {
        assert_eq!(name.parse::<Criterion>().unwrap().to_string(), name);
    }
    for name in AffineMethod::NAMES {
        assert_eq!(name.parse::<AffineMethod>().unwrap().to_string(), name);
    }
    assert!(
        "likelyhood"
            .parse::<Criterion>()
            .unwrap_err()
            .contains("likelihood or simulation")
    );
    assert!(
        "robst"
            .parse::<AffineMethod>()
            .unwrap_err()
            .contains("robust, em, psaem")
    );
}
