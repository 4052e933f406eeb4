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
                path => fmi2_cosim::parameter_set::read_json(path)?,
            };
            PiezoControllerFmu::with_params(params).map_err(|e| format!("{preset}: {e}"))
        },
    )
}
