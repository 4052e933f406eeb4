//! Conformance harness for FMI 2.0 binaries (co-simulation and Model Exchange).
//!
//! It loads an FMU as an importer does (the importer is `fmi2-import`, whose
//! items are re-exported here so that the checks and the FMU crates' tests
//! name them as before) and calls it in every order. Each check is a plain
//! function that panics with a reason; an FMU crate runs them all with
//! [`conformance_tests!`]. [`fuzz`] makes random call sequences.
//!
//! The legality tables in [`allowed_in`] and
//! [`model_exchange::allowed_in_model_exchange`] are written from the standard
//! (FMI 2.0.4, sections 4.2.4 and 3.2.3), independently of the layer under test.

pub use fmi2_import::*;

pub mod checks;
pub mod fuzz;
pub mod model_exchange;
pub mod table;
pub mod workspace;

/// `n` with its thousands separated by commas, as the documents in docs/
/// print counts (the fuzz report's table row, and the tests that compare
/// their counts with a document).
pub fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// The states the harness drives an instance into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    Instantiated,
    InitializationMode,
    StepComplete,
    Terminated,
    Error,
    /// Model Exchange only.
    EventMode,
    /// Model Exchange only.
    ContinuousTimeMode,
}

impl State {
    pub const ALL: [State; 7] = [
        State::Instantiated,
        State::InitializationMode,
        State::StepComplete,
        State::Terminated,
        State::Error,
        State::EventMode,
        State::ContinuousTimeMode,
    ];
    /// The states a co-simulation slave reaches (FMI 2.0.4 §4.2.4, without
    /// the asynchronous ones).
    pub const CO_SIMULATION: [State; 5] = [
        State::Instantiated,
        State::InitializationMode,
        State::StepComplete,
        State::Terminated,
        State::Error,
    ];
    /// The states a model-exchange model reaches (FMI 2.0.4 §3.2.3).
    pub const MODEL_EXCHANGE: [State; 6] = [
        State::Instantiated,
        State::InitializationMode,
        State::EventMode,
        State::ContinuousTimeMode,
        State::Terminated,
        State::Error,
    ];
}

/// The states of each interface's state machine that the harness drives an
/// instance into ([`Interface`] is the importer's; the states are the
/// harness's).
pub trait InterfaceStates {
    fn states(self) -> &'static [State];
}

impl InterfaceStates for Interface {
    fn states(self) -> &'static [State] {
        match self {
            Interface::ModelExchange => &State::MODEL_EXCHANGE,
            Interface::CoSimulation => &State::CO_SIMULATION,
        }
    }
}

/// What the checks ask of the FMU under test beyond what an importer needs.
pub trait FmuUnderTest {
    fn real_input(&self) -> &VariableInfo;
    fn fixed_real_parameter(&self) -> &VariableInfo;
    fn unknown_vr(&self) -> u32;
}

impl FmuUnderTest for Fmu {
    /// The first Real input.
    fn real_input(&self) -> &VariableInfo {
        self.with_causality(Causality::Input)
            .find(|v| v.kind == "Real")
            .expect("the FMU has a Real input")
    }

    /// The first fixed Real parameter.
    fn fixed_real_parameter(&self) -> &VariableInfo {
        self.with_causality(Causality::Parameter)
            .find(|v| v.kind == "Real" && v.variability == Some(Variability::Fixed))
            .expect("the FMU has a fixed Real parameter")
    }

    /// A value reference that no variable has.
    fn unknown_vr(&self) -> u32 {
        self.variables.iter().map(|v| v.vr).max().unwrap_or(0) + 1000
    }
}

/// Driving an instance into each state of the standard's state machine.
pub trait DriveTo {
    /// Drives a fresh instance into `state`.
    fn drive_to(&mut self, state: State);
}

