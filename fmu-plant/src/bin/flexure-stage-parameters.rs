//! Writes FlexureStage's parameter values for a preset by FMI name (JSON), as
//! an importer sets them before initialization: `3dof` (seed 000's 3-DOF stage,
//! the start values), `xy200s` (seed 001's XY200S stage), or a
//! FlexureStageParams JSON file.

use fmu_plant::FlexureStageFmu;
use piezo_models::FlexureStageParams;

fn main() -> std::process::ExitCode {
    fmi2_cosim::parameter_set::main::<FlexureStageFmu>(
        "3dof, xy200s or a FlexureStageParams JSON file",
        |preset| {
            let params = match preset {
                "3dof" => FlexureStageParams::default(),
                "xy200s" => FlexureStageParams::xy200s(),
                path => fmi2_cosim::parameter_set::read_json(path)?,
            };
            FlexureStageFmu::with_params(params).map_err(|e| format!("{preset}: {e}"))
        },
    )
}
