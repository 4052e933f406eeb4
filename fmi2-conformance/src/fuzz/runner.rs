//! The runner: the fuzzer's own state, the random walk that picks the next
//! call, bursts of legal calls that drive an instance deep, and instance
//! lifetimes (instantiate, free, and the checks at the end of a run).

use super::*;

pub(super) struct Fuzzer<'a> {
    pub(super) fmu: &'a Fmu,
    pub(super) rng: Xoshiro256PlusPlus,
    pub(super) slots: Vec<Option<Live>>,
    pub(super) handles: Vec<Handle>,
    pub(super) blobs: Vec<Blob>,
    pub(super) foreign: Option<Foreign<'a>>,
    pub(super) zeroed: Box<[u64; 256]>,
    pub(super) random: Box<[u64; 256]>,
    pub(super) report: FuzzReport,
    pub(super) trace: VecDeque<TraceEntry>,
    pub(super) progress: Arc<AtomicU64>,
    pub(super) instances_made: u64,
    /// Variable index of each value reference.
    pub(super) by_vr: BTreeMap<u32, usize>,
    /// Value references by type name ("Real", ...).
    pub(super) by_kind: BTreeMap<&'static str, Vec<u32>>,
    pub(super) settable_by_kind: BTreeMap<&'static str, Vec<u32>>,
    pub(super) real_outputs: Vec<u32>,
    pub(super) real_inputs: Vec<u32>,
    pub(super) string_inputs: Vec<u32>,
    pub(super) unknown_vrs: Vec<u32>,
    pub(super) categories: Vec<String>,
    pub(super) fresh: Shadow,
}

impl<'a> Fuzzer<'a> {
    pub(super) fn new(
        fmu: &'a Fmu,
        foreign: Option<&'a Fmu>,
        seed: u64,
        progress: Arc<AtomicU64>,
    ) -> Self {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut by_vr = BTreeMap::new();
        let mut by_kind: BTreeMap<&'static str, Vec<u32>> = BTreeMap::new();
        let mut settable_by_kind: BTreeMap<&'static str, Vec<u32>> = BTreeMap::new();
        let mut values = Vec::new();
        let mut strings = Vec::new();
        for (index, v) in fmu.variables.iter().enumerate() {
            by_vr.insert(v.vr, index);
            by_kind.entry(v.kind).or_default().push(v.vr);
            let settable = matches!(v.causality, Causality::Parameter | Causality::Input);
            if settable {
                settable_by_kind.entry(v.kind).or_default().push(v.vr);
            }
            values.push(if settable { v.start } else { None });
            strings.push(if settable && v.kind == "String" {
                Some(v.start_string.clone().unwrap_or_default())
            } else {
                None
            });
        }
        let real_outputs = fmu
            .with_causality(Causality::Output)
            .filter(|v| v.kind == "Real")
            .map(|v| v.vr)
            .collect();
        let real_inputs = fmu
            .with_causality(Causality::Input)
            .filter(|v| v.kind == "Real")
            .map(|v| v.vr)
            .collect();
        let string_inputs = fmu
            .with_causality(Causality::Input)
            .filter(|v| v.kind == "String")
            .map(|v| v.vr)
            .collect();
        let max_vr = fmu.variables.iter().map(|v| v.vr).max().unwrap_or(0);
        let unknown_vrs = vec![max_vr + 1, max_vr + 1000, u32::MAX, u32::MAX - 1, 1 << 31];
        let categories = fmu
            .description
            .log_categories
            .as_ref()
            .map(|c| c.categories.iter().map(|c| c.name.clone()).collect())
            .unwrap_or_default();
        let foreign = foreign.map(|other| {
            let mut instance = other.instantiate("foreign", false);
            instance.initialize();
            assert_eq!(instance.do_step(1e-4), OK, "the foreign FMU steps");
            let (status, state) = instance.get_state();
            assert_eq!(status, OK, "the foreign FMU gives a state");
            let (status, bytes) = instance.serialize(state);
            assert_eq!(status, OK, "the foreign FMU serializes its state");
            instance.take_log();
            Foreign {
                instance,
                state,
                bytes,
            }
        });
        let mut random = Box::new([0u64; 256]);
        for word in random.iter_mut() {
            *word = rng.random();
        }
        Fuzzer {
            fmu,
            rng,
            slots: (0..SLOTS).map(|_| None).collect(),
            handles: Vec::new(),
            blobs: Vec::new(),
            foreign,
            zeroed: Box::new([0u64; 256]),
            random,
            report: FuzzReport {
                model: fmu.description.model_name.clone(),
                seed,
                ..FuzzReport::default()
            },
            trace: VecDeque::with_capacity(32),
            progress,
            instances_made: 0,
            by_vr,
            by_kind,
            settable_by_kind,
            real_outputs,
            real_inputs,
            string_inputs,
            unknown_vrs,
            categories,
            fresh: Shadow {
                values,
                strings,
                time: 0.0,
                start_time: 0.0,
                stop_time: f64::INFINITY,
                machine: State::Instantiated,
                interface: Interface::CoSimulation,
                wild_states: false,
                tainted: false,
                failed: false,
            },
        }
    }

