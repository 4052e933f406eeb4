//! Writes FlexureStage's parameter values for a preset by FMI name (JSON), as
//! an importer sets them before initialization: `3dof` (seed 000's 3-DOF stage,
//! the start values: its stacks close their minor loops, the modes calibrated
//! to the Ziegler-Nichols figures of the loop on the moving stage),
//! `3dof_memory` (the same stacks, the figures taken at a held point),
//! `3dof_no_memory` (seed 001's eq. (3) as integrated, the figures taken at a
//! held point: the default until the memory ran everywhere), `xy200s` (seed
//! 001's XY200S stage), or a FlexureStageParams JSON file.

use fmu_plant::FlexureStageFmu;
use piezo_models::FlexureStageParams;

fn main() -> std::process::ExitCode {
    fmi2_cosim::parameter_set::main::<FlexureStageFmu>(
        "3dof, 3dof_memory, 3dof_no_memory, xy200s or a FlexureStageParams JSON file",
        |preset| {
            let params = match preset {
                "3dof" => FlexureStageParams::default(),
                "3dof_memory" => FlexureStageParams::with_closed_minor_loops(),
                "3dof_no_memory" => FlexureStageParams::without_memory(),
                "xy200s" => FlexureStageParams::xy200s(),
                path => fmi2_cosim::parameter_set::read_json(path)?,
            };
            FlexureStageFmu::with_params(params).map_err(|e| format!("{preset}: {e}"))
        },
    )
}
