//! FMU state across the state machine: a state taken in any state an instance
//! can be in, restored into an instance in any state (FMI 2.0.4 §2.1.8 allows
//! `fmi2SetFMUstate` in all of them, and after `fmi2Error` an importer
//! recovers this way, §2.1.3), in memory and through the serialized bytes.
//!
//! What is asked of the FMU: the restored instance is the one the state was
//! taken from, state machine included. It is checked three ways: the restore
//! succeeds; a state taken from the restored instance serializes to the same
//! bytes as the original (values, time and machine state all in them); and a
//! continuation of calls, legal in the state the original was in and chosen so
//! that the neighbouring states refuse one of them, gives the same statuses and
//! the same outputs, bit for bit, as the original instance gave.

use fmi_sys::fmi2 as sys;

use super::{has_message, interfaces};
use crate::{ERROR, Fmu, FmuUnderTest, Instance, Interface, InterfaceStates, OK, State};

/// Statuses and output bits, in call order.
type Trace = Vec<u64>;

/// Value references of every Real output.
fn real_outputs(fmu: &Fmu) -> Vec<u32> {
    fmu.with_causality(fmi_schema::fmi2::Causality::Output)
        .filter(|v| v.kind == "Real")
        .map(|v| v.vr)
        .collect()
}

fn record_outputs(inst: &Instance<'_>, trace: &mut Trace) {
    let (status, values) = inst.get_real(&real_outputs(inst.fmu));
    trace.push(status as u64);
    if status == OK {
        trace.extend(values.iter().map(|v| v.to_bits()));
    }
}

/// Steps (Co-Simulation) or integrates (Model Exchange) the instance with an
/// input that varies with `phase`, recording statuses, outputs and states.
fn run(inst: &mut Instance<'_>, trace: &mut Trace, phase: f64) {
    let input = inst.fmu.real_input().vr;
    match inst.interface {
        Interface::CoSimulation => {
            for k in 0..60 {
                trace.push(inst.set_real(&[input], &[3.0 + (phase + 0.1 * k as f64).sin()]) as u64);
                trace.push(inst.do_step(1e-4) as u64);
                record_outputs(inst, trace);
            }
        }
        Interface::ModelExchange => {
            for k in 0..10 {
                trace.push(inst.set_real(&[input], &[3.0 + (phase + 0.1 * k as f64).sin()]) as u64);
                inst.integrate_rk4(5e-6, 4);
                record_outputs(inst, trace);
                let n = inst.fmu.number_of_states();
                let (status, x) = inst.get_continuous_states(n);
                trace.push(status as u64);
                trace.extend(x.iter().map(|v| v.to_bits()));
            }
        }
    }
}

/// The calls that continue an instance from `state`, as the importer that
/// saved it would go on: finish initialization, enter continuous time, step or
/// integrate; from a terminated or failed instance, read what can be read,
/// then reset and start again. The first call that is not legal in a
/// neighbouring state is the one that tells it apart.
fn continuation(inst: &mut Instance<'_>, state: State) -> Trace {
    let mut trace = Trace::new();
    let parameter = inst.fmu.fixed_real_parameter().vr;
    let me = inst.interface == Interface::ModelExchange;
    match state {
        State::Instantiated => {
            trace.push(inst.setup(0.0) as u64);
            trace.push(inst.enter_init() as u64);
            trace.push(inst.exit_init() as u64);
        }
        State::InitializationMode => trace.push(inst.exit_init() as u64),
        State::StepComplete | State::EventMode | State::ContinuousTimeMode => {}
        State::Terminated | State::Error => {
            record_outputs(inst, &mut trace);
            if me {
                let n = inst.fmu.number_of_states();
                let (status, dx) = inst.get_derivatives(n);
                trace.push(status as u64);
                trace.extend(dx.iter().map(|v| v.to_bits()));
            } else {
                // Legal in Terminated, not in Error.
                let mut time = f64::NAN;
                // SAFETY: `inst.c` is a live instance and `time` a local.
                let status = unsafe {
                    inst.fmu.binding.fmi2GetRealStatus(
                        inst.c,
                        sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                        &mut time,
                    )
                };
                trace.push(status as u64);
                trace.push(time.to_bits());
            }
            trace.push(inst.reset() as u64);
            trace.push(inst.setup(0.0) as u64);
            trace.push(inst.enter_init() as u64);
            trace.push(inst.exit_init() as u64);
        }
    }
    if me && state != State::ContinuousTimeMode {
        // Legal in event mode only.
        let (status, info) = inst.new_discrete_states();
        trace.push(status as u64);
        trace.push(info.newDiscreteStatesNeeded as u64);
        trace.push(inst.enter_continuous_time_mode() as u64);
    }
    let (status, value) = inst.get_real(&[parameter]);
    trace.push(status as u64);
    trace.push(value[0].to_bits());
    run(inst, &mut trace, 0.0);
    trace
}

