use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use sysid::kalman::ModelSpec;
use sysid::models::System;

pub use super::simulate_args::Options;

pub fn run(o: &Options) -> Result<(), CliError> {
    // every output checked before anything is written
    crate::files::check_outputs(
        std::iter::once(o.out.as_path()).chain(o.model_out.as_deref()),
        o.force,
    )?;
    let Some(system_name) = o.system.as_deref() else {
        return super::simulate_model::run(o);
    };
    if o.model.is_some() {
        return Err(CliError::BadOption {
            option: "--model",
            message: format!(
                "give either a system ({system_name}) or --model with --data, not both"
            ),
        });
    }
    if o.steps == 0 {
        return Err(CliError::BadOption {
            option: "--steps",
            message: "must be at least 1".into(),
        });
    }
    // the simulated record (at least a state, an input or output, and the noise)
    crate::resources::check_memory(
        "--steps",
        &format!("{} steps", o.steps),
        8.0 * 3.0 * o.steps as f64,
    )?;
    use super::systems::{System as Builtin, Use, lookup};
    let system = match lookup(system_name, Use::Simulate)? {
        Builtin::Nlbench => return run_nlbench(o),
        Builtin::Wiener => return run_wiener(o),
        Builtin::Lgss => System::Lgss,
        Builtin::Lti2x2 => System::Lti2x2,
        Builtin::Pendulum => {
            return Err(CliError::BadOption {
                option: "simulate",
                message: "pendulum is driven by a torque input: simulate its model file with \
                          --model crates/sysid-modelfile/models/pendulum.toml --data INPUTS.csv"
                    .into(),
            });
        }
    };
    let sim = system
        .simulate(o.steps, o.seed)
        .map_err(|source| CliError::Kalman {
            context: format!("simulating {}", system.name()),
            source,
        })?;
    let (u, y, x) = (&sim.record.u, &sim.record.y, &sim.x);
    let mut header = vec!["t".to_string()];
    header.extend((1..=u.nrows()).map(|i| format!("u{i}")));
    header.extend((1..=y.nrows()).map(|i| format!("y{i}")));
    if o.states {
        header.extend((1..=x.nrows()).map(|i| format!("x{i}")));
    }
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for t in 0..o.steps {
        let mut row = vec![(t + 1).to_string()];
        row.extend(u.column(t).iter().map(|&v| fmt(v)));
        row.extend(y.column(t).iter().map(|&v| fmt(v)));
        if o.states {
            row.extend(x.column(t).iter().map(|&v| fmt(v)));
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    if let Some(path) = &o.model_out {
        crate::files::write_model(path, o.force, &ModelSpec::from_model(&system.model()))?;
    }
    if o.json {
        let summary = serde_json::json!({
            "command": "simulate", "system": system.name(), "steps": o.steps, "seed": o.seed,
            "out": o.out, "model_out": o.model_out,
        });
        crate::say(&summary.to_string());
    } else {
        crate::say(&format!(
            "wrote {} steps of {} to {}",
            o.steps,
            system.name(),
            o.out.display()
        ));
    }
    Ok(())
}

/// The nonlinear benchmark (no inputs, no model file: it is not linear Gaussian).
fn run_nlbench(o: &Options) -> Result<(), CliError> {
    if o.model_out.is_some() {
        return Err(CliError::BadOption {
            option: "--model-out",
            message: "nlbench is not a linear Gaussian model and has no model file".into(),
        });
    }
    let sim = sysid::models::Nlbench::truth().simulate(o.steps, o.seed);
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    writeln!(w, "{}", if o.states { "t,y1,x1" } else { "t,y1" }).map_err(io)?;
    for (t, (&y, &x)) in sim.outputs.iter().zip(&sim.states).enumerate() {
        if o.states {
            writeln!(w, "{},{},{}", t + 1, fmt(y), fmt(x)).map_err(io)?;
        } else {
            writeln!(w, "{},{}", t + 1, fmt(y)).map_err(io)?;
        }
    }
    w.commit()?;
    if o.json {
        let summary = serde_json::json!({
            "command": "simulate", "system": "nlbench", "steps": o.steps, "seed": o.seed,
            "out": o.out,
        });
        crate::say(&summary.to_string());
    } else {
        crate::say(&format!(
            "wrote {} steps of nlbench to {}",
            o.steps,
            o.out.display()
        ));
    }
    Ok(())
}

/// The blind Wiener system: outputs y1, y2 (and with `--states` the linear part's
/// output z); the input is unobserved and not written.
fn run_wiener(o: &Options) -> Result<(), CliError> {
    if o.model_out.is_some() {
        return Err(CliError::BadOption {
            option: "--model-out",
            message: "wiener is not a linear Gaussian model and has no model file".into(),
        });
    }
    let sim = sysid::models::BlindWiener::simulate(o.steps, o.seed);
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    writeln!(w, "{}", if o.states { "t,y1,y2,z" } else { "t,y1,y2" }).map_err(io)?;
    for (t, (y, &z)) in sim.outputs.chunks_exact(2).zip(&sim.z).enumerate() {
        let mut row = format!("{},{},{}", t + 1, fmt(y[0]), fmt(y[1]));
        if o.states {
            row += &format!(",{}", fmt(z));
        }
        writeln!(w, "{row}").map_err(io)?;
    }
    w.commit()?;
    crate::report(
        o.json,
        serde_json::json!({
            "command": "simulate", "system": "wiener", "steps": o.steps, "seed": o.seed,
            "out": o.out,
        }),
        || format!("wrote {} steps of wiener to {}", o.steps, o.out.display()),
    );
    Ok(())
}
