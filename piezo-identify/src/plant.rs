//! Drives a plant FMU, as the identification experiments of seed 000 drove
//! the real stage: the FMU is unpacked, its binary loaded with dlopen and
//! stepped through the FMI 2.0 C ABI (the importer, `fmi2-import`).
//!
//! The plant must have inputs `u1`, `u2`, `u3` [V] and outputs `s1`, `s2`,
//! `s3` [µm] (FlexureStage's interface): s1 reads y, s2 and s3 the two x
//! sensors, x = (s2 + s3)/2, θ = (s2 − s3)/L.

use std::path::{Path, PathBuf};

use fmi2_import::parameter_set::TypedValue;
use fmi2_import::{Causality, FmuArchive, Instance, OK, WARNING};
use piezo_models::{ControllerParams, PiezoController};

use crate::compare::eq6_command;
use crate::data::Record;

/// Why a plant FMU could not be driven.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    #[error("{path}: {problem}")]
    Archive { path: PathBuf, problem: String },
    #[error("{path}: {problem}")]
    Interface { path: PathBuf, problem: String },
    #[error("{path}: {call} returned status {status} at t = {time} s: {log}")]
    Call {
        path: PathBuf,
        call: &'static str,
        status: u32,
        time: f64,
        log: String,
    },
    /// A call of a session's start (set-up, the parameter set, initialization)
    /// refused: the FMU or the parameters given, not the run.
    #[error("{path}: {call} returned status {status} while starting a session: {log}")]
    Start {
        path: PathBuf,
        call: &'static str,
        status: u32,
        log: String,
    },
}

/// An unpacked plant FMU with its binary loaded.
pub struct PlantFmu {
    path: PathBuf,
    /// The unpacked FMU with its binary loaded.
    archive: FmuArchive,
    u: [u32; 3],
    s: [u32; 3],
    /// Parameter values set in initialization mode of every session (a
    /// preset; e.g. from `flexure-stage-parameters xy200s`).
    parameters: Vec<(String, u32, TypedValue)>,
}

pub use fmi2_import::parameter_set::{ParameterValue, read_parameter_set};

impl PlantFmu {
    /// Unpacks `path` (modelDescription.xml and this platform's binary) and
    /// loads it.
    pub fn open(path: &Path) -> Result<PlantFmu, PlantError> {
        let archive_error = |problem: String| PlantError::Archive {
            path: path.to_owned(),
            problem,
        };
        let archive = FmuArchive::open(path).map_err(|e| archive_error(e.problem))?;
        let fmu = &archive.fmu;
        // By causality as well as name: the controller has u1..u3 and
        // s1..s3 too, the other way round, and was taken for a plant until
        // its first fmi2SetReal on an output failed mid-identification.
        let vr = |name: &str, causality: Causality| {
            let interface = |problem: String| PlantError::Interface {
                path: path.to_owned(),
                problem: format!(
                    "{problem}: a plant needs inputs u1..u3 [V] and outputs s1..s3 [um]"
                ),
            };
            let variable = fmu
                .find(name)
                .ok_or_else(|| interface(format!("no variable {name}")))?;
            if variable.causality != causality {
                let role = |c: &Causality| format!("{c:?}").to_lowercase();
                return Err(interface(format!(
                    "{name} has causality \"{}\", a plant's \"{}\"",
                    role(&variable.causality),
                    role(&causality)
                )));
            }
            Ok(variable.vr)
        };
        let u = [
            vr("u1", Causality::Input)?,
            vr("u2", Causality::Input)?,
            vr("u3", Causality::Input)?,
        ];
        let s = [
            vr("s1", Causality::Output)?,
            vr("s2", Causality::Output)?,
            vr("s3", Causality::Output)?,
        ];
        Ok(PlantFmu {
            path: path.to_owned(),
            archive,
            u,
            s,
            parameters: Vec::new(),
        })
    }

