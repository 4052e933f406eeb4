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
                unsafe { abi::enter_initialization_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2ExitInitializationMode(c: fmi2Component) -> fmi2Status {
                unsafe { abi::exit_initialization_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2Terminate(c: fmi2Component) -> fmi2Status {
                unsafe { abi::terminate::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2Reset(c: fmi2Component) -> fmi2Status {
                unsafe { abi::reset::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Real,
            ) -> fmi2Status {
                unsafe { abi::get_real::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Integer,
            ) -> fmi2Status {
                unsafe { abi::get_integer::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2Boolean,
            ) -> fmi2Status {
                unsafe { abi::get_boolean::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *mut fmi2String,
            ) -> fmi2Status {
                unsafe { abi::get_string::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Real,
            ) -> fmi2Status {
                unsafe { abi::set_real::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Integer,
            ) -> fmi2Status {
                unsafe { abi::set_integer::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2Boolean,
            ) -> fmi2Status {
                unsafe { abi::set_boolean::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                nvr: usize,
                value: *const fmi2String,
            ) -> fmi2Status {
                unsafe { abi::set_string::<Model>(c, vr, nvr, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetFMUstate(
                c: fmi2Component,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
                unsafe { abi::get_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetFMUstate(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
            ) -> fmi2Status {
                unsafe { abi::set_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2FreeFMUstate(
                c: fmi2Component,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
                unsafe { abi::free_fmu_state::<Model>(c, FMUstate) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
                size: *mut usize,
            ) -> fmi2Status {
                unsafe { abi::serialized_fmu_state_size::<Model>(c, FMUstate, size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SerializeFMUstate(
                c: fmi2Component,
                FMUstate: fmi2FMUstate,
                serializedState: *mut fmi2Byte,
                size: usize,
            ) -> fmi2Status {
                unsafe { abi::serialize_fmu_state::<Model>(c, FMUstate, serializedState, size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
                c: fmi2Component,
                serializedState: *const fmi2Byte,
                size: usize,
                FMUstate: *mut fmi2FMUstate,
            ) -> fmi2Status {
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
                unsafe { abi::get_real_output_derivatives::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2DoStep(
                c: fmi2Component,
                currentCommunicationPoint: fmi2Real,
                communicationStepSize: fmi2Real,
                noSetFMUStatePriorToCurrentPoint: fmi2Boolean,
            ) -> fmi2Status {
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
                unsafe { abi::cancel_step::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Status,
            ) -> fmi2Status {
                unsafe { abi::get_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetRealStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Real,
            ) -> fmi2Status {
                unsafe { abi::get_real_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetIntegerStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Integer,
            ) -> fmi2Status {
                unsafe { abi::get_integer_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetBooleanStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2Boolean,
            ) -> fmi2Status {
                unsafe { abi::get_boolean_status::<Model>(c, s, value) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetStringStatus(
                c: fmi2Component,
                s: fmi2StatusKind,
                value: *mut fmi2String,
            ) -> fmi2Status {
                unsafe { abi::get_string_status::<Model>(c, s, value) }
            }

            // Every export has exactly the type of the official typedef.
            const _: () = {
                let _: fmi2GetTypesPlatformTYPE = Some(fmi2GetTypesPlatform);
                let _: fmi2GetVersionTYPE = Some(fmi2GetVersion);
                let _: fmi2SetDebugLoggingTYPE = Some(fmi2SetDebugLogging);
                let _: fmi2InstantiateTYPE = Some(fmi2Instantiate);
                let _: fmi2FreeInstanceTYPE = Some(fmi2FreeInstance);
                let _: fmi2SetupExperimentTYPE = Some(fmi2SetupExperiment);
                let _: fmi2EnterInitializationModeTYPE = Some(fmi2EnterInitializationMode);
                let _: fmi2ExitInitializationModeTYPE = Some(fmi2ExitInitializationMode);
                let _: fmi2TerminateTYPE = Some(fmi2Terminate);
                let _: fmi2ResetTYPE = Some(fmi2Reset);
                let _: fmi2GetRealTYPE = Some(fmi2GetReal);
                let _: fmi2GetIntegerTYPE = Some(fmi2GetInteger);
                let _: fmi2GetBooleanTYPE = Some(fmi2GetBoolean);
                let _: fmi2GetStringTYPE = Some(fmi2GetString);
                let _: fmi2SetRealTYPE = Some(fmi2SetReal);
                let _: fmi2SetIntegerTYPE = Some(fmi2SetInteger);
                let _: fmi2SetBooleanTYPE = Some(fmi2SetBoolean);
                let _: fmi2SetStringTYPE = Some(fmi2SetString);
                let _: fmi2GetFMUstateTYPE = Some(fmi2GetFMUstate);
                let _: fmi2SetFMUstateTYPE = Some(fmi2SetFMUstate);
                let _: fmi2FreeFMUstateTYPE = Some(fmi2FreeFMUstate);
                let _: fmi2SerializedFMUstateSizeTYPE = Some(fmi2SerializedFMUstateSize);
                let _: fmi2SerializeFMUstateTYPE = Some(fmi2SerializeFMUstate);
                let _: fmi2DeSerializeFMUstateTYPE = Some(fmi2DeSerializeFMUstate);
                let _: fmi2GetDirectionalDerivativeTYPE = Some(fmi2GetDirectionalDerivative);
                let _: fmi2SetRealInputDerivativesTYPE = Some(fmi2SetRealInputDerivatives);
                let _: fmi2GetRealOutputDerivativesTYPE = Some(fmi2GetRealOutputDerivatives);
                let _: fmi2DoStepTYPE = Some(fmi2DoStep);
                let _: fmi2CancelStepTYPE = Some(fmi2CancelStep);
                let _: fmi2GetStatusTYPE = Some(fmi2GetStatus);
                let _: fmi2GetRealStatusTYPE = Some(fmi2GetRealStatus);
                let _: fmi2GetIntegerStatusTYPE = Some(fmi2GetIntegerStatus);
                let _: fmi2GetBooleanStatusTYPE = Some(fmi2GetBooleanStatus);
                let _: fmi2GetStringStatusTYPE = Some(fmi2GetStringStatus);
            };
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
                unsafe { me::enter_event_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2NewDiscreteStates(
                c: fmi2Component,
                fmi2eventInfo: *mut fmi2EventInfo,
            ) -> fmi2Status {
                unsafe { me::new_discrete_states::<Model>(c, fmi2eventInfo) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterContinuousTimeMode(c: fmi2Component) -> fmi2Status {
                unsafe { me::enter_continuous_time_mode::<Model>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2CompletedIntegratorStep(
                c: fmi2Component,
                noSetFMUStatePriorToCurrentPoint: fmi2Boolean,
                enterEventMode: *mut fmi2Boolean,
                terminateSimulation: *mut fmi2Boolean,
            ) -> fmi2Status {
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
                unsafe { me::set_time::<Model>(c, time) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetContinuousStates(
                c: fmi2Component,
                x: *const fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                unsafe { me::set_continuous_states::<Model>(c, x, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetDerivatives(
                c: fmi2Component,
                derivatives: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                unsafe { me::get_derivatives::<Model>(c, derivatives, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetEventIndicators(
                c: fmi2Component,
                eventIndicators: *mut fmi2Real,
                ni: usize,
            ) -> fmi2Status {
                unsafe { me::get_event_indicators::<Model>(c, eventIndicators, ni) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetContinuousStates(
                c: fmi2Component,
                x: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                unsafe { me::get_continuous_states::<Model>(c, x, nx) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetNominalsOfContinuousStates(
                c: fmi2Component,
                x_nominal: *mut fmi2Real,
                nx: usize,
            ) -> fmi2Status {
                unsafe { me::get_nominals_of_continuous_states::<Model>(c, x_nominal, nx) }
            }

            // Every export has exactly the type of the official typedef.
            const _: () = {
                let _: fmi2EnterEventModeTYPE = Some(fmi2EnterEventMode);
                let _: fmi2NewDiscreteStatesTYPE = Some(fmi2NewDiscreteStates);
                let _: fmi2EnterContinuousTimeModeTYPE = Some(fmi2EnterContinuousTimeMode);
                let _: fmi2CompletedIntegratorStepTYPE = Some(fmi2CompletedIntegratorStep);
                let _: fmi2SetTimeTYPE = Some(fmi2SetTime);
                let _: fmi2SetContinuousStatesTYPE = Some(fmi2SetContinuousStates);
                let _: fmi2GetDerivativesTYPE = Some(fmi2GetDerivatives);
                let _: fmi2GetEventIndicatorsTYPE = Some(fmi2GetEventIndicators);
                let _: fmi2GetContinuousStatesTYPE = Some(fmi2GetContinuousStates);
                let _: fmi2GetNominalsOfContinuousStatesTYPE =
                    Some(fmi2GetNominalsOfContinuousStates);
            };
        }
    };
}

/// Names of the Model Exchange functions that `export_fmi2!(Model,
/// model_exchange)` exports besides [`EXPORTED_FUNCTIONS`].
pub const MODEL_EXCHANGE_FUNCTIONS: [&str; 10] = [
    "fmi2EnterEventMode",
    "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode",
    "fmi2CompletedIntegratorStep",
    "fmi2SetTime",
    "fmi2SetContinuousStates",
    "fmi2GetDerivatives",
    "fmi2GetEventIndicators",
    "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates",
];

/// Names of every common and co-simulation function [`export_fmi2!`] exports
/// (for export-table checks).
pub const EXPORTED_FUNCTIONS: [&str; 34] = [
    "fmi2GetTypesPlatform",
    "fmi2GetVersion",
    "fmi2SetDebugLogging",
    "fmi2Instantiate",
    "fmi2FreeInstance",
    "fmi2SetupExperiment",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2Terminate",
    "fmi2Reset",
    "fmi2GetReal",
    "fmi2GetInteger",
    "fmi2GetBoolean",
    "fmi2GetString",
    "fmi2SetReal",
    "fmi2SetInteger",
    "fmi2SetBoolean",
    "fmi2SetString",
    "fmi2GetFMUstate",
    "fmi2SetFMUstate",
    "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize",
    "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative",
    "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives",
    "fmi2DoStep",
    "fmi2CancelStep",
    "fmi2GetStatus",
    "fmi2GetRealStatus",
    "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus",
    "fmi2GetStringStatus",
];
