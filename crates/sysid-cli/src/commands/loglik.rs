use super::in_data;
use crate::ModelOnData;
use crate::error::CliError;
use sysid::kalman::KalmanWorkspace;

pub fn run(source: &ModelOnData, json: bool) -> Result<(), CliError> {
    let (model, file) = source.load()?;
    let loglik = KalmanWorkspace::new()
        .loglik(&model, &file.record)
        .map_err(in_data(source.data_path()))?;
    let observed = file.record.y.iter().filter(|v| !v.is_nan()).count();
    if json {
        let out = serde_json::json!({
            "command": "loglik", "loglik": loglik, "steps": file.record.len(),
            "observed_values": observed, "missing_values": file.record.y.len() - observed,
            "outputs": file.output_names, "inputs": file.input_names,
            "diffuse_directions": model.diffuse().ncols(),
        });
        crate::say(&out.to_string());
    } else {
        crate::say(&loglik.to_string());
    }
    Ok(())
}
