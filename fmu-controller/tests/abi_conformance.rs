//! The PiezoController binary, driven through the C ABI as an importer drives
//! it (dlopen, official typedefs, printf-style logger): every state-machine and
//! argument rule of the FMI layer.

fmi2_conformance::conformance_tests!(fmi2_conformance::workspace::load::<
    fmu_controller::PiezoControllerFmu,
>("fmu-controller"));
