//! The importer side of FMI 2.0 Model Exchange: instantiation for Model
//! Exchange, the ten Model Exchange calls on an [`Instance`], the state vector
//! that modelDescription declares, and a fixed-step integrator that drives an
//! instance as a simple importer does.
//!
//! Kept apart from the co-simulation importer in `lib.rs`; the legality table
//! of the model-exchange state machine is the conformance harness's.

// State pointers and vectors are handed to the FMU as an importer hands them.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use std::ptr;

use fmi_sys::fmi2 as sys;

use crate::{Fmu, Instance, Interface, OK, WARNING};

impl Fmu {
    /// Whether modelDescription offers Model Exchange.
    pub fn offers_model_exchange(&self) -> bool {
        self.description.model_exchange.is_some()
    }

    /// Length of the continuous-state vector: the number of
    /// ModelStructure/Derivatives entries.
    pub fn number_of_states(&self) -> usize {
        self.description.model_structure.derivatives.unknowns.len()
    }

    /// Whether the variable at `index` (0-based, in ModelVariables) is a
    /// state derivative: listed in ModelStructure/Derivatives.
    pub fn is_derivative(&self, index: usize) -> bool {
        self.description
            .model_structure
            .derivatives
            .unknowns
            .iter()
            .any(|unknown| unknown.index as usize == index + 1)
    }

    /// `numberOfEventIndicators` of modelDescription.
    pub fn number_of_event_indicators(&self) -> usize {
        self.description.number_of_event_indicators.unwrap_or(0) as usize
    }

    /// Instantiates for Model Exchange with a fresh log sink; panics with the
    /// log when the FMU refuses.
    pub fn instantiate_model_exchange(&self, name: &str, logging_on: bool) -> Instance<'_> {
        self.try_instantiate_as(Interface::ModelExchange, name, &self.guid, None, logging_on)
            .unwrap_or_else(|log| {
                panic!("fmi2Instantiate(fmi2ModelExchange) returned NULL: {log:#?}")
            })
    }

    /// A fresh instance of `interface`.
    pub fn instantiate_for(&self, interface: Interface, name: &str) -> Instance<'_> {
        match interface {
            Interface::CoSimulation => self.instantiate(name, false),
            Interface::ModelExchange => self.instantiate_model_exchange(name, false),
        }
    }
}

/// What `fmi2NewDiscreteStates` answered.
pub type EventInfo = sys::fmi2EventInfo;

