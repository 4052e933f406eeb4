//! The FlexureStage binary, driven through the C ABI as an importer drives it
//! (dlopen, official typedefs, printf-style logger): every state-machine and
//! argument rule of the FMI layer, for Co-Simulation and Model Exchange.

fmi2_conformance::conformance_tests!(
    fmi2_conformance::workspace::load::<fmu_plant::FlexureStageFmu>("fmu-plant"),
    model_exchange
);