impl DriveTo for Instance<'_> {
    fn drive_to(&mut self, state: State) {
        match state {
            State::Instantiated => {}
            State::InitializationMode => {
                assert_eq!(self.setup(0.0), OK);
                assert_eq!(self.enter_init(), OK);
            }
            State::StepComplete | State::EventMode => {
                assert_eq!(
                    self.interface,
                    if state == State::EventMode {
                        Interface::ModelExchange
                    } else {
                        Interface::CoSimulation
                    },
                    "{state:?} belongs to the other interface"
                );
                self.initialize();
            }
            State::ContinuousTimeMode => {
                self.initialize();
                assert_eq!(self.enter_continuous_time_mode(), OK);
            }
            State::Terminated => {
                self.initialize();
                assert_eq!(self.terminate(), OK);
            }
            State::Error => {
                self.initialize();
                // Entering initialization mode again is illegal after it.
                assert_eq!(self.enter_init(), ERROR);
            }
        }
        self.take_log();
    }
}

/// Whether the standard allows `function` on an instance of `interface` in
/// `state`.
pub fn allowed(interface: Interface, function: &str, state: State) -> bool {
    match interface {
        Interface::CoSimulation => allowed_in(function, state),
        Interface::ModelExchange => model_exchange::allowed_in_model_exchange(function, state),
    }
}

/// Whether the standard allows `function` in `state` (FMI 2.0.4, co-simulation
/// state machine). Written from the standard, not from the layer under test.
pub fn allowed_in(function: &str, state: State) -> bool {
    use State::*;
    if model_exchange::MODEL_EXCHANGE_FUNCTIONS.contains(&function) {
        // Not a function of a co-simulation slave in any state.
        return false;
    }
    let states: &[State] = match function {
        "fmi2SetDebugLogging"
        | "fmi2Reset"
        | "fmi2GetFMUstate"
        | "fmi2SetFMUstate"
        | "fmi2FreeFMUstate"
        | "fmi2SerializedFMUstateSize"
        | "fmi2SerializeFMUstate"
        | "fmi2DeSerializeFMUstate" => &[
            Instantiated,
            InitializationMode,
            StepComplete,
            Terminated,
            Error,
        ],
        "fmi2SetupExperiment" | "fmi2EnterInitializationMode" => &[Instantiated],
        "fmi2ExitInitializationMode" => &[InitializationMode],
        "fmi2Terminate" | "fmi2DoStep" => &[StepComplete],
        "fmi2GetReal"
        | "fmi2GetInteger"
        | "fmi2GetBoolean"
        | "fmi2GetString"
        | "fmi2GetDirectionalDerivative" => &[InitializationMode, StepComplete, Terminated, Error],
        "fmi2SetReal"
        | "fmi2SetInteger"
        | "fmi2SetBoolean"
        | "fmi2SetString"
        | "fmi2SetRealInputDerivatives" => &[Instantiated, InitializationMode, StepComplete],
        "fmi2GetRealOutputDerivatives" => &[StepComplete, Terminated, Error],
        "fmi2CancelStep" => &[],
        "fmi2GetStatus"
        | "fmi2GetRealStatus"
        | "fmi2GetIntegerStatus"
        | "fmi2GetBooleanStatus"
        | "fmi2GetStringStatus" => &[StepComplete, Terminated],
        other => panic!("no legality entry for {other}"),
    };
    states.contains(&state)
}