impl Instance<'_> {
    fn me(&self) -> &sys::Fmi2Binding {
        &self.fmu.binding
    }

    pub fn enter_event_mode(&self) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        unsafe { self.me().fmi2EnterEventMode(self.c) }
    }

    pub fn new_discrete_states(&self) -> (sys::fmi2Status, EventInfo) {
        let mut info = EventInfo {
            newDiscreteStatesNeeded: 7,
            terminateSimulation: 7,
            nominalsOfContinuousStatesChanged: 7,
            valuesOfContinuousStatesChanged: 7,
            nextEventTimeDefined: 7,
            nextEventTime: f64::NAN,
        };
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe { self.me().fmi2NewDiscreteStates(self.c, &mut info) };
        (status, info)
    }

    pub fn enter_continuous_time_mode(&self) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        unsafe { self.me().fmi2EnterContinuousTimeMode(self.c) }
    }

    /// `fmi2CompletedIntegratorStep`; returns the status and the two flags.
    pub fn completed_integrator_step(&self) -> (sys::fmi2Status, bool, bool) {
        let (mut enter_event_mode, mut terminate) = (7, 7);
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe {
            self.me()
                .fmi2CompletedIntegratorStep(self.c, 1, &mut enter_event_mode, &mut terminate)
        };
        (status, enter_event_mode != 0, terminate != 0)
    }

    pub fn set_time(&self, time: f64) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        unsafe { self.me().fmi2SetTime(self.c, time) }
    }

    pub fn set_continuous_states(&self, x: &[f64]) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        unsafe {
            self.me()
                .fmi2SetContinuousStates(self.c, x.as_ptr(), x.len())
        }
    }

    pub fn get_continuous_states(&self, n: usize) -> (sys::fmi2Status, Vec<f64>) {
        let mut x = vec![f64::NAN; n];
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe { self.me().fmi2GetContinuousStates(self.c, x.as_mut_ptr(), n) };
        (status, x)
    }

    pub fn get_derivatives(&self, n: usize) -> (sys::fmi2Status, Vec<f64>) {
        let mut dx = vec![f64::NAN; n];
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe { self.me().fmi2GetDerivatives(self.c, dx.as_mut_ptr(), n) };
        (status, dx)
    }

    pub fn get_event_indicators(&self, n: usize) -> (sys::fmi2Status, Vec<f64>) {
        let mut z = vec![f64::NAN; n];
        let pointer = if n == 0 {
            ptr::null_mut()
        } else {
            z.as_mut_ptr()
        };
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe { self.me().fmi2GetEventIndicators(self.c, pointer, n) };
        (status, z)
    }

    pub fn get_nominals(&self, n: usize) -> (sys::fmi2Status, Vec<f64>) {
        let mut nominals = vec![f64::NAN; n];
        // SAFETY: `self.c` is the live Model Exchange instance this `Instance` owns (freed
        // only on drop); every pointer is to a local or a slice of the length passed, valid
        // for the call (the standard's signatures, through fmi-sys).
        let status = unsafe {
            self.me()
                .fmi2GetNominalsOfContinuousStates(self.c, nominals.as_mut_ptr(), n)
        };
        (status, nominals)
    }

    /// The derivatives at `x`, panicking unless both calls succeed.
    pub fn derivatives_at(&self, x: &[f64]) -> Vec<f64> {
        assert_eq!(
            self.set_continuous_states(x),
            OK,
            "fmi2SetContinuousStates: {:#?}",
            self.take_log()
        );
        let (status, dx) = self.get_derivatives(x.len());
        assert_eq!(status, OK, "fmi2GetDerivatives: {:#?}", self.take_log());
        dx
    }

    /// Integrates from the instance's time (`self.time`) over `steps` steps
    /// of `h` with classical RK4, as a fixed-step importer does: time and
    /// states set before every evaluation, `fmi2CompletedIntegratorStep` after
    /// every step. The instance must be in continuous-time mode.
    pub fn integrate_rk4(&mut self, h: f64, steps: usize) {
        let n = self.fmu.number_of_states();
        for _ in 0..steps {
            let t0 = self.time;
            let (status, x0) = self.get_continuous_states(n);
            assert_eq!(
                status,
                OK,
                "fmi2GetContinuousStates: {:#?}",
                self.take_log()
            );
            let stage = |inst: &Self, t: f64, base: &[f64], k: Option<(&[f64], f64)>| {
                assert_eq!(inst.set_time(t), OK, "fmi2SetTime: {:#?}", inst.take_log());
                let x: Vec<f64> = match k {
                    None => base.to_vec(),
                    Some((k, f)) => base.iter().zip(k).map(|(x, d)| x + f * d).collect(),
                };
                inst.derivatives_at(&x)
            };
            let k1 = stage(self, t0, &x0, None);
            let k2 = stage(self, t0 + 0.5 * h, &x0, Some((&k1, 0.5 * h)));
            let k3 = stage(self, t0 + 0.5 * h, &x0, Some((&k2, 0.5 * h)));
            let k4 = stage(self, t0 + h, &x0, Some((&k3, h)));
            let x1: Vec<f64> = (0..n)
                .map(|i| x0[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
                .collect();
            self.time = t0 + h;
            assert_eq!(self.set_time(self.time), OK);
            assert_eq!(self.set_continuous_states(&x1), OK);
            let (status, event, terminate) = self.completed_integrator_step();
            assert!(
                status == OK || status == WARNING,
                "fmi2CompletedIntegratorStep: {:#?}",
                self.take_log()
            );
            assert!(!event && !terminate, "no step events are expected");
        }
    }

    /// An event at the instance's time: event mode, discrete states updated
    /// until settled, back to continuous-time mode (what an importer does at a
    /// change of a discrete input).
    pub fn event_iteration(&self) {
        assert_eq!(self.enter_event_mode(), OK, "{:#?}", self.take_log());
        loop {
            let (status, info) = self.new_discrete_states();
            assert_eq!(status, OK, "fmi2NewDiscreteStates: {:#?}", self.take_log());
            assert_eq!(info.terminateSimulation, 0);
            if info.newDiscreteStatesNeeded == 0 {
                break;
            }
        }
        assert_eq!(self.enter_continuous_time_mode(), OK);
    }
}

/// The ScalarVariable index (1-based) of the state whose derivative is the
/// variable at index `derivative` (its `derivative` attribute).
pub fn state_of(fmu: &Fmu, derivative: u32) -> u32 {
    use fmi_schema::fmi2::ScalarVariableElement;
    let variable = &fmu.description.model_variables.variables[derivative as usize - 1];
    match &variable.elem {
        ScalarVariableElement::Real(real) => real.derivative.unwrap_or_else(|| {
            panic!(
                "{} is listed as a derivative but has no derivative attribute",
                variable.name
            )
        }),
        _ => panic!(
            "{} is listed as a derivative but is not Real",
            variable.name
        ),
    }
}

/// The state vector as modelDescription declares it: for each entry, the
/// value references of the state and of its derivative, in the order of
/// ModelStructure/Derivatives (FMI 2.0.4 §2.2.8).
pub fn state_references(fmu: &Fmu) -> Vec<(u32, u32)> {
    let variables = &fmu.description.model_variables.variables;
    fmu.description
        .model_structure
        .derivatives
        .unknowns
        .iter()
        .map(|unknown| {
            let state = state_of(fmu, unknown.index);
            (
                variables[state as usize - 1].value_reference,
                variables[unknown.index as usize - 1].value_reference,
            )
        })
        .collect()
}