/// A fresh instance of `interface` in `state`, away from the start values
/// (see [`drive`]).
fn prepared<'a>(fmu: &'a Fmu, interface: Interface, state: State, phase: f64) -> Instance<'a> {
    let mut inst = fmu.instantiate_for(interface, &format!("restore-{state:?}"));
    drive(&mut inst, interface, state, phase);
    inst
}

/// Drives an instance in Instantiated into `state` away from the start
/// values: the fixed parameter changed, the inputs set, and when initialized,
/// moved for a while (`phase` makes two such instances differ); the error
/// state after an illegal call.
fn drive(inst: &mut Instance<'_>, interface: Interface, state: State, phase: f64) {
    let fmu = inst.fmu;
    let parameter = fmu.fixed_real_parameter();
    let start = parameter.start.expect("parameters have start values");
    assert_eq!(
        inst.set_real(&[parameter.vr], &[start * (1.01 + 0.01 * phase) + 1e-3]),
        OK
    );
    assert_eq!(inst.set_real(&[fmu.real_input().vr], &[4.0 + phase]), OK);
    match state {
        State::Instantiated => {}
        State::InitializationMode => {
            assert_eq!(inst.setup(0.0), OK);
            assert_eq!(inst.enter_init(), OK);
        }
        _ => {
            inst.initialize();
            if interface == Interface::ModelExchange {
                inst.event_iteration();
            }
            let mut scratch = Trace::new();
            run(inst, &mut scratch, phase);
            match state {
                State::StepComplete | State::ContinuousTimeMode => {}
                State::EventMode => assert_eq!(inst.enter_event_mode(), OK),
                State::Terminated => assert_eq!(inst.terminate(), OK),
                // An illegal call: initialization again.
                State::Error => assert_eq!(inst.enter_init(), ERROR),
                State::Instantiated | State::InitializationMode => unreachable!(),
            }
        }
    }
    inst.take_log();
}

fn serialized(inst: &Instance<'_>) -> Vec<u8> {
    let (status, mut state) = inst.get_state();
    assert_eq!(status, OK, "fmi2GetFMUstate: {:#?}", inst.take_log());
    let (status, bytes) = inst.serialize(state);
    assert_eq!(status, OK, "fmi2SerializeFMUstate: {:#?}", inst.take_log());
    assert_eq!(inst.free_state(&mut state), OK);
    bytes
}

/// Restores `handle` into `inst` and compares it with the original: the
/// serialized bytes of a state taken afterwards, and the continuation from the
/// state the original was taken in (at its time `time`). `None` when they
/// agree, or what differs.
fn restore_and_compare(
    inst: &mut Instance<'_>,
    handle: sys::fmi2FMUstate,
    taken: State,
    time: f64,
    bytes: &[u8],
    reference: &Trace,
) -> Option<String> {
    let status = inst.set_state(handle);
    if status != OK {
        return Some(format!("fmi2SetFMUstate {status}: {:#?}", inst.take_log()));
    }
    if serialized(inst) != bytes {
        return Some("a state taken after the restore differs from the original".to_owned());
    }
    inst.time = time;
    let trace = continuation(inst, taken);
    (trace != *reference).then(|| {
        format!(
            "the continuation differs from the original's: {:#?}",
            inst.take_log()
        )
    })
}

