//! Writes PiezoController's modelDescription.xml and documentation/index.html,
//! generated from the variable table that the binary serves.

fn main() -> std::process::ExitCode {
    fmi2_cosim::describe::main::<fmu_controller::PiezoControllerFmu>(include_str!(
        "../../documentation/index.html"
    ))
}
