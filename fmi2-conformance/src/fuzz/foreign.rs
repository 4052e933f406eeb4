//! Calls on pointers that are not instances of the FMU under test: NULL,
//! its own FMU states, the other FMU's instances and states, importer memory.

use super::*;

impl Fuzzer<'_> {
    pub(super) fn call_on_foreign_pointer(&mut self) {
        use Function as F;
        let (kind, c) = self.not_an_instance();
        let functions: Vec<(Function, u32)> = self.functions().collect();
        let function = self.pick(&functions).0;
        self.report.foreign_instance_calls += 1;
        self.begin(function.name(), None);
        let b = &self.fmu.binding;
        let mut reals = [0.0f64; 4];
        let mut ints = [0i32; 4];
        let mut strings: [sys::fmi2String; 4] = [ptr::null(); 4];
        let vrs = [0u32; 4];
        let mut size = 0usize;
        let mut bytes = [0u8; 64];
        let mut state_slot: sys::fmi2FMUstate = ptr::null_mut();
        let mut status_value = OK;
        let mut vector = [0.0f64; 32];
        let (mut enter_event_mode, mut terminate) = (0, 0);
        let mut info = crate::model_exchange::EventInfo {
            newDiscreteStatesNeeded: 0,
            terminateSimulation: 0,
            nominalsOfContinuousStatesChanged: 0,
            valuesOfContinuousStatesChanged: 0,
            nextEventTimeDefined: 0,
            nextEventTime: 0.0,
        };
        let takes_state = matches!(
            function,
            F::FmuState(FmuStateCall::Set)
                | F::FmuState(FmuStateCall::Free)
                | F::FmuState(FmuStateCall::SerializedSize)
                | F::FmuState(FmuStateCall::Serialize)
        );
        let mut state = if takes_state {
            self.state_argument(0.5).1
        } else {
            ptr::null_mut()
        };
        let serialized = self
            .blobs
            .first()
            .map_or(bytes.to_vec(), |blob| blob.bytes.clone());
        let (vr, real_in, int_in, string_in) = (
            vrs.as_ptr(),
            reals.as_ptr(),
            ints.as_ptr(),
            strings.as_ptr(),
        );
        let (real_out, int_out, string_out) =
            (reals.as_mut_ptr(), ints.as_mut_ptr(), strings.as_mut_ptr());
        let (vector_in, vector_out) = (vector.as_ptr(), vector.as_mut_ptr());
        // SAFETY: `c` is NULL, an object of the layer, or importer memory of at
        // least eight readable bytes (see the module documentation): what the
        // layer must recognize as not its instance. Every other pointer is to
        // a local that outlives the call, and each array holds at least the
        // length passed with it (1 of 4 values, 19 of 32, `bytes.len()`).
        let status = unsafe {
            match function {
                F::SetDebugLogging => b.fmi2SetDebugLogging(c, 1, 0, ptr::null()),
                F::SetupExperiment => b.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
                F::Simple(Simple::EnterInitializationMode) => b.fmi2EnterInitializationMode(c),
                F::ExitInitializationMode => b.fmi2ExitInitializationMode(c),
                F::Simple(Simple::Terminate) => b.fmi2Terminate(c),
                F::Simple(Simple::Reset) => b.fmi2Reset(c),
                F::Simple(Simple::CancelStep) => b.fmi2CancelStep(c),
                F::Get(ValueType::Real) => b.fmi2GetReal(c, vr, 1, real_out),
                F::Get(ValueType::Integer) => b.fmi2GetInteger(c, vr, 1, int_out),
                F::Get(ValueType::Boolean) => b.fmi2GetBoolean(c, vr, 1, int_out),
                F::Get(ValueType::String) => b.fmi2GetString(c, vr, 1, string_out),
                F::Set(ValueType::Real) => b.fmi2SetReal(c, vr, 1, real_in),
                F::Set(ValueType::Integer) => b.fmi2SetInteger(c, vr, 1, int_in),
                F::Set(ValueType::Boolean) => b.fmi2SetBoolean(c, vr, 1, int_in),
                F::Set(ValueType::String) => b.fmi2SetString(c, vr, 1, string_in),
                F::FmuState(FmuStateCall::Get) => b.fmi2GetFMUstate(c, &mut state_slot),
                F::FmuState(FmuStateCall::Set) => b.fmi2SetFMUstate(c, state),
                F::FmuState(FmuStateCall::Free) => b.fmi2FreeFMUstate(c, &mut state),
                F::FmuState(FmuStateCall::SerializedSize) => {
                    b.fmi2SerializedFMUstateSize(c, state, &mut size)
                }
                F::FmuState(FmuStateCall::Serialize) => {
                    b.fmi2SerializeFMUstate(c, state, bytes.as_mut_ptr().cast(), bytes.len())
                }
                F::FmuState(FmuStateCall::DeSerialize) => b.fmi2DeSerializeFMUstate(
                    c,
                    serialized.as_ptr().cast(),
                    serialized.len(),
                    &mut state_slot,
                ),
                F::NotOffered(NotOffered::GetDirectionalDerivative) => {
                    b.fmi2GetDirectionalDerivative(c, vr, 1, vr, 1, real_in, real_out)
                }
                F::NotOffered(NotOffered::SetRealInputDerivatives) => {
                    b.fmi2SetRealInputDerivatives(c, vr, 1, int_in, real_in)
                }
                F::NotOffered(NotOffered::GetRealOutputDerivatives) => {
                    b.fmi2GetRealOutputDerivatives(c, vr, 1, int_in, real_out)
                }
                F::DoStep => b.fmi2DoStep(c, 0.0, 1e-4, 0),
                F::StatusQuery(StatusQuery::Status) => {
                    b.fmi2GetStatus(c, sys::fmi2StatusKind_fmi2DoStepStatus, &mut status_value)
                }
                F::StatusQuery(StatusQuery::Real) => {
                    b.fmi2GetRealStatus(c, sys::fmi2StatusKind_fmi2LastSuccessfulTime, real_out)
                }
                F::StatusQuery(StatusQuery::Integer) => {
                    b.fmi2GetIntegerStatus(c, sys::fmi2StatusKind_fmi2DoStepStatus, int_out)
                }
                F::StatusQuery(StatusQuery::Boolean) => {
                    b.fmi2GetBooleanStatus(c, sys::fmi2StatusKind_fmi2Terminated, int_out)
                }
                F::StatusQuery(StatusQuery::String) => {
                    b.fmi2GetStringStatus(c, sys::fmi2StatusKind_fmi2PendingStatus, string_out)
                }
                F::ModeChange(ModeChange::EnterEventMode) => b.fmi2EnterEventMode(c),
                F::ModeChange(ModeChange::EnterContinuousTimeMode) => {
                    b.fmi2EnterContinuousTimeMode(c)
                }
                F::NewDiscreteStates => b.fmi2NewDiscreteStates(c, &mut info),
                F::CompletedIntegratorStep => {
                    b.fmi2CompletedIntegratorStep(c, 1, &mut enter_event_mode, &mut terminate)
                }
                F::SetTime => b.fmi2SetTime(c, 0.0),
                F::SetContinuousStates => b.fmi2SetContinuousStates(c, vector_in, 19),
                F::GetVector(VectorGetter::Derivatives) => b.fmi2GetDerivatives(c, vector_out, 19),
                F::GetVector(VectorGetter::EventIndicators) => {
                    b.fmi2GetEventIndicators(c, vector_out, 0)
                }
                F::GetVector(VectorGetter::ContinuousStates) => {
                    b.fmi2GetContinuousStates(c, vector_out, 19)
                }
                F::GetVector(VectorGetter::Nominals) => {
                    b.fmi2GetNominalsOfContinuousStates(c, vector_out, 19)
                }
                F::FreeInstance => {
                    b.fmi2FreeInstance(c);
                    return self.after_foreign_free(kind);
                }
            }
        };
        self.count_status(function.name(), status);
        if status != ERROR {
            self.fail(format!(
                "{} on {kind:?} ({c:?}) returned {}, expected fmi2Error",
                function.name(),
                STATUS_NAMES[status as usize]
            ));
        }
        if !state_slot.is_null() {
            self.fail(format!(
                "{} on {kind:?} returned an FMU state",
                function.name()
            ));
        }
        self.others_silent(None);
        self.check_foreign_alive(kind);
    }

    /// fmi2FreeInstance returns nothing to check: no other instance heard of
    /// it, and the other FMU's instance still works.
    fn after_foreign_free(&mut self, kind: NotAnInstance) {
        self.report.calls_without_status += 1;
        self.others_silent(None);
        self.check_foreign_alive(kind);
    }

    /// After a call aimed at the other FMU's instance or state by mistake, that
    /// instance still works and its state is still a state.
    pub(super) fn check_foreign_alive(&mut self, kind: NotAnInstance) {
        if !matches!(
            kind,
            NotAnInstance::ForeignInstance | NotAnInstance::ForeignFmuState
        ) {
            return;
        }
        let Some(foreign) = self.foreign.as_mut() else {
            return;
        };
        let stepped = foreign.instance.do_step(1e-4);
        let restored = foreign.instance.set_state(foreign.state);
        let log = foreign.instance.take_log();
        foreign.instance.time = {
            let mut time = 0.0;
            // SAFETY: `foreign.instance.c` is the other FMU's live instance and `time` a local.
            unsafe {
                foreign.instance.fmu.binding.fmi2GetRealStatus(
                    foreign.instance.c,
                    sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                    &mut time,
                )
            };
            time
        };
        if stepped != OK || restored != OK {
            self.fail(format!(
                "a call on the other FMU's {kind:?} through this FMU broke it (doStep {stepped}, \
                 setFMUstate {restored}): {log:#?}"
            ));
        }
    }
}