    pub(super) fn step(&mut self) {
        let slot = self.rng.random_range(0..SLOTS);
        if self.slots[slot].is_none() {
            self.instantiate(slot);
            return;
        }
        match self.rng.random_range(0..1000) {
            0..30 => return self.call_on_foreign_pointer(),
            30..45 => return self.burst(slot),
            45..48 => return self.platform_and_version(),
            _ => {}
        }
        let (state, interface) = (self.live(slot).state, self.live(slot).model.interface);
        let function = self.pick_function(interface, state);
        self.call(slot, function, false);
    }

    /// The functions this FMU's binary exports, with their weights: the Model
    /// Exchange ones only when it offers Model Exchange.
    pub(super) fn functions(&self) -> impl Iterator<Item = (Function, u32)> + use<> {
        let model_exchange = self.fmu.offers_model_exchange();
        FUNCTIONS.iter().copied().chain(
            MODEL_EXCHANGE_FUNCTIONS
                .iter()
                .copied()
                .filter(move |_| model_exchange),
        )
    }

    /// Whether `function` is legal on the instance in `slot` now.
    pub(super) fn legal_now(&self, slot: usize, function: Function) -> bool {
        let live = self.live(slot);
        legal(live.model.interface, function, live.state)
    }

    pub(super) fn call(&mut self, slot: usize, function: Function, benign: bool) {
        use Function as F;
        match function {
            F::SetDebugLogging => self.set_debug_logging(slot, benign),
            F::SetupExperiment => self.setup_experiment(slot, benign),
            F::ExitInitializationMode => self.exit_initialization_mode(slot),
            F::Simple(simple) => self.simple(slot, simple),
            F::Get(value_type) => self.get(slot, value_type, benign),
            F::Set(value_type) => self.set(slot, value_type, benign),
            F::FmuState(FmuStateCall::Get) => self.get_fmu_state(slot, benign),
            F::FmuState(FmuStateCall::Set) => self.set_fmu_state(slot, benign),
            F::FmuState(FmuStateCall::Free) => self.free_fmu_state(slot, benign),
            F::FmuState(FmuStateCall::SerializedSize) => self.serialized_size(slot, benign),
            F::FmuState(FmuStateCall::Serialize) => self.serialize(slot, benign),
            F::FmuState(FmuStateCall::DeSerialize) => self.deserialize(slot, benign),
            F::NotOffered(function) => self.not_offered(slot, function),
            F::DoStep => self.do_step(slot, benign),
            F::StatusQuery(query) => self.status_query(slot, query, benign),
            F::FreeInstance => self.free_instance(slot),
            F::ModeChange(change) => self.mode_change(slot, change),
            F::NewDiscreteStates => self.new_discrete_states(slot, benign),
            F::CompletedIntegratorStep => self.completed_integrator_step(slot, benign),
            F::SetTime => self.random_set_time(slot, benign),
            F::SetContinuousStates => self.random_set_continuous_states(slot, benign),
            F::GetVector(getter) => {
                let shape = self.vector_shape(benign);
                self.get_vector(slot, getter, shape);
            }
        }
    }

    /// A run of legal calls that drives the instance to where it runs
    /// (StepComplete, or continuous-time mode for Model Exchange) and runs it
    /// many steps with plausible inputs: random walks alone rarely get deep.
    pub(super) fn burst(&mut self, slot: usize) {
        let interface = self.live(slot).model.interface;
        for &function in path_to_running(interface, self.live(slot).state) {
            self.call(slot, function, true);
            if self.live(slot).state == State::Error {
                return;
            }
        }
        match interface {
            Interface::CoSimulation => self.run_co_simulation(slot),
            Interface::ModelExchange => self.run_model_exchange(slot),
        }
    }

    /// Steps of a co-simulation instance in StepComplete with plausible
    /// inputs, FMU states in between.
    fn run_co_simulation(&mut self, slot: usize) {
        let steps = self.rng.random_range(10..200);
        let terminate = self.chance(0.3);
        for _ in 0..steps {
            if self.live(slot).state != State::StepComplete {
                return;
            }
            match self.rng.random_range(0..10) {
                0..3 => self.set(slot, ValueType::Real, true),
                3 => self.get(slot, ValueType::Real, true),
                4 if self.chance(0.1) => self.get_fmu_state(slot, true),
                4 if self.chance(0.1) => self.set_fmu_state(slot, true),
                // Text inputs while running (an FMU without any draws nothing
                // here, so its runs are the same as before they existed).
                5 if !self.string_inputs.is_empty() && self.chance(0.3) => {
                    self.set(slot, ValueType::String, true);
                    self.get(slot, ValueType::String, true);
                }
                _ => self.do_step(slot, true),
            }
        }
        // Some runs end as a master ends them, and the calls that follow meet
        // a terminated instance.
        if terminate && self.live(slot).state == State::StepComplete {
            self.simple(slot, Simple::Terminate);
        }
    }

