//! The FMI 2.0 functions, once: every name [`export_fmi2!`](crate::export_fmi2)
//! exports, with the interface it belongs to. The state table
//! ([`FmiFunction`]) takes its names and interfaces from [`ALL`] at compile
//! time, the export macro checks its exports against it at compile time, and
//! the importer-side checks read it.

use crate::status::{FmiFunction, Interface};

/// Which interfaces offer a function (FMI 2.0.4 §2.1, §3.2, §4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Interfaces {
    /// Common to Model Exchange and Co-Simulation (§2.1).
    Both,
    /// Co-Simulation only (§4.2).
    CoSimulation,
    /// Model Exchange only (§3.2).
    ModelExchange,
}

impl Interfaces {
    /// Whether an instance of `interface` may call the function.
    pub const fn include(self, interface: Interface) -> bool {
        match self {
            Interfaces::Both => true,
            Interfaces::CoSimulation => matches!(interface, Interface::CoSimulation),
            Interfaces::ModelExchange => matches!(interface, Interface::ModelExchange),
        }
    }

    /// The one interface of an interface-specific function; `None` for a
    /// common one (the convention of [`FmiFunction::interface`]).
    pub const fn only(self) -> Option<Interface> {
        match self {
            Interfaces::Both => None,
            Interfaces::CoSimulation => Some(Interface::CoSimulation),
            Interfaces::ModelExchange => Some(Interface::ModelExchange),
        }
    }
}

/// One FMI 2.0 function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Function {
    /// The C name (`fmi2DoStep`).
    pub name: &'static str,
    pub interfaces: Interfaces,
    /// The entry of the state table, for the functions that take an instance
    /// (all but `fmi2GetTypesPlatform`, `fmi2GetVersion`, `fmi2Instantiate`).
    pub state_checked: Option<FmiFunction>,
}

const fn common(name: &'static str, state_checked: Option<FmiFunction>) -> Function {
    Function {
        name,
        interfaces: Interfaces::Both,
        state_checked,
    }
}

const fn co_simulation(name: &'static str, function: FmiFunction) -> Function {
    Function {
        name,
        interfaces: Interfaces::CoSimulation,
        state_checked: Some(function),
    }
}

const fn model_exchange(name: &'static str, function: FmiFunction) -> Function {
    Function {
        name,
        interfaces: Interfaces::ModelExchange,
        state_checked: Some(function),
    }
}

use FmiFunction as F;

/// Every FMI 2.0 function, in the order of the standard's header
/// `fmi2Functions.h`: the common ones, then Co-Simulation, then Model
/// Exchange. `export_fmi2!(Model)` exports the first two groups,
/// `export_fmi2!(Model, model_exchange)` all of them.
pub const ALL: [Function; 44] = [
    common("fmi2GetTypesPlatform", None),
    common("fmi2GetVersion", None),
    common("fmi2SetDebugLogging", Some(F::SetDebugLogging)),
    common("fmi2Instantiate", None),
    common("fmi2FreeInstance", Some(F::FreeInstance)),
    common("fmi2SetupExperiment", Some(F::SetupExperiment)),
    common(
        "fmi2EnterInitializationMode",
        Some(F::EnterInitializationMode),
    ),
    common(
        "fmi2ExitInitializationMode",
        Some(F::ExitInitializationMode),
    ),
    common("fmi2Terminate", Some(F::Terminate)),
    common("fmi2Reset", Some(F::Reset)),
    common("fmi2GetReal", Some(F::GetReal)),
    common("fmi2GetInteger", Some(F::GetInteger)),
    common("fmi2GetBoolean", Some(F::GetBoolean)),
    common("fmi2GetString", Some(F::GetString)),
    common("fmi2SetReal", Some(F::SetReal)),
    common("fmi2SetInteger", Some(F::SetInteger)),
    common("fmi2SetBoolean", Some(F::SetBoolean)),
    common("fmi2SetString", Some(F::SetString)),
    common("fmi2GetFMUstate", Some(F::GetFmuState)),
    common("fmi2SetFMUstate", Some(F::SetFmuState)),
    common("fmi2FreeFMUstate", Some(F::FreeFmuState)),
    common(
        "fmi2SerializedFMUstateSize",
        Some(F::SerializedFmuStateSize),
    ),
    common("fmi2SerializeFMUstate", Some(F::SerializeFmuState)),
    common("fmi2DeSerializeFMUstate", Some(F::DeSerializeFmuState)),
    common(
        "fmi2GetDirectionalDerivative",
        Some(F::GetDirectionalDerivative),
    ),
    co_simulation("fmi2SetRealInputDerivatives", F::SetRealInputDerivatives),
    co_simulation("fmi2GetRealOutputDerivatives", F::GetRealOutputDerivatives),
    co_simulation("fmi2DoStep", F::DoStep),
    co_simulation("fmi2CancelStep", F::CancelStep),
    co_simulation("fmi2GetStatus", F::GetStatus),
    co_simulation("fmi2GetRealStatus", F::GetRealStatus),
    co_simulation("fmi2GetIntegerStatus", F::GetIntegerStatus),
    co_simulation("fmi2GetBooleanStatus", F::GetBooleanStatus),
    co_simulation("fmi2GetStringStatus", F::GetStringStatus),
    model_exchange("fmi2EnterEventMode", F::EnterEventMode),
    model_exchange("fmi2NewDiscreteStates", F::NewDiscreteStates),
    model_exchange("fmi2EnterContinuousTimeMode", F::EnterContinuousTimeMode),
    model_exchange("fmi2CompletedIntegratorStep", F::CompletedIntegratorStep),
    model_exchange("fmi2SetTime", F::SetTime),
    model_exchange("fmi2SetContinuousStates", F::SetContinuousStates),
    model_exchange("fmi2GetDerivatives", F::GetDerivatives),
    model_exchange("fmi2GetEventIndicators", F::GetEventIndicators),
    model_exchange("fmi2GetContinuousStates", F::GetContinuousStates),
    model_exchange(
        "fmi2GetNominalsOfContinuousStates",
        F::GetNominalsOfContinuousStates,
    ),
];

