//! `sysid simulate --model M --data D`: a model's response to a record's inputs.

use super::simulate_args::Options;
use crate::error::CliError;
use crate::files::{create_output, fmt, read_model_file};
use nalgebra::DVector;
use rand::SeedableRng;
use std::io::Write;
use sysid::kalman::{Record, fit_percent};

pub fn run(o: &Options) -> Result<(), CliError> {
    if let Some(path) = o
        .model
        .as_deref()
        .filter(|p| super::nonlinear::is_model_file(p))
    {
        return run_model_file(o, path);
    }
    let (Some(model_path), Some(data_path)) = (&o.model, &o.data) else {
        return Err(CliError::BadOption {
            option: "simulate",
            message: "give a system name (lgss, lti2x2, nlbench, wiener), or --model with --data"
                .into(),
        });
    };
    crate::files::check_outputs(std::iter::once(o.out.as_path()), o.force)?;
    let stored = read_model_file(model_path)?;
    // the model's columns (outputs only if the file has them), its linear trend removed
    let data = crate::DataArgs {
        data: data_path.clone(),
        inputs: None,
        outputs: None,
        range: o.range.clone(),
        ts: None,
    };
    let file = data.read_for_model(&stored, true)?;
    let model = stored.model;
    super::check_column_counts(&file, model.m(), file.output_names.len())?;
    let has_outputs = !file.output_names.is_empty();
    if has_outputs {
        super::check_columns(&model, &file)?;
    }
    let x0_choice =
        o.x0.as_deref()
            .unwrap_or(if has_outputs { "estimate" } else { "model" });
    let model_error = |source| CliError::Model {
        path: model_path.clone(),
        source,
    };
    // the record the simulation runs on: the data's inputs, outputs if there are any
    let record = if has_outputs {
        file.record.clone()
    } else {
        Record::new(
            file.record.u.clone(),
            nalgebra::DMatrix::from_element(model.p(), file.record.len(), f64::NAN),
        )
    };
    let x0 = match x0_choice {
        "estimate" if !has_outputs => {
            return Err(CliError::BadOption {
                option: "--x0",
                message: format!(
                    "estimate needs the record's outputs; {} has none (use model or zero)",
                    data_path.display()
                ),
            });
        }
        "estimate" => {
            model
                .response(&record, None)
                .map_err(model_error)?
                .initial_state
        }
        // the file's initial state for this record (a stationary one at its first input)
        "model" => stored
            .initial
            .apply_to_record(&model, &record)
            .map_err(model_error)?
            .mu()
            .clone(),
        "zero" => DVector::zeros(model.n()),
        other => {
            return Err(CliError::BadOption {
                option: "--x0",
                message: format!("unknown initial state {other:?} (known: estimate, model, zero)"),
            });
        }
    };
    let outputs = if o.noise {
        // a realisation: the noise of the model, from x0 (no initial uncertainty)
        let start = model
            .to_builder()
            .mu(x0.clone())
            .p1(nalgebra::DMatrix::zeros(model.n(), model.n()))
            .diffuse(nalgebra::DMatrix::zeros(model.n(), 0))
            .build()
            .map_err(model_error)?;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(o.seed);
        start
            .simulate(&record.u, &mut rng)
            .map_err(model_error)?
            .record
            .y
    } else {
        model
            .response(&record, Some(&x0))
            .map_err(model_error)?
            .outputs
    };
    // in the file's units (a model fitted with --detrend linear)
    let outputs = file.restored(&outputs);
    let inputs = match &file.trend {
        Some(trend) => &record.u + trend.inputs_at(&file.time),
        None => record.u.clone(),
    };
    let names = output_names(&file, stored.metadata.as_ref(), model.p());
    write_response(o, &file, &names, &inputs, &outputs)?;
    let fit = has_outputs.then(|| fit_percent(&file.measured(), &outputs, 0));
    crate::report(
        o.json,
        serde_json::json!({
            "command": "simulate", "model": model_path, "data": data_path,
            "steps": record.len(), "x0": x0.iter().collect::<Vec<_>>(), "x0_from": x0_choice,
            "noise": o.noise, "seed": o.noise.then_some(o.seed), "outputs": names,
            "fit_percent": fit, "out": o.out,
        }),
        || {
            let fit_text = fit
                .as_ref()
                .map(|f| {
                    let per: Vec<String> = names
                        .iter()
                        .zip(f)
                        .map(|(n, v)| format!("{n} {v:.2} %"))
                        .collect();
                    format!(" (fit to the record: {})", per.join(", "))
                })
                .unwrap_or_default();
            format!(
                "wrote the {} response of {} to {}{fit_text}",
                if o.noise { "noisy" } else { "noise-free" },
                model_path.display(),
                o.out.display()
            )
        },
    );
    Ok(())
}

/// The names of the simulated outputs: the record's, else the model file's, else
/// `y1..yp`.
fn output_names(
    file: &crate::files::DataFile,
    metadata: Option<&sysid::kalman::Metadata>,
    p: usize,
) -> Vec<String> {
    let stored = metadata
        .map(|m| m.outputs.clone())
        .filter(|names| names.len() == p);
    if !file.output_names.is_empty() {
        file.output_names.clone()
    } else if let Some(names) = stored {
        names
    } else {
        (1..=p).map(|i| format!("y{i}")).collect()
    }
}