    pub(super) fn platform_and_version(&mut self) {
        let b = &self.fmu.binding;
        self.begin("fmi2GetTypesPlatform", None);
        self.report.calls_without_status += 1;
        // SAFETY: the function takes no argument and returns a static NUL-terminated string
        // (FMI 2.0.4 §2.1.4), which the binding keeps loaded.
        let platform = unsafe { std::ffi::CStr::from_ptr(b.fmi2GetTypesPlatform()) };
        self.begin("fmi2GetVersion", None);
        self.report.calls_without_status += 1;
        // SAFETY: the function takes no argument and returns a static NUL-terminated string
        // (FMI 2.0.4 §2.1.4), which the binding keeps loaded.
        let version = unsafe { std::ffi::CStr::from_ptr(b.fmi2GetVersion()) };
        if platform.to_bytes() != b"default" || version.to_bytes() != b"2.0" {
            self.fail(format!("platform {platform:?}, version {version:?}"));
        }
    }

    pub(super) fn instantiate(&mut self, slot: usize) {
        self.instances_made += 1;
        let name = match self.rng.random_range(0..100) {
            0..85 => format!("fuzz{slot}-{}", self.instances_made),
            85..90 => "%s%d%n%%".to_owned(),
            90..93 => "x".repeat(3000),
            93..95 => "µ-инстанс".to_owned(),
            _ => String::new(),
        };
        let null_name = self.chance(0.04);
        let fmu_type = match self.rng.random_range(0..20) {
            0..8 => sys::fmi2Type_fmi2ModelExchange,
            8 => self.rng.random_range(2..1000),
            _ => sys::fmi2Type_fmi2CoSimulation,
        };
        let interface = if fmu_type == sys::fmi2Type_fmi2ModelExchange {
            Interface::ModelExchange
        } else {
            Interface::CoSimulation
        };
        let own_guid = self.fmu.guid.clone();
        let guid = match self.rng.random_range(0..40) {
            0 => None,
            1 => Some(own_guid.to_uppercase()),
            2 => Some(own_guid.trim_matches(|c| c == '{' || c == '}').to_owned()),
            3 => Some("{00000000-0000-0000-0000-000000000000}".to_owned()),
            4 => Some(String::new()),
            _ => Some(own_guid.clone()),
        };
        let location = match self.rng.random_range(0..20) {
            0..12 => None,
            12..15 => Some("file:///tmp/fuzz%20dir/resources"),
            15 => Some("http://example.org/resources"),
            16 => Some("not a uri"),
            17 => Some("file:"),
            18 => Some(""),
            _ => Some("file://localhost/tmp/%ZZ"),
        };
        let (null_functions, has_logger) = match self.rng.random_range(0..40) {
            0 => (true, false),
            1 => (false, false),
            _ => (false, true),
        };
        let logging_on = self.rng.random_range(0..3) as sys::fmi2Boolean;
        let visible = self.rng.random_range(0..2) as sys::fmi2Boolean;

        let sink = Box::new(LogSink::default());
        let mut callbacks = Box::new(crate::callbacks_for(&sink));
        if !has_logger {
            callbacks.logger = None;
        }
        let name_c = CString::new(name.clone()).expect("no NUL in names");
        let guid_c = guid.as_ref().map(|g| CString::new(g.as_str()).unwrap());
        let location_c = location.map(|l| CString::new(l).unwrap());
        self.begin("fmi2Instantiate", Some(slot));
        self.report.calls_without_status += 1;
        // SAFETY: every string is NULL or a live CString, and the callbacks are NULL or boxed
        // in the `Live` slot, so they outlive the instance that logs through them.
        let c = unsafe {
            self.fmu.binding.fmi2Instantiate(
                if null_name {
                    ptr::null()
                } else {
                    name_c.as_ptr()
                },
                fmu_type,
                guid_c.as_ref().map_or(ptr::null(), |g| g.as_ptr()),
                location_c.as_ref().map_or(ptr::null(), |l| l.as_ptr()),
                if null_functions {
                    ptr::null()
                } else {
                    &*callbacks
                },
                visible,
                logging_on,
            )
        };
        let type_offered = fmu_type == sys::fmi2Type_fmi2CoSimulation
            || (fmu_type == sys::fmi2Type_fmi2ModelExchange && self.fmu.offers_model_exchange());
        let acceptable = !null_name
            && !null_functions
            && type_offered
            && guid.as_deref() == Some(own_guid.as_str());
        let log = sink.take();
        self.others_silent(None);
        let describe = || {
            format!(
                "name {:?}, type {fmu_type}, GUID {guid:?}, location {location:?}, functions {}, logger {}",
                (!null_name).then_some(&name),
                !null_functions,
                has_logger
            )
        };
        if c.is_null() {
            if acceptable {
                self.fail(format!(
                    "fmi2Instantiate refused legal arguments ({}): {log:#?}",
                    describe()
                ));
            }
            if has_logger && !log.iter().any(|r| r.status == ERROR) {
                self.fail(format!(
                    "fmi2Instantiate refused ({}) without an error message: {log:#?}",
                    describe()
                ));
            }
            self.report.instantiations_refused += 1;
            return;
        }
        if !acceptable {
            self.fail(format!("fmi2Instantiate accepted {}", describe()));
        }
        self.report.instantiated += 1;
        if interface == Interface::ModelExchange {
            self.report.model_exchange_instances += 1;
        }
        let mut model = self.fresh.clone();
        model.interface = interface;
        self.slots[slot] = Some(Live {
            c,
            sink,
            _callbacks: callbacks,
            name,
            has_logger,
            state: State::Instantiated,
            model,
            lent: Vec::new(),
        });
    }

