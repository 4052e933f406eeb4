//! The co-simulation and common functions on a live instance, each with the
//! oracle's verdict on what it may return and what it must leave behind.

use super::*;

impl Fuzzer<'_> {
    /// Functions without arguments: Enter, Terminate, Reset, CancelStep.
    pub(super) fn simple(&mut self, slot: usize, simple: Simple) {
        let function = Function::Simple(simple);
        let is_legal = self.legal_now(slot, function);
        let c = self.live(slot).c;
        let b = &self.fmu.binding;
        self.begin(function.name(), Some(slot));
        // SAFETY: `c` is the live instance in `slot`, the only argument.
        let status = unsafe {
            match simple {
                Simple::EnterInitializationMode => b.fmi2EnterInitializationMode(c),
                Simple::Terminate => b.fmi2Terminate(c),
                Simple::Reset => b.fmi2Reset(c),
                Simple::CancelStep => b.fmi2CancelStep(c),
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
        if status != OK {
            return;
        }
        let fresh = self.fresh.clone();
        let live = self.live_mut(slot);
        match simple {
            Simple::EnterInitializationMode => live.state = State::InitializationMode,
            Simple::Terminate => live.state = State::Terminated,
            Simple::Reset => {
                live.state = State::Instantiated;
                live.model = Shadow {
                    interface: live.model.interface,
                    ..fresh
                };
            }
            // Never legal for a synchronous slave: `check` refused an OK.
            Simple::CancelStep => {}
        }
    }

    pub(super) fn setup_experiment(&mut self, slot: usize, benign: bool) {
        let start = if benign {
            self.pick(&[0.0, 0.0, 0.0, 1.5, -2.0, 1e3])
        } else {
            match self.rng.random_range(0..20) {
                0..12 => 0.0,
                12..15 => self.rng.random_range(-1e3..1e3),
                15 => self.pick(&[1e300, -1e300, 1e15]),
                16 => f64::NAN,
                17 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                18 => 5e-324,
                _ => f64::from_bits(self.rng.random()),
            }
        };
        let stop_defined = !benign && self.chance(0.3);
        let stop = match self.rng.random_range(0..6) {
            0 | 1 => start + self.rng.random_range(0.0..10.0),
            2 => start - 1.0,
            3 => f64::NAN,
            4 => f64::INFINITY,
            _ => f64::NEG_INFINITY,
        };
        let tolerance_defined = self.rng.random_range(0..2);
        let tolerance = self.pick(&[1e-6, 0.0, -1.0, f64::NAN]);
        let is_legal = self.legal_now(slot, Function::SetupExperiment);
        let valid = start.is_finite() && (!stop_defined || (!stop.is_nan() && stop >= start));
        self.begin("fmi2SetupExperiment", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu.binding.fmi2SetupExperiment(
                self.live(slot).c,
                tolerance_defined,
                tolerance,
                start,
                stop_defined as sys::fmi2Boolean,
                stop,
            )
        };
        let allowed = if is_legal && valid { [OK] } else { [ERROR] };
        self.check(
            slot,
            "fmi2SetupExperiment",
            status,
            &allowed,
            !is_legal,
            || format!("startTime {start}, stopTimeDefined {stop_defined}, stopTime {stop}"),
        );
        if status == OK {
            let live = self.live_mut(slot);
            live.model.start_time = start;
            live.model.stop_time = if stop_defined { stop } else { f64::INFINITY };
            live.model.time = start;
        }
    }

    /// What building the model from `slot`'s values may answer: what
    /// fmi2ExitInitializationMode returns, and a getter in Initialization
    /// Mode too (it reads the model that exit would build, FMI 2.0's
    /// InitialUnknowns), when the call itself is legal and valid; and why.
    pub(super) fn initialization_outcome(
        &self,
        slot: usize,
    ) -> (&'static [sys::fmi2Status], String) {
        // A parameter outside its declared range must be refused; other
        // changed parameters are for the model to judge.
        let mut out_of_range = None;
        let mut changed = self.live(slot).model.tainted;
        for (index, v) in self.fmu.variables.iter().enumerate() {
            if v.causality != Causality::Parameter {
                continue;
            }
            let value = self.live(slot).model.values[index];
            if value.map(f64::to_bits) != v.start.map(f64::to_bits)
                || (v.kind == "String" && self.live(slot).model.strings[index] != v.start_string)
            {
                changed = true;
            }
            if let Some(value) = value
                && (v.min.is_some_and(|min| value < min) || v.max.is_some_and(|max| value > max))
            {
                out_of_range = Some(format!(
                    "{} = {value} outside [{:?}, {:?}]",
                    v.name, v.min, v.max
                ));
            }
        }
        let allowed: &'static [sys::fmi2Status] =
            if out_of_range.is_some() && !self.live(slot).model.tainted {
                &[ERROR]
            } else if changed {
                &[OK, ERROR]
            } else {
                &[OK]
            };
        let why = out_of_range.unwrap_or_else(|| format!("parameters changed: {changed}"));
        (allowed, why)
    }

    /// What a getter in Initialization Mode that reads a calculated value
    /// may return when the call is legal and valid: the values of the model
    /// built from the values set (fmi2OK), or, when no initialization takes
    /// them, the start values' with fmi2Warning; `may_fail` adds fmi2Error (a
    /// derivative that overflows).
    pub(super) fn initial_read_outcome(
        &self,
        slot: usize,
        may_fail: bool,
    ) -> &'static [sys::fmi2Status] {
        match (self.initialization_outcome(slot).0, may_fail) {
            ([OK], false) => &[OK],
            ([OK], true) => &[OK, ERROR],
            ([ERROR], false) => &[WARNING],
            ([ERROR], true) => &[WARNING, ERROR],
            (_, false) => &[OK, WARNING],
            (_, true) => &[OK, WARNING, ERROR],
        }
    }

    pub(super) fn exit_initialization_mode(&mut self, slot: usize) {
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::ExitInitializationMode);
        let (outcome, why) = self.initialization_outcome(slot);
        let allowed: &[sys::fmi2Status] = if is_legal { outcome } else { &[ERROR] };
        self.begin("fmi2ExitInitializationMode", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe { self.fmu.binding.fmi2ExitInitializationMode(c) };
        self.check(
            slot,
            "fmi2ExitInitializationMode",
            status,
            allowed,
            !is_legal,
            || why.clone(),
        );
        if status == OK {
            let live = self.live_mut(slot);
            live.state = match live.model.interface {
                Interface::CoSimulation => State::StepComplete,
                Interface::ModelExchange => State::EventMode,
            };
            // The model is built anew from its parameters.
            live.model.failed = false;
            live.model.wild_states = false;
            live.model.time = live.model.start_time;
        }
    }

    pub(super) fn set_debug_logging(&mut self, slot: usize, benign: bool) {
        let mut names: Vec<CString> = Vec::new();
        let count = self.rng.random_range(0..5);
        let mut unknown = false;
        for _ in 0..count {
            let name = match self.rng.random_range(0..10) {
                0..6 if !self.categories.is_empty() => {
                    let i = self.rng.random_range(0..self.categories.len());
                    self.categories[i].clone().into_bytes()
                }
                6 => b"logAll".to_vec(),
                _ if benign => b"logAll".to_vec(),
                7 => {
                    unknown = true;
                    self.pick(&[&b""[..], b"logNothing", b"%s%s%n%d", b"\xff\xfe"])
                        .to_vec()
                }
                8 => {
                    unknown = true;
                    vec![b'%'; 2000]
                }
                _ => {
                    unknown = true;
                    b"LOGALL".to_vec()
                }
            };
            names.push(CString::new(name).unwrap());
        }
        let mut pointers: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
        let null_entry = !benign && !pointers.is_empty() && self.chance(0.05);
        if null_entry {
            let i = self.rng.random_range(0..pointers.len());
            pointers[i] = ptr::null();
        }
        let null_array = !benign && self.chance(0.04);
        let n = if null_array {
            self.rng.random_range(1..4)
        } else {
            pointers.len()
        };
        let logging_on = self.pick(&[0, 1, 1, 2]);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::SetDebugLogging);
        let allowed = if !is_legal || null_array || null_entry {
            [ERROR]
        } else if unknown {
            [WARNING]
        } else {
            [OK]
        };
        self.begin("fmi2SetDebugLogging", Some(slot));
        let categories = if null_array || (n == 0 && self.rng.random_bool(0.5)) {
            ptr::null()
        } else {
            pointers.as_ptr()
        };
        // SAFETY: `c` is the live instance in `slot`; `categories` is NULL or
        // holds `n` pointers, each NULL or to a live NUL-terminated name.
        let status = unsafe {
            self.fmu
                .binding
                .fmi2SetDebugLogging(c, logging_on, n, categories)
        };
        self.check(slot, "fmi2SetDebugLogging", status, &allowed, !is_legal, || {
            format!("loggingOn {logging_on}, {n} categories {names:?}, NULL array {null_array}, NULL entry {null_entry}")
        });
    }

    pub(super) fn get(&mut self, slot: usize, kind: ValueType, benign: bool) {
        let function = Function::Get(kind);
        let vrs = match kind {
            ValueType::Real if benign => self.real_outputs.clone(),
            ValueType::String if benign => self.by_kind.get("String").cloned().unwrap_or_default(),
            _ => self.vrs(kind.name(), false),
        };
        let null_vr = !benign && !vrs.is_empty() && self.chance(0.04);
        let null_values = !benign && !vrs.is_empty() && self.chance(0.04);
        // NULL arrays may come with any length: nothing may be read.
        let n = if (null_vr || null_values) && self.chance(0.2) {
            self.pick(&[usize::MAX, 1 << 40, 100_000])
        } else {
            vrs.len()
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let resolved = self.resolve(&vrs, kind.name());
        let valid = n == 0 || (!null_vr && !null_values && resolved.is_ok());
        let vr_ptr = if null_vr { ptr::null() } else { vrs.as_ptr() };
        let len = vrs.len().max(1);
        let mut reals = vec![f64::NAN; len];
        let mut ints = vec![i32::MIN; len];
        let mut strings: Vec<sys::fmi2String> = vec![ptr::null(); len];
        let b = &self.fmu.binding;
        self.begin(function.name(), Some(slot));
        // The values argument: NULL, or the array of the call's type.
        fn out<T>(null: bool, values: &mut [T]) -> *mut T {
            if null {
                ptr::null_mut()
            } else {
                values.as_mut_ptr()
            }
        }
        // SAFETY: `c` is the live instance in `slot`; the
        // arrays are NULL or hold `vrs.len()` values, and `n` exceeds that only
        // with a NULL array, which the layer must refuse before reading any
        // (the case under test).
        let status = unsafe {
            match kind {
                ValueType::Real => b.fmi2GetReal(c, vr_ptr, n, out(null_values, &mut reals)),
                ValueType::Integer => b.fmi2GetInteger(c, vr_ptr, n, out(null_values, &mut ints)),
                ValueType::Boolean => b.fmi2GetBoolean(c, vr_ptr, n, out(null_values, &mut ints)),
                ValueType::String => b.fmi2GetString(c, vr_ptr, n, out(null_values, &mut strings)),
            }
        };
        // A state derivative is computed when read: from states or
        // parameters the fuzzer chose it may overflow, which the layer refuses
        // as fmi2GetDerivatives does.
        let reads_derivative = resolved
            .as_ref()
            .is_ok_and(|indices| indices.iter().any(|i| self.fmu.is_derivative(*i)));
        // What the model calculates (not a parameter, input, the time or a
        // constant) is read, in Initialization Mode, from the model built
        // from the values set.
        let reads_calculated = resolved.as_ref().is_ok_and(|indices| {
            indices.iter().any(|&i| {
                let v = &self.fmu.variables[i];
                !matches!(
                    v.causality,
                    Causality::Parameter | Causality::Input | Causality::Independent
                ) && v.variability != Some(Variability::Constant)
            })
        });
        let in_initialization = self.live(slot).state == State::InitializationMode;
        let allowed: &[sys::fmi2Status] = if !is_legal || !valid {
            &[ERROR]
        } else if in_initialization && reads_calculated {
            self.initial_read_outcome(
                slot,
                reads_derivative && !self.pristine_model_exchange(slot),
            )
        } else if reads_derivative && !self.pristine_model_exchange(slot) {
            &[OK, ERROR]
        } else {
            &[OK]
        };
        self.check(slot, function.name(), status, allowed, !is_legal, || {
            format!(
                "vr {vrs:?} (n {n}, NULL vr {null_vr}, NULL values {null_values}): {:?}",
                resolved.as_ref().err()
            )
        });
        if status != OK || n == 0 {
            return;
        }
        let live = self.live(slot);
        let tainted = live.model.tainted;
        // A state restored from forged bytes has unknown values, but the layer
        // refuses a state with a non-finite Real unless it was taken in the
        // error state: only a failed step, wild continuous states or the error
        // state excuse a non-finite value.
        let unreliable =
            live.model.failed || live.model.wild_states || (tainted && live.state == State::Error);
        let mut lent = Vec::new();
        for (i, index) in resolved.expect("valid").into_iter().enumerate() {
            let var = &self.fmu.variables[index];
            // What the value must be: a constant its start value in every
            // state (a restored state may not change it either), the
            // independent variable the time, a parameter or input what was
            // set; unknown after a forged state.
            let constant = var.variability == Some(Variability::Constant);
            let expected = if constant {
                var.start
            } else if var.causality == Causality::Independent {
                (!tainted).then_some(live.model.time)
            } else {
                live.model.values[index].filter(|_| !tainted)
            };
            let expected_text = if constant {
                var.start_string.as_deref()
            } else {
                live.model.strings[index].as_deref().filter(|_| !tainted)
            };
            let problem = match kind {
                ValueType::String => {
                    let pointer = strings[i];
                    if pointer.is_null() {
                        Some(format!("{} is a NULL pointer", var.name))
                    } else {
                        // SAFETY: returned with fmi2OK by the call just made on
                        // this instance: a NUL-terminated string the FMU keeps
                        // until the next call on the instance.
                        let bytes = unsafe { std::ffi::CStr::from_ptr(pointer) };
                        match bytes.to_str() {
                            Err(e) => Some(format!("{} is not UTF-8 ({e}): {bytes:?}", var.name)),
                            Ok(text) if expected_text.is_some_and(|e| e != text) => Some(format!(
                                "{} reads {text:?} but {:?} was set",
                                var.name,
                                expected_text.unwrap()
                            )),
                            Ok(text) => {
                                lent.push((pointer, text.to_owned()));
                                None
                            }
                        }
                    }
                }
                // The layer never hands out a non-finite derivative.
                ValueType::Real
                    if (!unreliable || self.fmu.is_derivative(index)) && !reals[i].is_finite() =>
                {
                    Some(format!("{} is {}", var.name, reals[i]))
                }
                ValueType::Real if expected.is_some_and(|e| e.to_bits() != reals[i].to_bits()) => {
                    Some(format!(
                        "{} reads {} but it is {}",
                        var.name,
                        reals[i],
                        expected.unwrap()
                    ))
                }
                ValueType::Boolean if ints[i] != 0 && ints[i] != 1 => Some(format!(
                    "{} reads {} (neither fmi2False nor fmi2True)",
                    var.name, ints[i]
                )),
                ValueType::Integer | ValueType::Boolean
                    if expected.is_some_and(|e| e != f64::from(ints[i])) =>
                {
                    Some(format!(
                        "{} reads {} but it is {}",
                        var.name,
                        ints[i],
                        expected.unwrap()
                    ))
                }
                _ => None,
            };
            if let Some(problem) = problem {
                self.fail(format!(
                    "{} returned fmi2OK with a wrong value: {problem}\n{}",
                    function.name(),
                    self.describe(slot)
                ));
            }
        }
        if kind == ValueType::String {
            self.report.strings_read += lent.len() as u64;
            self.live_mut(slot).lent = lent;
        }
    }

    pub(super) fn set(&mut self, slot: usize, kind: ValueType, benign: bool) {
        let function = Function::Set(kind);
        let vrs = if benign {
            let inputs = if kind == ValueType::String {
                self.string_inputs.clone()
            } else {
                self.real_inputs.clone()
            };
            let k = self.rng.random_range(1..=inputs.len().max(1));
            inputs.into_iter().take(k).collect()
        } else {
            self.vrs(kind.name(), true)
        };
        let null_vr = !benign && !vrs.is_empty() && self.chance(0.04);
        let null_values = !benign && !vrs.is_empty() && self.chance(0.04);
        let n = if (null_vr || null_values) && self.chance(0.2) {
            self.pick(&[usize::MAX, 1 << 40, 100_000])
        } else {
            vrs.len()
        };
        let resolved = self.resolve(&vrs, kind.name());
        // One value per vr, drawn for the variable it names when it names one.
        let mut reals = Vec::with_capacity(vrs.len().max(1));
        let mut ints = Vec::with_capacity(vrs.len().max(1));
        for vr in &vrs {
            let index = self.by_vr.get(vr).copied();
            let current = index.and_then(|i| self.live(slot).model.values[i]);
            if benign {
                reals.push(self.rng.random_range(-1.0..11.0));
                ints.push(0);
                continue;
            }
            reals.push(match index {
                Some(i) => self.real_value(i, current),
                None => self.rng.random_range(-10.0..10.0),
            });
            ints.push(match (kind, index) {
                (ValueType::Boolean, _) => self.boolean_value(current),
                (_, Some(i)) => self.integer_value(i, current),
                _ => self.rng.random(),
            });
        }
        reals.push(0.0);
        ints.push(0);
        // String arguments: NULL (None) or bytes without NUL, maybe not UTF-8.
        let texts: Vec<Option<Vec<u8>>> = if kind == ValueType::String {
            vrs.iter()
                .map(|vr| {
                    if benign {
                        let k: u16 = self.rng.random();
                        return Some(format!("text {k}").into_bytes());
                    }
                    let index = self.by_vr.get(vr).copied();
                    let current = index.and_then(|i| self.live(slot).model.strings[i].clone());
                    self.string_value(index, current.as_deref())
                })
                .collect()
        } else {
            Vec::new()
        };
        let owned: Vec<Option<CString>> = texts
            .iter()
            .map(|t| t.clone().map(|b| CString::new(b).expect("no NUL inside")))
            .collect();
        let mut strings: Vec<sys::fmi2String> = owned
            .iter()
            .map(|c| c.as_ref().map_or(ptr::null(), |c| c.as_ptr()))
            .collect();
        strings.push(ptr::null());

        // What the standard and the modelDescription say of each value.
        let is_legal = self.legal_now(slot, function);
        let live = self.live(slot);
        let state = live.state;
        let mut refusal: Option<String> = None;
        let mut bad_string = false;
        let mut warning_certain = false;
        let mut ambiguous = false;
        if n > 0 && (null_vr || null_values) {
            refusal = Some("a NULL array".to_owned());
        } else if let Err(reason) = &resolved {
            refusal = Some(reason.clone());
        } else if let Ok(indices) = &resolved {
            for (i, index) in indices.iter().enumerate() {
                let var = &self.fmu.variables[*index];
                let value = match kind {
                    ValueType::Real => reals[i],
                    ValueType::Boolean => f64::from(u8::from(ints[i] != 0)),
                    _ => f64::from(ints[i]),
                };
                if !value.is_finite() {
                    refusal = Some(format!("{} = {value}", var.name));
                    break;
                }
                // FMI 2.0.4 §2.1.7: a String is a pointer to a NUL-terminated
                // string; this layer's are UTF-8, as modelDescription is.
                let text = match texts.get(i) {
                    Some(None) => {
                        refusal = Some(format!("{}: a NULL string", var.name));
                        bad_string = true;
                        break;
                    }
                    Some(Some(bytes)) => match std::str::from_utf8(bytes) {
                        Ok(text) => Some(text),
                        Err(_) => {
                            refusal = Some(format!("{}: bytes that are not UTF-8", var.name));
                            bad_string = true;
                            break;
                        }
                    },
                    None => None,
                };
                let settable = matches!(var.causality, Causality::Parameter | Causality::Input);
                if !settable {
                    refusal = Some(format!("{} has causality {:?}", var.name, var.causality));
                    break;
                }
                if state == State::ContinuousTimeMode
                    && !(var.causality == Causality::Input
                        && var.variability.is_none_or(|v| v == Variability::Continuous))
                {
                    // FMI 2.0.4 §3.2.3: between events only continuous inputs.
                    refusal = Some(format!("{} set in continuous-time mode", var.name));
                    break;
                }
                if matches!(state, State::StepComplete | State::EventMode)
                    && var.causality == Causality::Parameter
                    && var.variability == Some(Variability::Tunable)
                    && (var.min.is_some_and(|min| value < min)
                        || var.max.is_some_and(|max| value > max))
                {
                    // Nothing checks a tunable parameter later: its declared
                    // range is checked when it is set while running.
                    refusal = Some(format!("tunable {} = {value} out of range", var.name));
                    break;
                }
                if matches!(state, State::StepComplete | State::EventMode)
                    && var.causality == Causality::Parameter
                    && var.variability != Some(Variability::Tunable)
                {
                    // A fixed parameter after initialization: the same value
                    // again is harmless (a warning), a new one is refused.
                    let same = match text {
                        Some(text) => live.model.strings[*index].as_deref().map(|c| c == text),
                        None => live.model.values[*index].map(|c| c == value),
                    };
                    match same {
                        Some(same) if !live.model.tainted => {
                            if same {
                                warning_certain = true;
                            } else {
                                refusal = Some(format!(
                                    "fixed parameter {} changed after initialization",
                                    var.name
                                ));
                                break;
                            }
                        }
                        _ => ambiguous = true,
                    }
                }
            }
        }
        let allowed: &[sys::fmi2Status] = if !is_legal || refusal.is_some() {
            &[ERROR]
        } else if ambiguous {
            &[OK, WARNING, ERROR]
        } else if warning_certain {
            &[WARNING]
        } else {
            &[OK]
        };
        let vr_ptr = if null_vr { ptr::null() } else { vrs.as_ptr() };
        let b = &self.fmu.binding;
        let c = live.c;
        self.begin(function.name(), Some(slot));
        // The values argument: NULL, or the array of the call's type.
        fn values<T>(null: bool, values: &[T]) -> *const T {
            if null { ptr::null() } else { values.as_ptr() }
        }
        // SAFETY: `c` is the live instance in `slot`; the
        // arrays are NULL or hold `vrs.len()` values (strings: a static one), and `n` exceeds that only
        // with a NULL array, which the layer must refuse before reading any
        // (the case under test).
        let status = unsafe {
            match kind {
                ValueType::Real => b.fmi2SetReal(c, vr_ptr, n, values(null_values, &reals)),
                ValueType::Integer => b.fmi2SetInteger(c, vr_ptr, n, values(null_values, &ints)),
                ValueType::Boolean => b.fmi2SetBoolean(c, vr_ptr, n, values(null_values, &ints)),
                ValueType::String => b.fmi2SetString(c, vr_ptr, n, values(null_values, &strings)),
            }
        };
        self.check(slot, function.name(), status, allowed, !is_legal, || {
            format!(
                "vr {vrs:?} (n {n}, NULL vr {null_vr}, NULL values {null_values}), values {}: {refusal:?}",
                match kind {
                    ValueType::Real => format!("{reals:?}"),
                    ValueType::String => format!(
                        "{:?}",
                        texts
                            .iter()
                            .map(|t| t.as_ref().map(|b| String::from_utf8_lossy(b)))
                            .collect::<Vec<_>>()
                    ),
                    _ => format!("{ints:?}"),
                }
            )
        });
        if bad_string {
            self.report.bad_strings_refused += 1;
        }
        if (status == OK || status == WARNING) && n > 0 {
            let indices = resolved.expect("accepted");
            self.report.strings_set += texts.len() as u64;
            let live = self.live_mut(slot);
            for (i, index) in indices.into_iter().enumerate() {
                let value = match kind {
                    ValueType::Real => reals[i],
                    ValueType::Boolean => f64::from(u8::from(ints[i] != 0)),
                    _ => f64::from(ints[i]),
                };
                match &texts.get(i) {
                    Some(Some(bytes)) => {
                        let text = String::from_utf8(bytes.clone()).expect("accepted: UTF-8");
                        live.model.strings[index] = Some(text);
                    }
                    _ => live.model.values[index] = Some(value),
                }
            }
        }
    }

    pub(super) fn do_step(&mut self, slot: usize, benign: bool) {
        let time = self.live(slot).model.time;
        let h = if benign {
            self.pick(&[1e-4, 1e-4, 1e-4, 5e-5, 1e-3, 2.5e-4])
        } else {
            match self.rng.random_range(0..100) {
                0..55 => 1e-4,
                55..70 => 10f64.powf(self.rng.random_range(-9.0..-1.0)),
                70..74 => self.pick(&[0.0, -0.0]),
                74..78 => -10f64.powf(self.rng.random_range(-9.0..3.0)),
                78..81 => f64::NAN,
                81..84 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                84..90 => self.pick(&[1.0, 1e3, 1e6]),
                90..93 => self.pick(&[1e300, f64::MAX]),
                93..95 => 5e-324,
                _ => f64::from_bits(self.rng.random()),
            }
        };
        // The layer's tolerance for a communication point that misses the
        // FMU's time by rounding is documented as 1e-9 relative (at least
        // 1e-9 absolute), at most half a step. Points well inside must be
        // accepted, points well outside refused; the band between is left open.
        let tolerance = (1e-9 * time.abs().max(1.0)).min(0.5 * h.abs());
        let t = if benign {
            time
        } else {
            match self.rng.random_range(0..100) {
                0..72 => time,
                72..80 => time + self.pick(&[0.3, -0.3]) * tolerance,
                80..88 => {
                    time + self.pick(&[1.0, -1.0])
                        * (4.0 * tolerance + 10f64.powf(self.rng.random_range(-6.0..3.0)))
                }
                88..92 => f64::NAN,
                92..96 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                _ => f64::from_bits(self.rng.random()),
            }
        };
        let no_prior = self.rng.random_range(0..2);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::DoStep);
        let miss = (t - time).abs();
        let tainted = self.live(slot).model.tainted;
        // A step must be positive and finite, start at a finite point and end
        // at one: an end time that overflows leaves no time to continue from.
        let arguments_valid = h.is_finite() && h > 0.0 && t.is_finite() && (t + h).is_finite();
        // A step may not end past the defined stopTime; the layer lets one end
        // within 0.1 % of its size past it (rounding), the band left open here.
        let stop_time = self.live(slot).model.stop_time;
        let past_stop = t + h > stop_time + 2e-3 * h;
        let near_stop = t + h > stop_time;
        let allowed: &[sys::fmi2Status] =
            if !is_legal || !arguments_valid || (!tainted && (miss > 2.0 * tolerance || past_stop))
            {
                &[ERROR]
            } else if tainted || miss > 0.5 * tolerance || near_stop {
                &[OK, WARNING, ERROR]
            } else if self.pristine(slot) && (1e-9..=1.0).contains(&h) {
                // Steps from a nanosecond (the resolution of integer-nanosecond
                // masters) to a second must work with start parameters and modest
                // inputs. Outside, a model may fail with a message (the
                // controller's rate terms divide by h: a subnormal step overflows).
                &[OK, WARNING]
            } else {
                &[OK, WARNING, ERROR]
            };
        self.begin("fmi2DoStep", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe { self.fmu.binding.fmi2DoStep(c, t, h, no_prior) };
        self.check(slot, "fmi2DoStep", status, allowed, !is_legal, || {
            format!("currentCommunicationPoint {t} (FMU time {time}), communicationStepSize {h}")
        });
        if status == ERROR && is_legal && allowed.contains(&OK) {
            self.live_mut(slot).model.failed = true;
        }
        if status == OK || status == WARNING {
            self.report.steps_completed += 1;
            self.live_mut(slot).model.time = t + h;
            // The outputs after a successful step are finite.
            self.get(slot, ValueType::Real, true);
        }
    }

    pub(super) fn not_offered(&mut self, slot: usize, which: NotOffered) {
        let function = Function::NotOffered(which);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let vrs = [0u32; 2];
        let mut reals = [0.0f64; 2];
        let orders = [1i32; 2];
        let n = self.rng.random_range(0..3);
        let b = &self.fmu.binding;
        self.begin(function.name(), Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            match which {
                NotOffered::GetDirectionalDerivative => b.fmi2GetDirectionalDerivative(
                    c,
                    vrs.as_ptr(),
                    n,
                    vrs.as_ptr(),
                    n,
                    reals.as_ptr(),
                    reals.as_mut_ptr(),
                ),
                NotOffered::SetRealInputDerivatives => b.fmi2SetRealInputDerivatives(
                    c,
                    vrs.as_ptr(),
                    n,
                    orders.as_ptr(),
                    reals.as_ptr(),
                ),
                NotOffered::GetRealOutputDerivatives => b.fmi2GetRealOutputDerivatives(
                    c,
                    vrs.as_ptr(),
                    n,
                    orders.as_ptr(),
                    reals.as_mut_ptr(),
                ),
            }
        };
        // modelDescription declares none of the three capabilities.
        let log = self.check(
            slot,
            function.name(),
            status,
            &[ERROR],
            !is_legal,
            String::new,
        );
        if is_legal
            && self.live(slot).has_logger
            && !log.iter().any(|r| r.message.contains("not offered"))
        {
            self.fail(format!(
                "{} refused without saying it is not offered: {log:#?}",
                function.name()
            ));
        }
    }

    pub(super) fn status_query(&mut self, slot: usize, query: StatusQuery, benign: bool) {
        let function = Function::StatusQuery(query);
        let kind: sys::fmi2StatusKind = if benign || self.chance(0.85) {
            self.rng.random_range(0..4)
        } else {
            self.pick(&[4, 1000, u32::MAX])
        };
        let null_value = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let mut real = f64::NAN;
        let mut int = i32::MIN;
        let mut status_value = u32::MAX;
        let mut string: sys::fmi2String = ptr::null();
        let b = &self.fmu.binding;
        self.begin(function.name(), Some(slot));
        // The value argument: NULL, or the local of the query's type.
        fn out<T>(null: bool, value: &mut T) -> *mut T {
            if null { ptr::null_mut() } else { value }
        }
        // SAFETY: `c` is the live instance in `slot`; the value pointer is NULL
        // (the case under test, which the layer must refuse) or a local.
        let status = unsafe {
            match query {
                StatusQuery::Status => b.fmi2GetStatus(c, kind, out(null_value, &mut status_value)),
                StatusQuery::Real => b.fmi2GetRealStatus(c, kind, out(null_value, &mut real)),
                StatusQuery::Integer => b.fmi2GetIntegerStatus(c, kind, out(null_value, &mut int)),
                StatusQuery::Boolean => b.fmi2GetBooleanStatus(c, kind, out(null_value, &mut int)),
                StatusQuery::String => b.fmi2GetStringStatus(c, kind, out(null_value, &mut string)),
            }
        };
        // A synchronous slave answers the last successful time and whether it
        // wants to terminate; the other kinds are not available: fmi2Discard.
        let answerable = matches!(
            (query, kind),
            (
                StatusQuery::Real,
                sys::fmi2StatusKind_fmi2LastSuccessfulTime
            ) | (StatusQuery::Boolean, sys::fmi2StatusKind_fmi2Terminated)
        );
        let allowed = if !is_legal || null_value {
            [ERROR]
        } else if answerable {
            [OK]
        } else {
            [DISCARD]
        };
        self.check(slot, function.name(), status, &allowed, !is_legal, || {
            format!("kind {kind}, NULL value {null_value}")
        });
        if status == OK {
            let live = self.live(slot);
            let wrong = match query {
                StatusQuery::Real => {
                    !live.model.tainted && real.to_bits() != live.model.time.to_bits()
                }
                _ => int != 0,
            };
            if wrong {
                self.fail(format!(
                    "{}({kind}) answered {real} / {int}; the FMU's time is {}",
                    function.name(),
                    live.model.time
                ));
            }
        }
    }
}