/// The names of the functions in [`ALL`] whose interfaces are `wanted`, in
/// order; `N` must be their number (checked at compile time).
const fn names<const N: usize>(wanted: &[Interfaces]) -> [&'static str; N] {
    let mut out = [""; N];
    let mut filled = 0;
    let mut i = 0;
    while i < ALL.len() {
        let mut w = 0;
        while w < wanted.len() {
            if ALL[i].interfaces as u8 == wanted[w] as u8 {
                assert!(filled < N, "more functions than N");
                out[filled] = ALL[i].name;
                filled += 1;
            }
            w += 1;
        }
        i += 1;
    }
    assert!(filled == N, "fewer functions than N");
    out
}

/// Names of every common and co-simulation function `export_fmi2!` exports.
pub const EXPORTED_FUNCTIONS: [&str; 34] = names(&[Interfaces::Both, Interfaces::CoSimulation]);

/// Names of the Model Exchange functions that `export_fmi2!(Model,
/// model_exchange)` exports besides [`EXPORTED_FUNCTIONS`].
pub const MODEL_EXCHANGE_FUNCTIONS: [&str; 10] = names(&[Interfaces::ModelExchange]);

/// Whether `a` and `b` hold the same names in the same order (usable in
/// `const` assertions: the export macro checks its exports with it).
pub const fn same_names(a: &[&str], b: &[&str]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        let (x, y) = (a[i].as_bytes(), b[i].as_bytes());
        if x.len() != y.len() {
            return false;
        }
        let mut k = 0;
        while k < x.len() {
            if x[k] != y[k] {
                return false;
            }
            k += 1;
        }
        i += 1;
    }
    true
}

/// The function named `name`, if FMI 2.0 has one.
pub fn by_name(name: &str) -> Option<&'static Function> {
    ALL.iter().find(|f| f.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn names_are_unique() {
        let names: HashSet<&str> = ALL.iter().map(|f| f.name).collect();
        assert_eq!(names.len(), ALL.len());
    }

    /// The state table is built from the list (`status::state_table`):
    /// every function that takes an instance is in it under its own name and
    /// interface.
    #[test]
    fn the_state_table_is_the_list() {
        let checked: Vec<FmiFunction> = ALL.iter().filter_map(|f| f.state_checked).collect();
        assert_eq!(checked, FmiFunction::ALL);
        for f in ALL.iter().filter(|f| f.state_checked.is_some()) {
            let function = f.state_checked.unwrap();
            assert_eq!(function.name(), f.name);
            assert_eq!(function.interface(), f.interfaces.only());
        }
        assert_eq!(FmiFunction::DoStep.name(), "fmi2DoStep");
        assert_eq!(
            FmiFunction::SetTime.interface(),
            Some(Interface::ModelExchange)
        );
        assert_eq!(FmiFunction::GetReal.interface(), None);
    }

    #[test]
    fn exported_lists_follow_the_interfaces() {
        assert!(EXPORTED_FUNCTIONS.contains(&"fmi2DoStep"));
        assert!(!EXPORTED_FUNCTIONS.contains(&"fmi2SetTime"));
        assert!(MODEL_EXCHANGE_FUNCTIONS.contains(&"fmi2SetTime"));
        assert_eq!(
            EXPORTED_FUNCTIONS.len() + MODEL_EXCHANGE_FUNCTIONS.len(),
            ALL.len()
        );
        assert_eq!(
            by_name("fmi2GetRealStatus").map(|f| f.interfaces),
            Some(Interfaces::CoSimulation)
        );
        assert!(by_name("fmi2Nonsense").is_none());
    }

    #[test]
    fn same_names_compares_order_and_content() {
        assert!(same_names(&["a", "bc"], &["a", "bc"]));
        assert!(!same_names(&["a", "bc"], &["bc", "a"]));
        assert!(!same_names(&["a", "bc"], &["a", "bd"]));
        assert!(!same_names(&["a"], &["a", "bc"]));
    }
}