    pub(super) fn free_instance(&mut self, slot: usize) {
        // The states the instance made are freed with it (FMI 2.0.4 §2.1.5:
        // fmi2FreeInstance frees all memory the FMU interface allocated), so a
        // careful importer frees them first or never uses them again; the
        // fuzzer does either.
        let owned: Vec<usize> = (0..self.handles.len())
            .filter(|i| self.handles[*i].owner == slot)
            .collect();
        let free_first = self.chance(0.5);
        for index in owned.into_iter().rev() {
            if free_first {
                self.free_handle(slot, index);
            } else {
                self.handles.swap_remove(index);
            }
        }
        // Freeing is the next call on the instance: what it lent must hold
        // until then.
        self.verify_lent_strings(slot);
        let live = self.slots[slot].take().expect("a live instance");
        self.begin("fmi2FreeInstance", Some(slot));
        self.report.calls_without_status += 1;
        // SAFETY: `live.c` is a live instance, freed once: its slot was emptied above and the
        // states it owned were dropped from `handles`.
        unsafe { self.fmu.binding.fmi2FreeInstance(live.c) };
        // Messages sent while freeing (call tracing) belong to the instance.
        for record in live.sink.take() {
            if record.status >= ERROR {
                self.fail(format!("fmi2FreeInstance logged an error: {record:#?}"));
            }
        }
        self.others_silent(None);
    }

    /// Frees our handle `index` through the instance in `slot`, checked.
    pub(super) fn free_handle(&mut self, slot: usize, index: usize) {
        let mut pointer = self.handles[index].ptr;
        self.begin("fmi2FreeFMUstate", Some(slot));
        // SAFETY: `c` is the live instance in `slot` and `pointer` one of its own states, freed
        // once (its handle is removed below).
        let status = unsafe {
            self.fmu
                .binding
                .fmi2FreeFMUstate(self.live(slot).c, &mut pointer)
        };
        self.check(slot, "fmi2FreeFMUstate", status, &[OK], false, || {
            "one of its own states".to_owned()
        });
        if !pointer.is_null() {
            self.fail("fmi2FreeFMUstate returned OK but left *FMUstate non-NULL".to_owned());
        }
        self.handles.swap_remove(index);
    }

    /// Frees everything, checked, and verifies that the other FMU's instance
    /// still works after the calls aimed at it by mistake.
    pub(super) fn finish(&mut self) {
        for slot in 0..SLOTS {
            if self.slots[slot].is_some() {
                self.free_instance(slot);
            }
        }
        if !self.handles.is_empty() {
            self.fail(format!(
                "{} FMU states outlived their instances",
                self.handles.len()
            ));
        }
        if let Some(mut foreign) = self.foreign.take() {
            let log = foreign.instance.take_log();
            if !log.is_empty() {
                self.fail(format!(
                    "the other FMU's instance heard of this one's calls: {log:#?}"
                ));
            }
            if foreign.instance.do_step(1e-4) != OK {
                self.fail(format!(
                    "the other FMU's instance no longer steps: {:#?}",
                    foreign.instance.take_log()
                ));
            }
            if foreign.instance.free_state(&mut foreign.state) != OK {
                self.fail("the other FMU's state could not be freed".to_owned());
            }
        }
    }
}
