//! The Feedthrough fixture, driven through the C ABI as an importer drives it:
//! every state-machine and argument rule of the FMI layer, on a model with a
//! variable of every type, causality and variability the layer serves
//! (String variables, the independent variable and a constant included).

fmi2_conformance::conformance_tests!(
    fmi2_conformance::workspace::load::<fmu_fixture::Feedthrough>("fmu-fixture"),
    strings_time_constants
);