/// The restores [`fmu_state_restores_every_machine_state`] ran for one
/// interface, counted as they ran (so that a document giving their number
/// can be checked against the run): `taken` machine states a state was taken
/// in, times `restored_into` machine states it was restored into, times the
/// ways of restoring (in memory, deserialized), is `cases`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RestoreCases {
    pub interface: Interface,
    pub taken: usize,
    pub restored_into: usize,
    pub cases: usize,
}

impl RestoreCases {
    /// Ways of restoring each state into each machine state.
    pub fn ways(&self) -> usize {
        self.cases / (self.taken * self.restored_into).max(1)
    }
}

impl std::fmt::Display for RestoreCases {
    /// `5 × 5 × 2 = 50`, as a document prints the product.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} × {} × {} = {}",
            self.taken,
            self.restored_into,
            self.ways(),
            self.cases
        )
    }
}

/// Every combination, for every interface the FMU offers: a state taken in
/// each machine state (after a changed parameter, set inputs and some
/// simulated time), restored into an instance in each machine state (the
/// error state included), in memory into the same instance and deserialized
/// into another, continues as the original, bit for bit, state machine
/// included. A state of one interface is refused by an instance of the other.
/// Returns the cases run, per interface.
pub fn fmu_state_restores_every_machine_state(fmu: &Fmu) -> Vec<RestoreCases> {
    let mut failures = Vec::new();
    let mut counted = Vec::new();
    for interface in interfaces(fmu) {
        let mut count = RestoreCases {
            interface,
            taken: 0,
            restored_into: 0,
            cases: 0,
        };
        for &taken in interface.states() {
            count.taken += 1;
            let mut restored_into = 0;
            let mut source = prepared(fmu, interface, taken, 0.0);
            let time = source.time;
            let bytes = serialized(&source);
            let (status, mut state) = source.get_state();
            assert_eq!(status, OK);
            let reference = continuation(&mut source, taken);
            for &target in interface.states() {
                restored_into += 1;
                let case = |how: &str| {
                    format!("{interface:?}: taken in {taken:?}, restored into {target:?} ({how})")
                };
                // In memory, into the same instance moved elsewhere.
                assert_eq!(source.reset(), OK);
                drive(&mut source, interface, target, 1.0);
                if let Some(problem) =
                    restore_and_compare(&mut source, state, taken, time, &bytes, &reference)
                {
                    failures.push(format!("{}: {problem}", case("in memory")));
                }
                count.cases += 1;
                // Deserialized, into another instance.
                let mut other = prepared(fmu, interface, target, 2.0);
                let (status, mut restored) = other.deserialize(&bytes);
                assert_eq!(status, OK, "{:#?}", other.take_log());
                if let Some(problem) =
                    restore_and_compare(&mut other, restored, taken, time, &bytes, &reference)
                {
                    failures.push(format!("{}: {problem}", case("deserialized")));
                }
                count.cases += 1;
                assert_eq!(other.free_state(&mut restored), OK);
            }
            assert_eq!(source.free_state(&mut state), OK);
            // Every taken state is restored into the same machine states.
            count.restored_into = restored_into;
        }
        counted.push(count);
    }
    // Across interfaces: refused, with the reason.
    if fmu.offers_model_exchange() {
        let me = prepared(
            fmu,
            Interface::ModelExchange,
            State::ContinuousTimeMode,
            0.0,
        );
        let cs = prepared(fmu, Interface::CoSimulation, State::StepComplete, 0.0);
        for (from, into) in [(&me, &cs), (&cs, &me)] {
            let (status, mut handle) = into.deserialize(&serialized(from));
            assert_eq!(status, OK, "the bytes themselves are sound");
            assert_eq!(
                into.set_state(handle),
                ERROR,
                "a state of the other interface restored"
            );
            let log = into.take_log();
            assert!(has_message(&log, "interface"), "{log:#?}");
            assert_eq!(into.free_state(&mut handle), OK);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    counted
}
