//! FlexureStage as Model Exchange against FlexureStage as Co-Simulation, on
//! the calibration fingerprints' procedures (`piezo_models::fingerprint`):
//! both interfaces of the one binary, through the C ABI, with the same
//! commands held over the same 100 µs samples (10 µs for the resonance
//! record).
//!
//! - Co-Simulation: `fmi2DoStep` per sample, with the hysteresis chords cut
//!   to 1 mV (`solver.max_voltage_step`) so that its own approximation is far
//!   below the tolerance.
//! - Model Exchange: as an importer with a variable-step solver runs it: at
//!   each sample an event (enter event mode, set the inputs, new discrete
//!   states, back to continuous time), then Dormand-Prince 8(5,3) (the
//!   `ode_solvers` crate) over the sample on the states scaled by their
//!   nominals, relative and absolute tolerance 1e-10, through
//!   `fmi2SetTime`/`fmi2SetContinuousStates`/`fmi2GetDerivatives`, and
//!   `fmi2CompletedIntegratorStep` after it. Where an event indicator
//!   changes sign over the sample (FMI's z > 0 against z <= 0), a crossing
//!   (the first, unless two indicators change sign in the same sample) is
//!   located by bisection to 2^-40 of the sample (or the time's
//!   resolution), and the
//!   importer's event is taken there (event mode, new discrete states, the
//!   states read again, back to continuous time) before the sample goes on:
//!   the kinks of the Bouc-Wen rates and, with `return_point_memory`, the
//!   memory's wipe-outs inside a sample.
//!
//! Both parameter sets the stage ships with its loops open and closed run:
//! `3dof_no_memory`, and the default (the return-point memory on).
//!
//! Asserted: every sensor reading of every sample within 1e-6 µm; the
//! fingerprints computed from them (coupling spans and loop widths, major
//! loops, the 790 Hz θ mode) the same; and docs/fmi.md's table ("On the
//! calibration fingerprints") prints these figures (`tests/docs_figures.rs`
//! says within what). `-- --nocapture` prints the figures.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::{Fmu, Instance, OK, WARNING};
use fmi2_cosim::parameter_set::{ScalarValue, parameter_values};
use fmu_plant::FlexureStageFmu;
use ode_solvers::{Dop853, SVector, System};
use piezo_models::FlexureStageParams;
use piezo_models::fingerprint::{
    self, FULL_COMMAND, RAMP_TIME, RESONANCE_RECORD_TIME, RESONANCE_SAMPLE_PERIOD,
    RESONANCE_STEP_COMMAND, SAMPLE_PERIOD,
};

const STATES: usize = 19;
const INDICATORS: usize = 21;
type State = SVector<f64, STATES>;
/// Bisection steps that locate a crossing inside a sample: to 2^-40 of it.
const BISECTIONS: usize = 40;

/// The agreement asked of the two interfaces, on every sensor reading.
const TOLERANCE_UM: f64 = 1e-6;
/// Dormand-Prince tolerances (relative, and absolute on the nominal-scaled
/// states).
const SOLVER_TOLERANCE: f64 = 1e-10;

fn plant() -> Fmu {
    fmi2_conformance::workspace::load::<FlexureStageFmu>("fmu-plant")
}

/// The right-hand side through the C ABI, on states scaled by their nominals.
struct Scaled<'a> {
    inst: &'a Instance<'a>,
    nominals: [f64; STATES],
}

impl System<f64, State> for Scaled<'_> {
    fn system(&self, t: f64, z: &State, dz: &mut State) {
        let x: Vec<f64> = (0..STATES).map(|i| z[i] * self.nominals[i]).collect();
        assert_eq!(self.inst.set_time(t), OK);
        let dx = self.inst.derivatives_at(&x);
        for i in 0..STATES {
            dz[i] = dx[i] / self.nominals[i];
        }
    }
}

/// One instance of either interface, stepped a sample at a time with the
/// commands held.
enum Rig<'a> {
    CoSimulation(Instance<'a>),
    ModelExchange {
        inst: Instance<'a>,
        nominals: [f64; STATES],
        evaluations: usize,
        events: usize,
    },
}

