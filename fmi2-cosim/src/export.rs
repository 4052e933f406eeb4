//! The macro that exports a model's FMI 2.0 entry points.

/// Exports every FMI 2.0 common and co-simulation function for `$model`
/// (a type implementing [`CoSimModel`](crate::model::CoSimModel)) under its
/// standard, unprefixed name, as a binary FMU needs; with `model_exchange`,
/// the Model Exchange functions too, for a model that also implements
/// [`ModelExchange`](crate::model_exchange::ModelExchange) (one binary serves
/// both interfaces, as the Reference FMUs do).
///
/// Each exported function is also checked at compile time against the
/// corresponding typedef of the official `fmi2FunctionTypes.h` (through
/// fmi-sys's bindings): a signature that drifts from the standard does not
/// compile; and the model's `MODEL_EXCHANGE` declaration must agree with the
/// form used. Use it once per cdylib.
#[macro_export]
macro_rules! export_fmi2 {
    ($model:ty) => {
        $crate::__export_fmi2_common!($model);
        const _: () = assert!(
            <$model as $crate::CoSimModel>::MODEL_EXCHANGE.is_none(),
            "the model declares Model Exchange: export it with export_fmi2!(Model, model_exchange)"
        );
    };
    ($model:ty, model_exchange) => {
        $crate::__export_fmi2_common!($model);
        $crate::__export_fmi2_model_exchange!($model);
        const _: () = assert!(
            <$model as $crate::CoSimModel>::MODEL_EXCHANGE.is_some(),
            "export_fmi2!(Model, model_exchange) needs CoSimModel::MODEL_EXCHANGE = Some(..)"
        );
    };
}

