//! The fuzzer's Model Exchange calls, for an FMU that offers Model Exchange:
//! the ten functions of FMI 2.0.4 §3.2.2 with hostile arguments (NULL vectors,
//! lengths that are not the model's, NaN and huge states and times), and bursts
//! that integrate an instance with explicit Euler steps as a simple importer
//! does. The oracle is the one of the co-simulation calls (`super`): the
//! legality table, the statuses a call may return, and the values a
//! successful call may hand out.

use super::*;

/// How a vector argument is passed.
#[derive(Clone, Copy, Debug)]
pub(super) enum Vector {
    /// The model's length.
    Right,
    /// Another length (never one past the buffer).
    Wrong(usize),
    /// NULL with this length.
    Null(usize),
}

impl Fuzzer<'_> {
    /// fmi2SetTime at a random time: mostly forward, sometimes backward or
    /// not finite.
    pub(super) fn random_set_time(&mut self, slot: usize, benign: bool) {
        let time = self.live(slot).model.time;
        let t = if benign {
            time + 1e-6
        } else {
            match self.rng.random_range(0..20) {
                0..10 => time + 10f64.powf(self.rng.random_range(-9.0..-3.0)),
                10..13 => time - 10f64.powf(self.rng.random_range(-9.0..-3.0)),
                13 => f64::NAN,
                14 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                15 => self.pick(&[1e300, -1e300, f64::MAX]),
                16 => 5e-324,
                _ => f64::from_bits(self.rng.random()),
            }
        };
        self.set_time(slot, t);
    }

    /// fmi2SetContinuousStates with states the fuzzer chose.
    pub(super) fn random_set_continuous_states(&mut self, slot: usize, benign: bool) {
        let n = self.fmu.number_of_states();
        let values: Vec<f64> = (0..n)
            .map(|_| match self.rng.random_range(0..100) {
                0..80 => self.rng.random_range(-10.0..10.0),
                80..85 => 0.0,
                85..90 => self.pick(&[1e6, -1e6, 1e300, f64::MAX]),
                90..93 => f64::NAN,
                93..96 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                _ => f64::from_bits(self.rng.random()),
            })
            .collect();
        let shape = self.vector_shape(benign);
        self.set_continuous_states(slot, &values, shape, true);
    }

    pub(super) fn vector_shape(&mut self, benign: bool) -> Vector {
        if benign {
            return Vector::Right;
        }
        match self.rng.random_range(0..20) {
            0..15 => Vector::Right,
            15..18 => Vector::Wrong(self.rng.random_range(0..=32)),
            _ => Vector::Null(self.pick(&[0, 1, 19, 1 << 40])),
        }
    }

    /// Whether the instance in `slot` is where every Model Exchange call with
    /// good arguments must succeed: start parameters, modest inputs, states
    /// only ever set by an integrator.
    pub(super) fn pristine_model_exchange(&self, slot: usize) -> bool {
        self.pristine(slot) && !self.live(slot).model.wild_states
    }

    /// fmi2EnterEventMode, fmi2EnterContinuousTimeMode.
    pub(super) fn mode_change(&mut self, slot: usize, change: ModeChange) {
        let function = Function::ModeChange(change);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        self.begin(function.name(), Some(slot));
        let b = &self.fmu.binding;
        // SAFETY: `c` is the live instance in `slot`.
        let status = unsafe {
            match change {
                ModeChange::EnterEventMode => b.fmi2EnterEventMode(c),
                ModeChange::EnterContinuousTimeMode => b.fmi2EnterContinuousTimeMode(c),
            }
        };
        let allowed = if is_legal { [OK] } else { [ERROR] };
        self.check(
            slot,
            function.name(),
            status,
            &allowed,
            !is_legal,
            String::new,
        );
        if status == OK {
            self.live_mut(slot).state = match change {
                ModeChange::EnterEventMode => State::EventMode,
                ModeChange::EnterContinuousTimeMode => State::ContinuousTimeMode,
            };
        }
    }

    pub(super) fn new_discrete_states(&mut self, slot: usize, benign: bool) {
        let null = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::NewDiscreteStates);
        let mut info = crate::model_exchange::EventInfo {
            newDiscreteStatesNeeded: 7,
            terminateSimulation: 7,
            nominalsOfContinuousStatesChanged: 7,
            valuesOfContinuousStatesChanged: 7,
            nextEventTimeDefined: 7,
            nextEventTime: f64::NAN,
        };
        self.begin("fmi2NewDiscreteStates", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu
                .binding
                .fmi2NewDiscreteStates(c, if null { ptr::null_mut() } else { &mut info })
        };
        let allowed: &[sys::fmi2Status] = if !is_legal || null {
            &[ERROR]
        } else if self.pristine_model_exchange(slot) {
            &[OK]
        } else {
            // The model checks its state at events too.
            &[OK, ERROR]
        };
        self.check(
            slot,
            "fmi2NewDiscreteStates",
            status,
            allowed,
            !is_legal,
            || format!("fmi2eventInfo NULL {null}"),
        );
        if status == OK {
            let flags = [
                info.newDiscreteStatesNeeded,
                info.terminateSimulation,
                info.nominalsOfContinuousStatesChanged,
                info.valuesOfContinuousStatesChanged,
                info.nextEventTimeDefined,
            ];
            if flags.iter().any(|f| *f != 0 && *f != 1)
                || (info.nextEventTimeDefined == 1 && !info.nextEventTime.is_finite())
            {
                self.fail(format!("fmi2NewDiscreteStates answered {info:?}"));
            }
        }
    }

    pub(super) fn completed_integrator_step(&mut self, slot: usize, benign: bool) {
        let null = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::CompletedIntegratorStep);
        let (mut enter_event_mode, mut terminate) = (7, 7);
        self.begin("fmi2CompletedIntegratorStep", Some(slot));
        let no_set_fmu_state_prior = self.rng.random_range(0..2);
        let enter_event_mode_out: *mut sys::fmi2Boolean = if null {
            ptr::null_mut()
        } else {
            &mut enter_event_mode
        };
        // SAFETY: `c` is the live instance in `slot`; the flags point to
        // locals, or NULL (the case under test, which the layer must refuse).
        let status = unsafe {
            self.fmu.binding.fmi2CompletedIntegratorStep(
                c,
                no_set_fmu_state_prior,
                enter_event_mode_out,
                &mut terminate,
            )
        };
        let allowed: &[sys::fmi2Status] = if !is_legal || null {
            &[ERROR]
        } else if self.pristine_model_exchange(slot) {
            &[OK, WARNING]
        } else {
            // A state the fuzzer set may be one the model refuses to go on from.
            &[OK, WARNING, ERROR]
        };
        self.check(
            slot,
            "fmi2CompletedIntegratorStep",
            status,
            allowed,
            !is_legal,
            || format!("enterEventMode NULL {null}"),
        );
        if (status == OK || status == WARNING)
            && ![0, 1].contains(&enter_event_mode)
            && ![0, 1].contains(&terminate)
        {
            self.fail(format!(
                "fmi2CompletedIntegratorStep answered enterEventMode {enter_event_mode}, \
                 terminateSimulation {terminate}"
            ));
        }
        if status == OK || status == WARNING {
            self.report.integrator_steps += 1;
        }
    }

    fn set_time(&mut self, slot: usize, t: f64) {
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::SetTime);
        self.begin("fmi2SetTime", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe { self.fmu.binding.fmi2SetTime(c, t) };
        let allowed = if is_legal && t.is_finite() {
            [OK]
        } else {
            [ERROR]
        };
        self.check(slot, "fmi2SetTime", status, &allowed, !is_legal, || {
            format!("time {t}")
        });
        if status == OK {
            self.live_mut(slot).model.time = t;
        }
    }

    /// fmi2SetContinuousStates with `values` (the model's length) passed as
    /// `shape` says; `chosen` when the fuzzer chose them (not an integrator).
    fn set_continuous_states(&mut self, slot: usize, values: &[f64], shape: Vector, chosen: bool) {
        let nx = self.fmu.number_of_states();
        let mut buffer = values.to_vec();
        buffer.resize(33, 0.0);
        let (pointer, n) = match shape {
            Vector::Right => (buffer.as_ptr(), nx),
            Vector::Wrong(n) => (buffer.as_ptr(), n),
            Vector::Null(n) => (ptr::null(), n),
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::SetContinuousStates);
        let finite = values.iter().all(|v| v.is_finite());
        let valid = n == nx && (n == 0 || !pointer.is_null()) && finite;
        self.begin("fmi2SetContinuousStates", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe { self.fmu.binding.fmi2SetContinuousStates(c, pointer, n) };
        let allowed = if is_legal && valid { [OK] } else { [ERROR] };
        self.check(
            slot,
            "fmi2SetContinuousStates",
            status,
            &allowed,
            !is_legal,
            || format!("{shape:?} of {nx}, finite {finite}: {values:?}"),
        );
        if status == OK && chosen {
            self.live_mut(slot).model.wild_states = true;
        }
    }

    /// The four getters of vectors; returns the values when the call succeeded.
    pub(super) fn get_vector(
        &mut self,
        slot: usize,
        getter: VectorGetter,
        shape: Vector,
    ) -> Option<Vec<f64>> {
        let function = Function::GetVector(getter);
        let expected = if getter == VectorGetter::EventIndicators {
            self.fmu.number_of_event_indicators()
        } else {
            self.fmu.number_of_states()
        };
        let mut buffer = vec![f64::NAN; 33];
        let (pointer, n) = match shape {
            Vector::Right => (buffer.as_mut_ptr(), expected),
            Vector::Wrong(n) => (buffer.as_mut_ptr(), n),
            Vector::Null(n) => (ptr::null_mut(), n),
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let valid = n == expected && (n == 0 || !pointer.is_null());
        let b = &self.fmu.binding;
        self.begin(function.name(), Some(slot));
        // SAFETY: `c` is the live instance in `slot`; `pointer` is NULL or
        // `buffer`, whose 33 values are more than any length the fuzzer passes
        // with it.
        let status = unsafe {
            match getter {
                VectorGetter::Derivatives => b.fmi2GetDerivatives(c, pointer, n),
                VectorGetter::EventIndicators => b.fmi2GetEventIndicators(c, pointer, n),
                VectorGetter::ContinuousStates => b.fmi2GetContinuousStates(c, pointer, n),
                VectorGetter::Nominals => b.fmi2GetNominalsOfContinuousStates(c, pointer, n),
            }
        };
        let live = &self.live(slot).model;
        // Derivatives are computed from whatever the states are: from states
        // the fuzzer set, or parameters it changed, they may be out of the
        // model's domain, which the model reports as an error.
        let may_fail = getter == VectorGetter::Derivatives
            && (!self.pristine_model_exchange(slot) || live.failed);
        let in_initialization = self.live(slot).state == State::InitializationMode;
        let allowed: &[sys::fmi2Status] = if !is_legal || !valid {
            &[ERROR]
        } else if in_initialization {
            // Read from the model built from the values set.
            self.initial_read_outcome(slot, may_fail)
        } else if may_fail {
            &[OK, ERROR]
        } else {
            &[OK]
        };
        let tainted = self.live(slot).model.tainted;
        self.check(slot, function.name(), status, allowed, !is_legal, || {
            format!("{shape:?} of {expected}")
        });
        if status != OK {
            return None;
        }
        let values = buffer[..n].to_vec();
        let bad = match getter {
            // The layer never hands out a non-finite derivative.
            VectorGetter::Derivatives => values.iter().any(|v| !v.is_finite()),
            VectorGetter::Nominals => values.iter().any(|v| !(v.is_finite() && *v > 0.0)),
            VectorGetter::ContinuousStates => !tainted && values.iter().any(|v| !v.is_finite()),
            VectorGetter::EventIndicators => values.iter().any(|v| v.is_nan()),
        };
        if bad {
            self.fail(format!(
                "{} returned fmi2OK with {values:?}",
                function.name()
            ));
        }
        Some(values)
    }

    /// Explicit Euler steps of a model-exchange instance in continuous-time
    /// mode, with input changes, events and FMU states in between.
    pub(super) fn run_model_exchange(&mut self, slot: usize) {
        let steps = self.rng.random_range(10..200);
        let terminate = self.chance(0.3);
        for _ in 0..steps {
            if self.live(slot).state != State::ContinuousTimeMode {
                return;
            }
            match self.rng.random_range(0..12) {
                0..2 => self.set(slot, ValueType::Real, true),
                2 => self.get(slot, ValueType::Real, true),
                3 if self.chance(0.1) => self.get_fmu_state(slot, true),
                3 if self.chance(0.1) => self.set_fmu_state(slot, true),
                4 => {
                    // An event, as at a jump of a discrete input.
                    self.mode_change(slot, ModeChange::EnterEventMode);
                    self.new_discrete_states(slot, true);
                    if self.live(slot).state == State::EventMode {
                        self.mode_change(slot, ModeChange::EnterContinuousTimeMode);
                    }
                }
                _ => self.euler_step(slot),
            }
        }
        if terminate && self.live(slot).state == State::ContinuousTimeMode {
            self.simple(slot, Simple::Terminate);
        }
    }

    /// One explicit Euler step through the C ABI: states and derivatives
    /// read, time and states set, the step completed.
    fn euler_step(&mut self, slot: usize) {
        // Explicit Euler through a Bouc-Wen state is stable only while the
        // input moves a few volts per step: a 3 kHz amplifier slewing across
        // a -30..130 V range moves up to 30 V in 10 us, and the hysteretic
        // state then oscillates and escapes. An importer's step control keeps
        // within that; the fuzzer's fixed steps stay at or below 5 us
        // (at most 15 V).
        let h = self.pick(&[1e-6, 2e-6, 5e-6]);
        let Some(x) = self.get_vector(slot, VectorGetter::ContinuousStates, Vector::Right) else {
            return;
        };
        let Some(dx) = self.get_vector(slot, VectorGetter::Derivatives, Vector::Right) else {
            return;
        };
        let t = self.live(slot).model.time + h;
        self.set_time(slot, t);
        let next: Vec<f64> = x.iter().zip(&dx).map(|(x, d)| x + h * d).collect();
        self.set_continuous_states(slot, &next, Vector::Right, false);
        if self.live(slot).state == State::ContinuousTimeMode {
            self.completed_integrator_step(slot, true);
        }
    }
}
