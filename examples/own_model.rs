//! Your own nonlinear model, defined once, fitted by particle EM and sampled by PMMH.
//!
//! A predator-prey (Lotka-Volterra) system on the log scale, two states: the log
//! populations of the prey `h` and of the predator `l`, both counted with noise:
//! ```text
//! h' = h + dt (a - b exp(l)) + w1,   l' = l + dt (c exp(h) - d) + w2
//! y1 = h + e1,                       y2 = l + e2
//! ```
//! The four rates enter linearly, so particle EM has a closed-form M-step (sysid finds
//! this itself); PMMH then samples their posterior from the EM estimate.
//!
//! `cargo run --release --example own_model`

use sysid::em::affine::{RobustOptions, fit_robust};
use sysid::modelfile::ModelFile;
use sysid::pmcmc::{ChainRun, IndependentPrior, PmmhOptions, pmmh, summarise};
use sysid::smc::{Series, Tanizaki};

const MODEL: &str = r#"
format = 1
name = "predator-prey"
states = ["h", "l"]
outputs = ["y1", "y2"]

[parameters]
a = { value = 0.6, prior = { family = "normal", mean = 0.0, sd = 10.0 } }
b = { value = 0.025, prior = { family = "normal", mean = 0.0, sd = 1.0 } }
c = { value = 0.012, prior = { family = "normal", mean = 0.0, sd = 1.0 } }
d = { value = 0.5, prior = { family = "normal", mean = 0.0, sd = 10.0 } }
dt = 0.1
q = 1e-4
r1 = { value = 0.01, prior = { family = "inverse_gamma", shape = 2.0, scale = 0.02 } }
r2 = { value = 0.01, prior = { family = "inverse_gamma", shape = 2.0, scale = 0.02 } }

[transition]
h = "h + dt*(a - b*exp(l))"
l = "l + dt*(c*exp(h) - d)"

[observation]
y1 = "h"
y2 = "l"

[noise]
h = "q"
l = "q"
y1 = "r1"
y2 = "r2"

[initial]
h = { mean = 3.7, variance = 0.01 }
l = { mean = 3.0, variance = 0.01 }
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // one definition: the filters, particle EM and PMMH all use it
    let model = ModelFile::parse(MODEL, "predator-prey")?;
    let truth = model.free_values();
    let (_, y) = model.at(&truth)?.simulate(400, &[], 11)?;
    let data = Series::new(&y, 2)?;

    // particle EM (closed form: the rates enter linearly), from 30 % off
    let affine = model
        .affine()
        .ok_or_else(|| model.why_not_affine().unwrap_or_default())?;
    let start: Vec<f64> = truth.iter().map(|v| v * 1.3).collect();
    let smoother = Tanizaki::default();
    let options = RobustOptions {
        refine_iterations: 100,
        ..RobustOptions::default()
    };
    let fit = fit_robust(
        &affine,
        data,
        &affine.params(&start)?,
        &affine.em_spec(),
        &smoother,
        &options,
        1,
    )?;
    let estimate = affine.theta(&fit.estimate);
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }

    // PMMH from the estimate, under the priors of the model text
    let priors = model.priors().into_iter().flatten().collect();
    let prior = IndependentPrior::new(&model.free_names(), priors)?;
    let pmmh_options = PmmhOptions {
        iterations: 10_000,
        burn_in: 3000,
        particles: 100,
        ..PmmhOptions::default()
    };
    let chains = pmmh(
        &model,
        &prior,
        &data,
        &estimate,
        &pmmh_options,
        &ChainRun::new(2, 5),
    )?;

    println!("parameter      truth   particle EM   posterior mean (sd)   R-hat");
    for (k, s) in summarise(&chains).iter().enumerate() {
        println!(
            "{:>9} {:>10.4} {:>13.4} {:>12.4} ({:.4}) {:>9.3}",
            s.name, truth[k], estimate[k], s.mean, s.sd, s.rhat
        );
        if s.rhat > 1.05 {
            eprintln!(
                "warning: {} has not mixed (R-hat {:.3}): run longer",
                s.name, s.rhat
            );
        }
    }
    Ok(())
}