/// The common and co-simulation exports of [`export_fmi2!`].
#[doc(hidden)]
#[macro_export]
macro_rules! __export_fmi2_common {
    ($model:ty) => {
        mod __fmi2_exports {
            #![allow(non_snake_case)]
            use super::*;
            use $crate::abi;
            use $crate::fmi_sys::fmi2::*;

            type Model = $model;

            #[unsafe(no_mangle)]
            pub extern "C" fn fmi2GetTypesPlatform() -> *const ::std::ffi::c_char {
                abi::get_types_platform()
            }
            #[unsafe(no_mangle)]
            pub extern "C" fn fmi2GetVersion() -> *const ::std::ffi::c_char {
                abi::get_version()
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetDebugLogging(
                c: fmi2Component,
                loggingOn: fmi2Boolean,
                nCategories: usize,
                categories: *const fmi2String,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_debug_logging::<Model>(c, loggingOn, nCategories, categories) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2Instantiate(
                instanceName: fmi2String,
                fmuType: fmi2Type,
                fmuGUID: fmi2String,
                fmuResourceLocation: fmi2String,
                functions: *const fmi2CallbackFunctions,
                visible: fmi2Boolean,
                loggingOn: fmi2Boolean,
            ) -> fmi2Component {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe {
                    abi::instantiate::<Model>(
                        instanceName,
                        fmuType,
                        fmuGUID,
                        fmuResourceLocation,
                        functions,
                        visible,
                        loggingOn,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2FreeInstance(c: fmi2Component) {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::free_instance::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetupExperiment(
                c: fmi2Component,
                toleranceDefined: fmi2Boolean,
                tolerance: fmi2Real,
                startTime: fmi2Real,
                stopTimeDefined: fmi2Boolean,
                stopTime: fmi2Real,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe {
                    abi::setup_experiment::<Model>(
                        c,
                        toleranceDefined,
                        tolerance,
                        startTime,
                        stopTimeDefined,
                        stopTime,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterInitializationMode(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::enter_initialization_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2ExitInitializationMode(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::exit_initialization_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2Terminate(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::terminate::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2Reset(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::reset::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Real,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_real::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Integer,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_integer::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Boolean,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_boolean::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2String,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_string::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Real,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_real::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Integer,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_integer::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Boolean,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_boolean::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2String,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_string::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetFMUstate(
                c: fmi2Component,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetFMUstate(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2FreeFMUstate(
                c: fmi2Component,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::free_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
                size: *mut usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::serialized_fmu_state_size::<Model>(c, FMUstate, size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SerializeFMUstate(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
                serializedState: *mut fmi2Byte,
                size: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::serialize_fmu_state::<Model>(c, FMUstate, serializedState, size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
                c: fmi2Component,
                serializedState: *const fmi2Byte,
                size: usize,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::deserialize_fmu_state::<Model>(c, serializedState, size, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
                c: fmi2Component,
                vUnknown_ref: *const fmi2ValueReference,
                nUnknown: usize,
                vKnown_ref: *const fmi2ValueReference,
                nKnown: usize,
                dvKnown: *const fmi2Real,
                dvUnknown: *mut fmi2Real,
            ) -> fmi2Status {
                let _ = (
                    vUnknown_ref,
                    nUnknown,
                    vKnown_ref,
                    nKnown,
                    dvKnown,
                    dvUnknown,
                );
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_directional_derivative::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                order: *const fmi2Integer,
                value: *const fmi2Real,
            ) -> fmi2Status {
                let _ = (vr, nvr, order, value);
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::set_real_input_derivatives::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                order: *const fmi2Integer,
                value: *mut fmi2Real,
            ) -> fmi2Status {
                let _ = (vr, nvr, order, value);
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_real_output_derivatives::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2DoStep(
                c: fmi2Component,
                currentCommunicationPoint: fmi2Real,
                communicationStepSize: fmi2Real,
                noSetFMUStatePriorToCurrentPoint: fmi2Boolean,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe {
                    abi::do_step::<Model>(
                        c,
                        currentCommunicationPoint,
                        communicationStepSize,
                        noSetFMUStatePriorToCurrentPoint,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2CancelStep(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::cancel_step::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Status,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetRealStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Real,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_real_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetIntegerStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Integer,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_integer_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetBooleanStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Boolean,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_boolean_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetStringStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2String,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { abi::get_string_status::<Model>(c, s, value) }
            }

            // Every export has exactly the type of the official typedef, and
            // the exports are the list of `functions::ALL` (checked at compile
            // time).
            $crate::__fmi2_signatures! {
                $crate::functions::EXPORTED_FUNCTIONS;
                fmi2GetTypesPlatform: fmi2GetTypesPlatformTYPE,
                fmi2GetVersion: fmi2GetVersionTYPE,
                fmi2SetDebugLogging: fmi2SetDebugLoggingTYPE,
                fmi2Instantiate: fmi2InstantiateTYPE,
                fmi2FreeInstance: fmi2FreeInstanceTYPE,
                fmi2SetupExperiment: fmi2SetupExperimentTYPE,
                fmi2EnterInitializationMode: fmi2EnterInitializationModeTYPE,
                fmi2ExitInitializationMode: fmi2ExitInitializationModeTYPE,
                fmi2Terminate: fmi2TerminateTYPE,
                fmi2Reset: fmi2ResetTYPE,
                fmi2GetReal: fmi2GetRealTYPE,
                fmi2GetInteger: fmi2GetIntegerTYPE,
                fmi2GetBoolean: fmi2GetBooleanTYPE,
                fmi2GetString: fmi2GetStringTYPE,
                fmi2SetReal: fmi2SetRealTYPE,
                fmi2SetInteger: fmi2SetIntegerTYPE,
                fmi2SetBoolean: fmi2SetBooleanTYPE,
                fmi2SetString: fmi2SetStringTYPE,
                fmi2GetFMUstate: fmi2GetFMUstateTYPE,
                fmi2SetFMUstate: fmi2SetFMUstateTYPE,
                fmi2FreeFMUstate: fmi2FreeFMUstateTYPE,
                fmi2SerializedFMUstateSize: fmi2SerializedFMUstateSizeTYPE,
                fmi2SerializeFMUstate: fmi2SerializeFMUstateTYPE,
                fmi2DeSerializeFMUstate: fmi2DeSerializeFMUstateTYPE,
                fmi2GetDirectionalDerivative: fmi2GetDirectionalDerivativeTYPE,
                fmi2SetRealInputDerivatives: fmi2SetRealInputDerivativesTYPE,
                fmi2GetRealOutputDerivatives: fmi2GetRealOutputDerivativesTYPE,
                fmi2DoStep: fmi2DoStepTYPE,
                fmi2CancelStep: fmi2CancelStepTYPE,
                fmi2GetStatus: fmi2GetStatusTYPE,
                fmi2GetRealStatus: fmi2GetRealStatusTYPE,
                fmi2GetIntegerStatus: fmi2GetIntegerStatusTYPE,
                fmi2GetBooleanStatus: fmi2GetBooleanStatusTYPE,
                fmi2GetStringStatus: fmi2GetStringStatusTYPE,
            }
        }
    };
}

/// The Model Exchange exports of [`export_fmi2!`].
#[doc(hidden)]
#[macro_export]
macro_rules! __export_fmi2_model_exchange {
    ($model:ty) => {
        mod __fmi2_model_exchange_exports {
            #![allow(non_snake_case)]
            use super::*;
            use $crate::abi::model_exchange as me;
            use $crate::fmi_sys::fmi2::*;

            type Model = $model;

            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterEventMode(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::enter_event_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2NewDiscreteStates(
                c: fmi2Component,
                fmi2eventInfo: *mut fmi2EventInfo,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::new_discrete_states::<Model>(c, fmi2eventInfo) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterContinuousTimeMode(c: fmi2Component) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::enter_continuous_time_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2CompletedIntegratorStep(
                c: fmi2Component,
                noSetFMUStatePriorToCurrentPoint: fmi2Boolean,
                enterEventMode: *mut fmi2Boolean,
                terminateSimulation: *mut fmi2Boolean,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe {
                    me::completed_integrator_step::<Model>(
                        c,
                        noSetFMUStatePriorToCurrentPoint,
                        enterEventMode,
                        terminateSimulation,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetTime(c: fmi2Component, time: fmi2Real) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::set_time::<Model>(c, time) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetContinuousStates(
                c: fmi2Component,
                x: *const fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::set_continuous_states::<Model>(c, x, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetDerivatives(
                c: fmi2Component,
                derivatives: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::get_derivatives::<Model>(c, derivatives, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetEventIndicators(
                c: fmi2Component,
                eventIndicators: *mut fmi2Real,
                ni: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::get_event_indicators::<Model>(c, eventIndicators, ni) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetContinuousStates(
                c: fmi2Component,
                x: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::get_continuous_states::<Model>(c, x, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetNominalsOfContinuousStates(
                c: fmi2Component,
                x_nominal: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                // SAFETY: the importer's arguments, passed on under the standard's
                // contract for this function (the callee's `# Safety`).
                unsafe { me::get_nominals_of_continuous_states::<Model>(c, x_nominal, nx) }
            }

            // Every export has exactly the type of the official typedef, and
            // the exports are the list of `functions::ALL` (checked at compile
            // time).
            $crate::__fmi2_signatures! {
                $crate::functions::MODEL_EXCHANGE_FUNCTIONS;
                fmi2EnterEventMode: fmi2EnterEventModeTYPE,
                fmi2NewDiscreteStates: fmi2NewDiscreteStatesTYPE,
                fmi2EnterContinuousTimeMode: fmi2EnterContinuousTimeModeTYPE,
                fmi2CompletedIntegratorStep: fmi2CompletedIntegratorStepTYPE,
                fmi2SetTime: fmi2SetTimeTYPE,
                fmi2SetContinuousStates: fmi2SetContinuousStatesTYPE,
                fmi2GetDerivatives: fmi2GetDerivativesTYPE,
                fmi2GetEventIndicators: fmi2GetEventIndicatorsTYPE,
                fmi2GetContinuousStates: fmi2GetContinuousStatesTYPE,
                fmi2GetNominalsOfContinuousStates: fmi2GetNominalsOfContinuousStatesTYPE,
            }
        }
    };
}

/// Checks each `function: typedef` pair of an export module at compile time
/// (the function has exactly the type of the official typedef), and that the
/// functions are, in order, the `expected` names drawn from
/// [`functions::ALL`](crate::functions::ALL): a function exported here and
/// not listed there, or listed there and not exported, does not compile.
#[doc(hidden)]
#[macro_export]
macro_rules! __fmi2_signatures {
    ($expected:expr; $($function:ident: $typedef:ident),* $(,)?) => {
        const _: () = {
            $(let _: $typedef = Some($function);)*
        };
        /// The functions this module exports, in order.
        #[allow(dead_code)]
        pub const EXPORTED: &[&str] = &[$(stringify!($function)),*];
        const _: () = assert!(
            $crate::functions::same_names(EXPORTED, &$expected),
            "the exported functions differ from fmi2_cosim::functions::ALL"
        );
    };
}