/// Sets every parameter of `params` (by FMI name) on an instantiated
/// instance.
fn apply(inst: &Instance<'_>, params: &FlexureStageParams) {
    let model = FlexureStageFmu::with_params(params.clone()).expect("a shipped parameter set");
    for (name, value) in parameter_values(&model) {
        let vr = inst.fmu.variable(name).vr;
        let status = match value {
            ScalarValue::Real(v) => inst.set_real(&[vr], &[v]),
            ScalarValue::Integer(v) => inst.set_integer(&[vr], &[v]),
            ScalarValue::Boolean(v) => inst.set_boolean(&[vr], &[v]),
            ScalarValue::String(_) => continue,
        };
        assert_eq!(status, OK, "{name}: {:#?}", inst.take_log());
    }
}

/// Whether an indicator changed domain (FMI 2.0: z > 0 against z <= 0).
fn crossed(before: &[f64], after: &[f64]) -> bool {
    before
        .iter()
        .zip(after)
        .any(|(a, b)| (*a > 0.0) != (*b > 0.0))
}

impl<'a> Rig<'a> {
    fn co_simulation(fmu: &'a Fmu, params: &FlexureStageParams) -> Rig<'a> {
        let mut inst = fmu.instantiate("cs", false);
        apply(&inst, params);
        let vr = fmu.variable("solver.max_voltage_step").vr;
        assert_eq!(inst.set_real(&[vr], &[1e-3]), OK);
        inst.initialize();
        Rig::CoSimulation(inst)
    }

    fn model_exchange(fmu: &'a Fmu, params: &FlexureStageParams) -> Rig<'a> {
        let mut inst = fmu.instantiate_model_exchange("me", false);
        apply(&inst, params);
        inst.initialize();
        inst.event_iteration();
        let (status, nominals) = inst.get_nominals(STATES);
        assert_eq!(status, OK);
        Rig::ModelExchange {
            inst,
            nominals: nominals.try_into().expect("19 states"),
            evaluations: 0,
            events: 0,
        }
    }

    fn instance(&self) -> &Instance<'a> {
        match self {
            Rig::CoSimulation(inst) | Rig::ModelExchange { inst, .. } => inst,
        }
    }

    fn sensors(&self) -> [f64; 3] {
        let inst = self.instance();
        let vrs = ["s1", "s2", "s3"].map(|name| inst.fmu.variable(name).vr);
        let (status, values) = inst.get_real(&vrs);
        assert_eq!(status, OK);
        [values[0], values[1], values[2]]
    }

    /// One sample of length `h` with `commands` held; the sensors after it.
    fn step(&mut self, commands: [f64; 3], h: f64) -> [f64; 3] {
        match self {
            Rig::CoSimulation(inst) => {
                let vrs = ["u1", "u2", "u3"].map(|name| inst.fmu.variable(name).vr);
                assert_eq!(inst.set_real(&vrs, &commands), OK);
                let status = inst.do_step(h);
                assert!(status == OK || status == WARNING, "{:#?}", inst.take_log());
            }
            Rig::ModelExchange {
                inst,
                nominals,
                evaluations,
                events,
            } => {
                // A jump of the inputs is an event for the importer.
                let vrs = ["u1", "u2", "u3"].map(|name| inst.fmu.variable(name).vr);
                assert_eq!(inst.enter_event_mode(), OK);
                let status = inst.set_real(&vrs, &commands);
                assert!(status == OK || status == WARNING);
                let (status, _) = inst.new_discrete_states();
                assert_eq!(status, OK);
                assert_eq!(inst.enter_continuous_time_mode(), OK);
                let nominals = *nominals;
                let end = inst.time + h;
                loop {
                    let t0 = inst.time;
                    let (status, x) = inst.get_continuous_states(STATES);
                    assert_eq!(status, OK);
                    let z0 = State::from_fn(|i, _| x[i] / nominals[i]);
                    let (_, before) = inst.get_event_indicators(INDICATORS);
                    // The states at t0 + span from (t0, z0), left set in the instance.
                    let mut reach = |span: f64| -> Vec<f64> {
                        let system = Scaled {
                            inst: &*inst,
                            nominals,
                        };
                        let mut solver = Dop853::new(
                            system,
                            t0,
                            t0 + span,
                            span,
                            z0,
                            SOLVER_TOLERANCE,
                            SOLVER_TOLERANCE,
                        );
                        solver.set_output(ode_solvers::OutputType::Sparse);
                        let stats = solver.integrate().expect("Dop853 integrates the sample");
                        *evaluations += stats.num_eval as usize;
                        let z1 = solver.y_out().last().expect("the end of the span");
                        let x1: Vec<f64> = (0..STATES).map(|i| z1[i] * nominals[i]).collect();
                        assert_eq!(inst.set_time(t0 + span), OK);
                        assert_eq!(inst.set_continuous_states(&x1), OK);
                        inst.get_event_indicators(INDICATORS).1
                    };
                    let rest = end - t0;
                    if !crossed(&before, &reach(rest)) {
                        break;
                    }
                    // A crossing, to 2^-40 of the sample (the first where
                    // one indicator changes sign; the rig compares the
                    // ends of each span, so a sign that changes and
                    // changes back inside a sample goes unseen, which held
                    // inputs do not make); the event just past it.
                    let (mut lo, mut hi) = (0.0, rest);
                    // No finer than the time can resolve (a few ulps of t).
                    let resolution = 16.0 * f64::EPSILON * end.abs();
                    for _ in 0..BISECTIONS {
                        if hi - lo <= resolution {
                            break;
                        }
                        let mid = 0.5 * (lo + hi);
                        if crossed(&before, &reach(mid)) {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    reach(hi);
                    inst.time = t0 + hi;
                    let (status, _, _) = inst.completed_integrator_step();
                    assert!(status == OK || status == WARNING, "{:#?}", inst.take_log());
                    inst.event_iteration();
                    *events += 1;
                    if hi >= rest {
                        break;
                    }
                }
                inst.time = end;
                assert_eq!(inst.set_time(inst.time), OK);
                let (status, _, _) = inst.completed_integrator_step();
                assert!(status == OK || status == WARNING, "{:#?}", inst.take_log());
            }
        }
        self.sensors()
    }
}

/// A procedure of the fingerprints: a sequence of samples, each its length
/// and the commands held over it.
type Procedure = Vec<(f64, [f64; 3])>;

/// `duration` s at `period`, the commands of sample k being demand(k·period).
fn run(procedure: &mut Procedure, duration: f64, period: f64, demand: impl Fn(f64) -> [f64; 3]) {
    let steps = (duration / period).round() as usize;
    for k in 1..=steps {
        procedure.push((period, demand(k as f64 * period)));
    }
}

/// The linear 1 s ramp of `fingerprint::Rig::ramp_to`.
fn ramp(procedure: &mut Procedure, from: [f64; 3], to: [f64; 3]) {
    run(procedure, RAMP_TIME, SAMPLE_PERIOD, |t| {
        let f = t / RAMP_TIME;
        [0, 1, 2].map(|i| from[i] + (to[i] - from[i]) * f)
    });
}

/// The procedures, exactly as `piezo_models::fingerprint` runs them, with the
/// sweep amplitudes its calibration solves for.
fn procedures(params: &FlexureStageParams) -> Vec<(&'static str, Procedure, f64)> {
    let u_home = fingerprint::x_home_command(params);
    let sweeps = fingerprint::coupling_sweeps(params, u_home);
    let home = [0.0, u_home, u_home];
    let tau = std::f64::consts::TAU;
    let mut list = Vec::new();

    let mut y = Procedure::new();
    ramp(&mut y, [0.0; 3], home);
    let a = sweeps.y_sweep_amplitude;
    run(&mut y, 2.0, SAMPLE_PERIOD, |t| {
        [0.5 * a * (1.0 - (tau * t).cos()), u_home, u_home]
    });
    list.push(("y sweep (s2, s3 from y)", y, 1.0));

    let mut x = Procedure::new();
    let a = sweeps.x_sweep_amplitude;
    run(&mut x, 2.0, SAMPLE_PERIOD, |t| {
        let u = 0.5 * a * (1.0 - (tau * t).cos());
        [0.0, u, u]
    });
    list.push(("x sweep (y from x)", x, 1.0));

    let mut rotation = Procedure::new();
    ramp(&mut rotation, [0.0; 3], home);
    let d = sweeps.rotation_sweep_amplitude;
    run(&mut rotation, 2.75, SAMPLE_PERIOD, |t| {
        let s = d * (tau * t).sin();
        [0.0, u_home + s, u_home - s]
    });
    list.push(("rotation sweep (y from θ)", rotation, 1.75));

    let wave = move |t: f64| 0.5 * FULL_COMMAND * (1.0 - (tau * t).cos());
    let mut major_x = Procedure::new();
    run(&mut major_x, 2.0, SAMPLE_PERIOD, |t| {
        [0.0, wave(t), wave(t)]
    });
    list.push(("major loop x", major_x, 1.0));
    let mut major_y = Procedure::new();
    run(&mut major_y, 2.0, SAMPLE_PERIOD, |t| [wave(t), 0.0, 0.0]);
    list.push(("major loop y", major_y, 1.0));

    let mut resonance = Procedure::new();
    ramp(&mut resonance, [0.0; 3], home);
    run(&mut resonance, 0.5, SAMPLE_PERIOD, |_| home);
    let held = [
        0.0,
        u_home + RESONANCE_STEP_COMMAND,
        u_home - RESONANCE_STEP_COMMAND,
    ];
    run(
        &mut resonance,
        RESONANCE_RECORD_TIME,
        RESONANCE_SAMPLE_PERIOD,
        |_| held,
    );
    list.push(("θ resonance record", resonance, 1.5));
    list
}

struct Outcome {
    sensors: Vec<[f64; 3]>,
    seconds: f64,
}

/// The sensors of every sample, and (for Model Exchange) the derivative
/// evaluations and the located events.
fn simulate(mut rig: Rig<'_>, procedure: &Procedure) -> (Outcome, (usize, usize)) {
    let started = std::time::Instant::now();
    let sensors = procedure
        .iter()
        .map(|(h, commands)| rig.step(*commands, *h))
        .collect();
    let evaluations = match rig {
        Rig::ModelExchange {
            evaluations,
            events,
            ..
        } => (evaluations, events),
        Rig::CoSimulation(_) => (0, 0),
    };
    (
        Outcome {
            sensors,
            seconds: started.elapsed().as_secs_f64(),
        },
        evaluations,
    )
}

/// Sensor readings of samples from `from` s on (the measured cycle).
fn window<'s>(
    procedure: &Procedure,
    sensors: &'s [[f64; 3]],
    from: f64,
) -> (Vec<[f64; 3]>, Vec<&'s [f64; 3]>) {
    let mut t = 0.0;
    let mut commands = Vec::new();
    let mut readings = Vec::new();
    for ((h, u), s) in procedure.iter().zip(sensors) {
        t += h;
        if t >= from - 1e-9 {
            commands.push(*u);
            readings.push(s);
        }
    }
    (commands, readings)
}

#[test]
fn model_exchange_and_co_simulation_agree_on_the_fingerprints() {
    agree_on_the_fingerprints(
        &FlexureStageParams::without_memory(),
        "### On the calibration fingerprints (Rust, through the C ABI)",
    );
}

/// The same with the stacks' minor loops closed (the default): the return-point memory's
/// turns at the samples' input events, its wipe-outs located inside them.
#[test]
fn model_exchange_runs_the_return_point_memory_on_the_fingerprints() {
    let params = FlexureStageParams::default();
    assert!(params.return_point_memory);
    agree_on_the_fingerprints(
        &params,
        "### On the calibration fingerprints, with the return-point memory",
    );
}

fn agree_on_the_fingerprints(params: &FlexureStageParams, section: &str) {
    let fmu = plant();
    let spacing = params.sensor_spacing_mm * 1e3;
    // docs/fmi.md's rows: procedure, samples, largest difference, fingerprint.
    let mut rows = Vec::new();
    for (name, procedure, from) in procedures(params) {
        let (cs, _) = simulate(Rig::co_simulation(&fmu, params), &procedure);
        let (me, (evaluations, events)) = simulate(Rig::model_exchange(&fmu, params), &procedure);
        let worst = cs
            .sensors
            .iter()
            .zip(&me.sensors)
            .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs()))
            .fold(0.0, f64::max);
        println!(
            "{name}: {} samples, largest |s_ME - s_CS| {worst:.2e} um; CS {:.2} s, ME {:.2} s \
             ({evaluations} derivative evaluations, {events} located events)",
            procedure.len(),
            cs.seconds,
            me.seconds
        );
        assert!(worst <= TOLERANCE_UM, "{name}: {worst:e} um");

        // The fingerprints computed from both records.
        let (commands, cs_window) = window(&procedure, &cs.sensors, from);
        let (_, me_window) = window(&procedure, &me.sensors, from);
        let shapes = |readings: &[&[f64; 3]],
                      input: &dyn Fn(&[f64; 3]) -> f64,
                      output: &dyn Fn(&[f64; 3]) -> f64| {
            let u: Vec<f64> = commands.iter().map(input).collect();
            let y: Vec<f64> = readings.iter().map(|s| output(s)).collect();
            fingerprint::loop_shape(&u, &y)
        };
        // ME - CS of the loop's span and width.
        let compare = |what: &str,
                       input: &dyn Fn(&[f64; 3]) -> f64,
                       output: &dyn Fn(&[f64; 3]) -> f64|
         -> (f64, f64) {
            let (a, b) = (
                shapes(&cs_window, input, output),
                shapes(&me_window, input, output),
            );
            let (span, width) = (b.span_um - a.span_um, b.max_width_um - a.max_width_um);
            println!(
                "  {what}: span {:.6} um, width {:.6} um (ME - CS: {span:.1e}, {width:.1e})",
                a.span_um, a.max_width_um
            );
            assert!(span.abs() <= 2.0 * TOLERANCE_UM, "{what} span");
            assert!(width.abs() <= 2.0 * TOLERANCE_UM, "{what} width");
            (span, width)
        };
        let signed = |(span, width): (f64, f64)| format!("span {span:.1e}, width {width:.1e} µm");
        let fingerprints = match name {
            "y sweep (s2, s3 from y)" => {
                let input = |u: &[f64; 3]| u[0];
                let s2 = compare("s2 from y", &input, &|s| s[1]);
                let s3 = compare("s3 from y", &input, &|s| s[2]);
                format!(
                    "spans within {:.1e}, loop widths within {:.1e} µm",
                    s2.0.abs().max(s3.0.abs()),
                    s2.1.abs().max(s3.1.abs())
                )
            }
            "x sweep (y from x)" => signed(compare("y from x", &|u| u[1], &|s| s[0])),
            "rotation sweep (y from θ)" => {
                signed(compare("y from rotation", &|u| 0.5 * (u[1] - u[2]), &|s| {
                    s[0]
                }))
            }
            "major loop x" => signed(compare("major loop x", &|u| u[1], &|s| 0.5 * (s[1] + s[2]))),
            "major loop y" => signed(compare("major loop y", &|u| u[0], &|s| s[0])),
            _ => {
                let theta = |readings: &[&[f64; 3]]| -> Vec<f64> {
                    readings.iter().map(|s| (s[1] - s[2]) / spacing).collect()
                };
                let cs_peak =
                    fingerprint::spectral_peak_hz(&theta(&cs_window), RESONANCE_SAMPLE_PERIOD);
                let me_peak =
                    fingerprint::spectral_peak_hz(&theta(&me_window), RESONANCE_SAMPLE_PERIOD);
                println!("  theta mode: CS {cs_peak} Hz, ME {me_peak} Hz");
                assert_eq!(cs_peak, me_peak);
                assert!(
                    (cs_peak - 790.0).abs() <= 0.02 * 790.0,
                    "seed 000 §2: 790 Hz"
                );
                format!("θ mode: {cs_peak:.0} Hz in both")
            }
        };
        rows.push(vec![
            Some(name.to_owned()),
            Some(fmi2_conformance::thousands(procedure.len() as u64)),
            Some(format!("{worst:.1e} µm")),
            Some(fingerprints),
        ]);
    }
    docs_figures::assert_documented("fmi.md", section, 1, &rows);
}