    /// Every session will set these parameters (FMI name, value) before
    /// initialization. Refuses a name the plant does not have or a value of
    /// another type than the variable's.
    pub fn with_parameters(
        mut self,
        parameters: &[(String, ParameterValue)],
    ) -> Result<PlantFmu, PlantError> {
        for (name, value) in parameters {
            let problem = |problem: String| PlantError::Interface {
                path: self.path.clone(),
                problem,
            };
            let fmu = &self.archive.fmu;
            let variable = fmu
                .find(name)
                .ok_or_else(|| problem(format!("no parameter {name}{}", fmu.hint_for(name))))?;
            let typed = value.typed(variable.kind).map_err(|wanted| {
                let kind = variable.kind;
                problem(format!(
                    "{name} is a {kind} variable, which takes {wanted}; the parameter set \
                     gives {value}"
                ))
            })?;
            self.parameters.push((name.clone(), variable.vr, typed));
        }
        Ok(self)
    }

    /// The `.fmu` file or folder it was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The value a Real parameter has in every session, e.g. `L`: the one
    /// set by [`with_parameters`](Self::with_parameters), else its start
    /// attribute.
    pub fn start(&self, name: &str) -> Option<f64> {
        self.parameters
            .iter()
            .find_map(|(n, _, value)| match value {
                TypedValue::Real(v) if n == name => Some(*v),
                _ => None,
            })
            .or_else(|| self.archive.fmu.find(name).and_then(|v| v.start))
    }

    /// A fresh instance at rest, initialized at t = 0 with its start values.
    pub fn session(&self) -> Result<PlantSession<'_>, PlantError> {
        let instance = self
            .archive
            .instantiate("identification", false)
            .map_err(|log| PlantError::Interface {
                path: self.path.clone(),
                problem: format!(
                    "fmi2Instantiate returned NULL: {}",
                    log.iter()
                        .map(|r| r.message.as_str())
                        .collect::<Vec<_>>()
                        .join("; ")
                ),
            })?;
        let mut session = PlantSession {
            plant: self,
            instance,
        };
        let starting = |e: PlantError| match e {
            PlantError::Call {
                path,
                call,
                status,
                log,
                ..
            } => PlantError::Start {
                path,
                call,
                status,
                log,
            },
            other => other,
        };
        let status = session.instance.setup(0.0);
        session
            .check("fmi2SetupExperiment", status)
            .map_err(starting)?;
        let status = session.instance.enter_init();
        session
            .check("fmi2EnterInitializationMode", status)
            .map_err(starting)?;
        for (_, vr, value) in &self.parameters {
            let (call, status) = session.instance.set_typed(*vr, *value);
            session.check(call, status).map_err(starting)?;
        }
        let status = session.instance.exit_init();
        session
            .check("fmi2ExitInitializationMode", status)
            .map_err(starting)?;
        Ok(session)
    }

    fn call_error(
        &self,
        call: &'static str,
        status: u32,
        time: f64,
        log: &[fmi2_import::LogRecord],
    ) -> PlantError {
        PlantError::Call {
            path: self.path.clone(),
            call,
            status,
            time,
            log: log
                .iter()
                .map(|r| r.message.as_str())
                .collect::<Vec<_>>()
                .join("; "),
        }
    }
}

/// One running instance.
pub struct PlantSession<'a> {
    plant: &'a PlantFmu,
    instance: Instance<'a>,
}

impl PlantSession<'_> {
    fn check(&self, call: &'static str, status: u32) -> Result<(), PlantError> {
        if status == OK || status == WARNING {
            Ok(())
        } else {
            Err(self
                .plant
                .call_error(call, status, self.instance.time, &self.instance.take_log()))
        }
    }

    /// Holds `commands` over one step of `h` seconds; returns s1, s2, s3
    /// at its end.
    pub fn step(&mut self, commands: [f64; 3], h: f64) -> Result<[f64; 3], PlantError> {
        let status = self.instance.set_real(&self.plant.u, &commands);
        self.check("fmi2SetReal", status)?;
        let status = self.instance.do_step(h);
        self.check("fmi2DoStep", status)?;
        let (status, s) = self.instance.get_real(&self.plant.s);
        self.check("fmi2GetReal", status)?;
        Ok([s[0], s[1], s[2]])
    }
}