/// Defines one `#[test]` per conformance check for an FMU: `$fmu` is an
/// expression giving its [`Fmu`] (usually [`workspace::load`]), loaded once
/// for all of them. With no list, every co-simulation check; with
/// `model_exchange`, the Model Exchange checks as well; with
/// `strings_time_constants`, the checks of settable String variables, the
/// independent variable and constants, for an FMU that declares them; or the
/// checks named. A trailing `restore_cases => path` hands the cases
/// [`checks::fmu_state_restores_every_machine_state`] ran to the function
/// `path(&[checks::RestoreCases])`, for a test that compares them with the
/// number a document prints.
#[macro_export]
macro_rules! conformance_tests {
    ($fmu:expr, model_exchange $(, restore_cases => $restore_cases:path)?) => {
        $crate::conformance_tests!($fmu; @co_simulation [$($restore_cases)?]
            model_exchange_vectors_match_the_variables,
            model_exchange_arguments_are_checked,
            non_finite_derivatives_are_refused,
            derivative_dependencies_hold,
        );
    };
    ($fmu:expr, strings_time_constants $(, restore_cases => $restore_cases:path)?) => {
        $crate::conformance_tests!($fmu; @co_simulation [$($restore_cases)?]
            string_arguments_are_checked,
            independent_variable_is_the_time,
            constants_hold_their_start_values,
        );
    };
    ($fmu:expr; @co_simulation [$($restore_cases:path)?] $($more:ident),* $(,)?) => {
        #[test]
        fn fmu_state_restores_every_machine_state() {
            let _cases = $crate::checks::fmu_state_restores_every_machine_state(__conformance_fmu());
            $($restore_cases(&_cases);)?
        }
        $crate::conformance_tests!($fmu;
            exports_every_function_and_nothing_else,
            reports_platform_and_version,
            model_description_declares_capabilities,
            declared_dependencies_hold,
            instantiate_refuses_bad_arguments,
            resource_locations_in_every_spelling,
            state_machine_allows_exactly_the_standard_calls,
            free_instance_in_every_state,
            foreign_instance_pointers_are_refused,
            unknown_value_references_are_refused,
            type_mismatch_is_refused,
            null_arrays,
            non_finite_and_partial_sets_change_nothing,
            fixed_parameters_after_initialization,
            tunable_parameters_hold_their_ranges,
            only_parameters_and_inputs_are_settable,
            string_values_round_trip,
            step_sizes_must_be_positive_and_finite,
            communication_points_must_continue,
            fmu_state_restores_bit_for_bit,
            corrupted_states_are_refused,
            status_queries,
            reset_restores_start_values,
            logging_follows_debug_logging,
            instances_are_independent,
            instances_step_identically_in_threads,
            $($more,)*
        );
    };
    ($fmu:expr; $($check:ident),* $(,)?) => {
        fn __conformance_fmu() -> &'static $crate::Fmu {
            static FMU: ::std::sync::OnceLock<$crate::Fmu> = ::std::sync::OnceLock::new();
            FMU.get_or_init(|| $fmu)
        }
        $(
            #[test]
            fn $check() {
                $crate::checks::$check(__conformance_fmu());
            }
        )*
    };
    ($fmu:expr $(, restore_cases => $restore_cases:path)?) => {
        $crate::conformance_tests!($fmu; @co_simulation [$($restore_cases)?]);
    };
}

/// Reading Integer and Boolean values, which the importer's [`Instance`] does
/// not offer (its users exchange Reals).
pub trait GetDiscrete {
    fn get_integer(&self, vrs: &[u32]) -> (fmi_sys::fmi2::fmi2Status, Vec<i32>);
    /// Booleans as the FMU wrote them (`fmi2True` is 1).
    fn get_boolean(
        &self,
        vrs: &[u32],
    ) -> (fmi_sys::fmi2::fmi2Status, Vec<fmi_sys::fmi2::fmi2Boolean>);
}

