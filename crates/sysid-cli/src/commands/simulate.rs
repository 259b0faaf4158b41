use crate::error::CliError;
use crate::files::{create_output, fmt, write_output};
use std::io::Write;
use std::path::PathBuf;
use sysid::kalman::ModelSpec;
use sysid::models::System;

pub struct Options {
    pub system: String,
    pub steps: usize,
    pub seed: u64,
    pub out: PathBuf,
    pub states: bool,
    pub model_out: Option<PathBuf>,
    pub force: bool,
    pub json: bool,
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let system = System::from_name(&o.system).ok_or_else(|| CliError::UnknownSystem {
        name: o.system.clone(),
        known: System::ALL.map(System::name).join(", "),
    })?;
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
    w.flush().map_err(io)?;
    if let Some(path) = &o.model_out {
        let spec = ModelSpec::from_model(&system.model());
        let text = serde_json::to_string_pretty(&spec).expect("a model spec serialises");
        write_output(path, o.force, &(text + "\n"))?;
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