/// Writes the record's times and inputs with the simulated outputs.
fn write_response(
    o: &Options,
    file: &crate::files::DataFile,
    names: &[String],
    inputs: &nalgebra::DMatrix<f64>,
    outputs: &nalgebra::DMatrix<f64>,
) -> Result<(), CliError> {
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    let mut header = vec!["t".to_string()];
    header.extend(file.input_names.iter().cloned());
    header.extend(names.iter().cloned());
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for t in 0..inputs.ncols() {
        let mut row = vec![file.label(t)];
        row.extend(inputs.column(t).iter().map(|&v| fmt(v)));
        row.extend(outputs.column(t).iter().map(|&v| fmt(v)));
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    Ok(())
}

/// `sysid simulate --model m.toml [--data inputs.csv]`: one realisation of a nonlinear
/// model file at its parameters' values, from the random stream `(seed, 0)`.
fn run_model_file(o: &Options, path: &std::path::Path) -> Result<(), CliError> {
    crate::files::check_outputs(std::iter::once(o.out.as_path()), o.force)?;
    if o.model_out.is_some() || o.x0.is_some() || o.noise {
        return Err(CliError::BadOption {
            option: if o.model_out.is_some() {
                "--model-out"
            } else if o.x0.is_some() {
                "--x0"
            } else {
                "--noise"
            },
            message: "does not apply to a nonlinear model file (it is simulated with its \
                      noise, from its initial law)"
                .into(),
        });
    }
    let file = super::nonlinear::read(path)?;
    let spec = file.spec();
    let smc = file
        .at(&file.free_values())
        .map_err(|message| CliError::BadOption {
            option: "--model",
            message: format!("{}: {message}", path.display()),
        })?;
    let (steps, inputs, time) = match &o.data {
        Some(data_path) => {
            let data = crate::DataArgs {
                data: data_path.clone(),
                inputs: (!spec.inputs.is_empty()).then(|| spec.inputs.clone()),
                outputs: Some(Vec::new()),
                range: o.range.clone(),
                ts: None,
            };
            // the model's input names, else the default ones (u1, ...); a bad cell is
            // the file's fault either way
            let record = match data.read() {
                Err(CliError::UnknownColumn { .. }) => crate::DataArgs {
                    inputs: None,
                    ..data.clone()
                }
                .read(),
                read => read,
            }?;
            super::check_column_counts(&record, spec.inputs.len(), 0)?;
            let u: Vec<f64> = record.record.u.iter().copied().collect();
            (record.record.len(), u, record.time.clone())
        }
        None if !spec.inputs.is_empty() => {
            return Err(CliError::BadOption {
                option: "--data",
                message: format!(
                    "{} has inputs ({}): give a record of them with --data",
                    path.display(),
                    spec.inputs.join(", ")
                ),
            });
        }
        None => {
            // the times, the states and outputs, before any of them is allocated
            let (n, p) = (spec.states.len(), spec.outputs.len());
            crate::resources::check_memory(
                "--steps",
                &format!("{} steps", o.steps),
                8.0 * o.steps as f64 * ((n + p) as f64 * 2.0 + 1.0),
            )?;
            (
                o.steps,
                Vec::new(),
                (1..=o.steps).map(|t| t as f64).collect(),
            )
        }
    };
    if steps == 0 {
        return Err(CliError::BadOption {
            option: "--steps",
            message: "must be at least 1".into(),
        });
    }
    let (n, p) = (spec.states.len(), spec.outputs.len());
    crate::resources::check_memory(
        "--steps",
        &format!("{steps} steps"),
        8.0 * steps as f64 * (n + p + spec.inputs.len()) as f64 * 2.0,
    )?;
    let simulated = if o.noise_free {
        file.simulate_noise_free(&inputs, steps, None)
            .map(|run| (run.states, run.outputs))
            .map_err(|e| e.to_string())
    } else {
        smc.simulate(steps, &inputs, o.seed)
            .map_err(|message| message.to_string())
    };
    let (states, outputs) = simulated.map_err(|message| CliError::BadOption {
        option: "--model",
        message: format!("{}: {message}", path.display()),
    })?;
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    let mut header = vec!["t".to_string()];
    header.extend(spec.inputs.iter().cloned());
    header.extend(spec.outputs.iter().cloned());
    if o.states {
        header.extend(spec.states.iter().cloned());
    }
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    let m = spec.inputs.len();
    for t in 0..steps {
        let mut row = vec![fmt(time[t])];
        row.extend(inputs[t * m..(t + 1) * m].iter().map(|&v| fmt(v)));
        row.extend(outputs[t * p..(t + 1) * p].iter().map(|&v| fmt(v)));
        if o.states {
            row.extend(states[t * n..(t + 1) * n].iter().map(|&v| fmt(v)));
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    crate::report(
        o.json,
        serde_json::json!({"command": "simulate", "model": path, "steps": steps,
            "seed": o.seed, "out": o.out, "noise_free": o.noise_free}),
        || {
            format!(
                "wrote {steps} {}steps of {} to {}",
                if o.noise_free { "noise-free " } else { "" },
                path.display(),
                o.out.display()
            )
        },
    );
    Ok(())
}