impl PlantSession<'_> {
    /// The instance's whole state, serialized (fmi2GetFMUstate, then
    /// fmi2SerializeFMUstate): a probe runs from here and
    /// [`restore`](Self::restore) comes back.
    pub fn snapshot(&self) -> Result<Vec<u8>, PlantError> {
        let (status, mut state) = self.instance.get_state();
        self.check("fmi2GetFMUstate", status)?;
        let (status, bytes) = self.instance.serialize(state);
        let freed = self.instance.free_state(&mut state);
        self.check("fmi2SerializeFMUstate", status)?;
        self.check("fmi2FreeFMUstate", freed)?;
        Ok(bytes)
    }

    /// Back to a [`snapshot`](Self::snapshot) of this plant, time included.
    pub fn restore(&mut self, snapshot: &[u8], time: f64) -> Result<(), PlantError> {
        let (status, mut state) = self.instance.deserialize(snapshot);
        self.check("fmi2DeSerializeFMUstate", status)?;
        let set = self.instance.set_state(state);
        let freed = self.instance.free_state(&mut state);
        self.check("fmi2SetFMUstate", set)?;
        self.check("fmi2FreeFMUstate", freed)?;
        self.instance.time = time;
        Ok(())
    }

    /// The communication point the next step starts from [s].
    pub fn time(&self) -> f64 {
        self.instance.time
    }
}

/// The axis an open-loop identification record drives and reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordAxis {
    /// u1 driven, y = s1 read (PZT1).
    Y,
    /// u2 = u3 driven, x = (s2 + s3)/2 read (the x pair, seed 000 §3.1).
    X,
}

/// Seed 000 §3.1's identification record: eq. (6) on the axis's channel(s),
/// the others at 0 V, from rest, `duration` s at `sample_rate`. Sample n
/// pairs the command held over [t_n, t_n+1] (limited to `command_max`, the
/// amplifier's input range: beyond it the stage does not respond) with the
/// displacement at t_n+1, as [`crate::compare::synthetic_plant_record`] does.
///
/// With `exercise` > 0 s the record starts with one exercise cycle of that
/// length, u = 5(1 − cos 2πt/T) V (0 → 10 → 0 V), before eq. (6): the
/// cycle a lab runs to bring a stack onto its working loop. The first
/// `exercise_samples(exercise, sample_rate)` samples are that cycle.
pub fn eq6_record(
    plant: &PlantFmu,
    axis: RecordAxis,
    duration: f64,
    sample_rate: f64,
    command_max: f64,
    exercise: f64,
) -> Result<Record, PlantError> {
    let mut session = plant.session()?;
    let h = 1.0 / sample_rate;
    let warm_up = exercise_samples(exercise, sample_rate);
    let samples = (duration * sample_rate).round() as usize + warm_up;
    let mut input = Vec::with_capacity(samples);
    let mut output = Vec::with_capacity(samples);
    for n in 0..samples {
        let u = if n < warm_up {
            5.0 * (1.0 - (std::f64::consts::TAU * n as f64 * h / exercise).cos())
        } else {
            eq6_command((n - warm_up) as f64 * h)
        };
        let commands = match axis {
            RecordAxis::Y => [u, 0.0, 0.0],
            RecordAxis::X => [0.0, u, u],
        };
        let s = session.step(commands, h)?;
        input.push(u.min(command_max));
        output.push(match axis {
            RecordAxis::Y => s[0],
            RecordAxis::X => 0.5 * (s[1] + s[2]),
        });
    }
    Ok(Record {
        input,
        output,
        sample_period: h,
    })
}

/// Samples of an exercise cycle of `exercise` s at `sample_rate`.
pub fn exercise_samples(exercise: f64, sample_rate: f64) -> usize {
    (exercise * sample_rate).round() as usize
}

