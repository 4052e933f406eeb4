//! Writes PiezoController's parameter values for a preset by FMI name (JSON),
//! as an importer sets them before initialization: `stage` (the start
//! values), `paper` (seed 000 as printed), or a ControllerParams JSON file
//! (e.g. `piezo-models/presets/piezo_controller_xy200s.json`).

use fmu_controller::PiezoControllerFmu;
use piezo_models::ControllerParams;

fn main() -> std::process::ExitCode {
    fmi2_cosim::parameter_set::main::<PiezoControllerFmu>(
        "stage, paper or a ControllerParams JSON file",
        |preset| {
            let params = match preset {
                "stage" => ControllerParams::stage(),
                "paper" => ControllerParams::paper(),
                path => {
                    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
                    serde_json::from_str(&text)
                        .map_err(|e| format!("{path}:{}:{}: {e}", e.line(), e.column()))?
                }
            };
            PiezoControllerFmu::with_params(params).map_err(|e| format!("{preset}: {e}"))
        },
    )
}