impl GetDiscrete for Instance<'_> {
    fn get_integer(&self, vrs: &[u32]) -> (fmi_sys::fmi2::fmi2Status, Vec<i32>) {
        let mut values = vec![0; vrs.len()];
        // SAFETY: `self.c` is a live instance of the binding's FMU, and both
        // arrays hold `vrs.len()` elements.
        let status = unsafe {
            self.fmu
                .binding
                .fmi2GetInteger(self.c, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        };
        (status, values)
    }

    fn get_boolean(
        &self,
        vrs: &[u32],
    ) -> (fmi_sys::fmi2::fmi2Status, Vec<fmi_sys::fmi2::fmi2Boolean>) {
        let mut values = vec![0; vrs.len()];
        // SAFETY: as for `get_integer`.
        let status = unsafe {
            self.fmu
                .binding
                .fmi2GetBoolean(self.c, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        };
        (status, values)
    }
}

/// Reading and writing String values through `fmi2GetString` and
/// `fmi2SetString`, which the importer's [`Instance`] does not offer.
pub trait StringValues {
    /// `fmi2GetString`: the status, and with `fmi2OK` the strings, copied at
    /// once (they belong to the FMU until the next call on the instance).
    /// Panics, naming the value reference, when the FMU answers `fmi2OK`
    /// with a NULL pointer or with bytes that are not UTF-8.
    fn get_string(&self, vrs: &[u32]) -> (fmi_sys::fmi2::fmi2Status, Vec<String>);
    /// `fmi2SetString` of the texts (none may hold a NUL byte).
    fn set_string(&self, vrs: &[u32], texts: &[&str]) -> fmi_sys::fmi2::fmi2Status;
    /// `fmi2SetString` of raw element pointers: the arguments an importer
    /// may get wrong (NULL, bytes that are not UTF-8).
    ///
    /// # Safety
    /// Each element must be NULL or point to a NUL-terminated string alive
    /// for the call.
    unsafe fn set_string_raw(
        &self,
        vrs: &[u32],
        values: &[*const std::ffi::c_char],
    ) -> fmi_sys::fmi2::fmi2Status;
}

impl StringValues for Instance<'_> {
    fn get_string(&self, vrs: &[u32]) -> (fmi_sys::fmi2::fmi2Status, Vec<String>) {
        let mut pointers: Vec<fmi_sys::fmi2::fmi2String> = vec![std::ptr::null(); vrs.len()];
        // SAFETY: `self.c` is a live instance of the binding's FMU, and both
        // arrays hold `vrs.len()` elements.
        let status = unsafe {
            self.fmu
                .binding
                .fmi2GetString(self.c, vrs.as_ptr(), vrs.len(), pointers.as_mut_ptr())
        };
        if status != OK {
            return (status, Vec::new());
        }
        let texts = vrs
            .iter()
            .zip(&pointers)
            .map(|(vr, p)| {
                assert!(!p.is_null(), "fmi2GetString answered NULL for vr {vr}");
                // SAFETY: a string the FMU just returned with fmi2OK: non-NULL
                // (checked) and NUL-terminated, the FMU's until the next call
                // on the instance, and none was made since.
                let bytes = unsafe { std::ffi::CStr::from_ptr(*p) };
                bytes
                    .to_str()
                    .unwrap_or_else(|e| panic!("fmi2GetString of vr {vr} is not UTF-8: {e}"))
                    .to_owned()
            })
            .collect();
        (status, texts)
    }

    fn set_string(&self, vrs: &[u32], texts: &[&str]) -> fmi_sys::fmi2::fmi2Status {
        let owned: Vec<std::ffi::CString> = texts
            .iter()
            .map(|t| std::ffi::CString::new(*t).expect("no NUL in a text to set"))
            .collect();
        let pointers: Vec<*const std::ffi::c_char> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: every element points into `owned`, NUL-terminated C
        // strings alive until the end of this function.
        unsafe { self.set_string_raw(vrs, &pointers) }
    }

    unsafe fn set_string_raw(
        &self,
        vrs: &[u32],
        values: &[*const std::ffi::c_char],
    ) -> fmi_sys::fmi2::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: `self.c` is a live instance of the binding's FMU; both
        // arrays hold `vrs.len()` elements, each value NULL or a
        // NUL-terminated string alive for the call (this function's
        // contract).
        unsafe {
            self.fmu
                .binding
                .fmi2SetString(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        }
    }
}