/// Seed 001 §5.2's identification run: a sine of `frequency` [Hz] between 0
/// and `peak` [V] (u = peak·(1 − cos 2πft)/2, from rest; the actuators cannot
/// take a negative voltage) on one axis's channel(s), the other channels at
/// 0 V, for `periods` periods at `sample_rate`. Returns two records with the
/// same input: the driven axis's displacement (for H_XX, H_YY) and the other
/// axis's (the coupled displacement, for H_XY, H_YX; eq. 8). Sample n pairs
/// the command held over [t_n, t_n+1] with the displacements at t_n+1.
pub fn sine_records(
    plant: &PlantFmu,
    axis: RecordAxis,
    frequency: f64,
    peak: f64,
    periods: f64,
    sample_rate: f64,
) -> Result<(Record, Record), PlantError> {
    let samples = (periods / frequency * sample_rate).round() as usize;
    let input: Vec<f64> = (0..samples)
        .map(|n| {
            let t = n as f64 / sample_rate;
            0.5 * peak * (1.0 - (2.0 * std::f64::consts::PI * frequency * t).cos())
        })
        .collect();
    command_records(plant, axis, &input, sample_rate)
}

/// `input` [V] on one axis's channel(s), the other channels at 0 V, from the
/// plant's rest at `sample_rate`: the records of [`sine_records`] for any
/// command.
pub fn command_records(
    plant: &PlantFmu,
    axis: RecordAxis,
    input: &[f64],
    sample_rate: f64,
) -> Result<(Record, Record), PlantError> {
    let mut session = plant.session()?;
    let h = 1.0 / sample_rate;
    let mut driven = Vec::with_capacity(input.len());
    let mut coupled = Vec::with_capacity(input.len());
    for &u in input {
        let commands = match axis {
            RecordAxis::Y => [u, 0.0, 0.0],
            RecordAxis::X => [0.0, u, u],
        };
        let s = session.step(commands, h)?;
        let (x, y) = (0.5 * (s[1] + s[2]), s[0]);
        let (own, other) = match axis {
            RecordAxis::Y => (y, x),
            RecordAxis::X => (x, y),
        };
        driven.push(own);
        coupled.push(other);
    }
    let record = |output| Record {
        input: input.to_vec(),
        output,
        sample_period: h,
    };
    Ok((record(driven), record(coupled)))
}

/// A closed-loop run: the demands and the sensor readings at every
/// communication point.
#[derive(Clone, Debug, Default)]
pub struct ClosedLoopRun {
    pub t: Vec<f64>,
    /// x_ref [µm], y_ref [µm], theta_ref [rad] at t.
    pub references: Vec<[f64; 3]>,
    /// s1, s2, s3 [µm] at t.
    pub sensors: Vec<[f64; 3]>,
}

/// Runs `controller` in closed loop with a fresh plant instance for
/// `duration` s at step `h`, with the master algorithm of the project's
/// co-simulation harness (demo/cosim.py): Jacobi ordering, so the command the
/// plant holds over [t_k, t_k+1] was computed from the sensors at t_k−1 (one
/// sample of compute delay), and the references given `preview` samples
/// ahead.
pub fn closed_loop(
    plant: &PlantFmu,
    controller: &ControllerParams,
    reference: impl Fn(f64) -> [f64; 3],
    duration: f64,
    h: f64,
    preview: usize,
) -> Result<ClosedLoopRun, PlantError> {
    let mut session = plant.session()?;
    let mut law = PiezoController::new(controller.clone()).map_err(|e| PlantError::Interface {
        path: plant.path.clone(),
        problem: format!("controller parameter {}: {}", e.parameter, e.allowed),
    })?;
    let steps = (duration / h).round() as usize;
    let mut run = ClosedLoopRun::default();
    let mut sensors = [0.0; 3];
    let mut commands = [0.0; 3];
    for k in 0..=steps {
        let t = k as f64 * h;
        run.t.push(t);
        run.references.push(reference(t));
        run.sensors.push(sensors);
        if k == steps {
            break;
        }
        let [x, y, theta] = reference(t + preview as f64 * h);
        let next = law.step(x, y, theta, sensors, h).u;
        sensors = session.step(commands, h)?;
        commands = next;
    }
    Ok(run)
}
