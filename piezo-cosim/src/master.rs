//! The master: a fixed-step Jacobi loop over a connection table.
//!
//! At each communication point t_k = k·h every FMU's outputs are read; every
//! input then gets its value at t_k (a connection: the source's output at
//! t_k; a signal: its trajectory at t_k + preview·h), and every FMU steps from
//! t_k to t_k+1. This is demo/cosim.py's algorithm, call for call: the
//! controller samples its inputs at the start of its step and its outputs
//! hold from the end of it, so the command a plant applies over
//! [t_k, t_k+1] was computed from its sensors at t_k−1, one sample of compute
//! delay, as on a DSP that writes its outputs at the next sample; with the
//! references two samples ahead the command aims at r(t_k+1).
//!
//! Nothing in the loop knows what the FMUs are: the scenario's connections,
//! signals and parameter values are resolved to value references and buffer
//! indices before the first step, and the loop allocates nothing.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::time::Instant;

use fmi2_import::parameter_set::TypedValue;
use fmi2_import::{Causality, FmuArchive, Instance, LogRecord, OK, VariableInfo, WARNING};

use crate::metrics::{self, Metrics};
use crate::scenario::{CONTROLLER, Connection, Scenario, ScenarioError, split_port};

/// What to keep of a run besides its metrics.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Record the time series: every Real output, every signal, and the
    /// scenario's `record` list.
    pub series: bool,
    /// Stop after initialization: the scenario is checked against the FMUs
    /// (every variable, connection, signal and parameter value, and the
    /// FMUs' own checks at fmi2ExitInitializationMode) without a step.
    pub check_only: bool,
}

/// The recorded time series: `t` and one column per name.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub t: Vec<f64>,
    /// `instance.variable`
    pub names: Vec<String>,
    /// Each column's unit, as its FMU declares the variable's (None where it
    /// declares none).
    pub units: Vec<Option<String>>,
    pub columns: Vec<Vec<f64>>,
}

impl Series {
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }
}

/// The result of a run.
#[derive(Clone, Debug)]
pub struct RunOutput {
    pub steps: usize,
    /// Wall time of the whole run: loading, instantiation, the loop, metrics [s].
    pub wall_s: f64,
    /// Wall time of the step loop alone [s].
    pub loop_s: f64,
    pub metrics: Option<Metrics>,
    /// Messages the FMUs logged with status Warning (the first few).
    pub warnings: Vec<String>,
    pub series: Option<Series>,
}

/// Why a run did not complete.
#[derive(Debug)]
pub enum RunError {
    /// The scenario does not fit the FMUs (an unknown variable, a type).
    Scenario(String),
    /// An FMU refused a call or failed a step.
    Fmu(String),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Scenario(m) | RunError::Fmu(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for RunError {}

impl From<ScenarioError> for RunError {
    fn from(e: ScenarioError) -> Self {
        RunError::Scenario(e.0)
    }
}

/// How many warning messages a run keeps.
const KEPT_WARNINGS: usize = 20;

/// Where an input's value comes from at each step.
#[derive(Clone, Copy, Debug)]
enum Source {
    /// Index into the flat buffer of outputs read at t_k.
    Output(usize),
    /// Index of a signal (its value at t_k + preview·h).
    Signal(usize),
}

/// One FMU of the run: what it reads and writes at each step.
struct Slot<'a> {
    name: String,
    instance: Instance<'a>,
    /// Value references read at every step, and where they land in the flat
    /// output buffer (a contiguous range starting at `first_output`).
    output_vrs: Vec<u32>,
    first_output: usize,
    input_vrs: Vec<u32>,
    input_sources: Vec<Source>,
    input_values: Vec<f64>,
}

/// A loaded FMU of the scenario.
struct Loaded<'a> {
    name: String,
    archive: &'a FmuArchive,
}

/// The FMUs a process has opened, by the path a scenario names them with:
/// runs of one process (`piezo-cosim batch`, a sweep task's runs) open,
/// unpack, parse and load each FMU once, and instantiate it per run. A run's
/// instances are its own; what the binary keeps between instances is the
/// FMU's business (this project's FMUs keep their GUID, nothing of a run),
/// and an FMU that keeps more, or declares
/// `canBeInstantiatedOnlyOncePerProcess`, needs a process per run.
#[derive(Default)]
pub struct OpenFmus {
    by_path: BTreeMap<PathBuf, FmuArchive>,
    /// FMUs this process has instantiated.
    instantiated: BTreeSet<PathBuf>,
}

impl OpenFmus {
    /// Opens every FMU of `scenario` not open yet, and checks that the run
    /// may instantiate each: an FMU that declares
    /// `canBeInstantiatedOnlyOncePerProcess` may have one instance in a
    /// process, once (`instantiated` counts those a run made).
    fn open_all(&mut self, scenario: &Scenario) -> Result<(), RunError> {
        for spec in scenario.fmu.values() {
            if !self.by_path.contains_key(&spec.path) {
                let archive =
                    FmuArchive::open(&spec.path).map_err(|e| RunError::Scenario(e.to_string()))?;
                self.by_path.insert(spec.path.clone(), archive);
            }
        }
        let mut claimed = BTreeSet::new();
        for spec in scenario.fmu.values() {
            let once = self.by_path[&spec.path]
                .fmu
                .description
                .co_simulation
                .as_ref()
                .and_then(|cs| cs.can_be_instantiated_only_once_per_process)
                .unwrap_or(false);
            if once && (self.instantiated.contains(&spec.path) || !claimed.insert(&spec.path)) {
                return Err(RunError::Scenario(format!(
                    "{}: the FMU can be instantiated only once per process \
                     (canBeInstantiatedOnlyOncePerProcess), and this process has an instance \
                     of it already: give each run its own process (`piezo-cosim run`; in a \
                     sweep, runs_per_task = 1)",
                    spec.path.display()
                )));
            }
        }
        Ok(())
    }

    /// How many FMUs are open.
    pub fn len(&self) -> usize {
        self.by_path.len()
    }

    pub fn is_empty(&self) -> bool {
        self.by_path.is_empty()
    }
}

impl Loaded<'_> {
    fn variable(&self, variable: &str, port: &str) -> Result<&VariableInfo, RunError> {
        self.archive.fmu.find(variable).ok_or_else(|| {
            let hint = self.archive.fmu.hint_for(variable);
            RunError::Scenario(format!(
                "{port}: {} has no variable {variable:?}{hint}",
                self.archive.path.display()
            ))
        })
    }
}

/// The log of an instance as one line.
fn log_text(log: &[LogRecord]) -> String {
    if log.is_empty() {
        return "(nothing logged)".to_owned();
    }
    log.iter()
        .map(|r| format!("[{}] {}", r.category, r.message))
        .collect::<Vec<_>>()
        .join("; ")
}

/// Runs `scenario` once, opening its FMUs for this run alone.
pub fn run(scenario: &Scenario, options: RunOptions) -> Result<RunOutput, RunError> {
    run_with(scenario, options, &mut OpenFmus::default())
}

/// Runs `scenario` once with the FMUs `open` holds, opening those it does
/// not (kept for the next run). The result equals [`run`]'s: each run has
/// its own instances.
pub fn run_with(
    scenario: &Scenario,
    options: RunOptions,
    open: &mut OpenFmus,
) -> Result<RunOutput, RunError> {
    let started = Instant::now();
    open.open_all(scenario)?;
    let loaded: Vec<Loaded> = scenario
        .fmu
        .iter()
        .map(|(name, spec)| Loaded {
            name: name.clone(),
            archive: &open.by_path[&spec.path],
        })
        .collect();
    let index_of: BTreeMap<&str, usize> = loaded
        .iter()
        .enumerate()
        .map(|(i, l)| (l.name.as_str(), i))
        .collect();
    let resolve = |port: &str| -> Result<(usize, &VariableInfo), RunError> {
        let (instance, variable) = split_port(port)
            .ok_or_else(|| RunError::Scenario(format!("{port:?} is not `instance.variable`")))?;
        let slot = *index_of
            .get(instance)
            .ok_or_else(|| RunError::Scenario(format!("{port}: no FMU instance {instance:?}")))?;
        let info = loaded[slot].variable(variable, port)?;
        if info.kind != "Real" {
            return Err(RunError::Scenario(format!(
                "{port} is a {} variable; the master exchanges Real values",
                info.kind
            )));
        }
        Ok((slot, info))
    };

    // The outputs read at every step, per FMU, in a flat buffer.
    let mut read: Vec<Vec<(String, u32)>> = vec![Vec::new(); loaded.len()];
    let want_output = |port: &str, read: &mut Vec<Vec<(String, u32)>>| -> Result<(), RunError> {
        let (slot, info) = resolve(port)?;
        // By name: two names of one value reference (an alias) are two
        // entries, read twice, so that each has its index.
        if !read[slot].iter().any(|(name, _)| name == port) {
            read[slot].push((port.to_owned(), info.vr));
        }
        Ok(())
    };
    let connections: Vec<Connection> = scenario.connections();
    // Which FMU a port is of, and what its variable is there: the stage's
    // default wiring is written nowhere, so a plant and controller given the
    // other way round are named by their files.
    let of_fmu = |slot: usize, info: &VariableInfo| {
        let path = &scenario.fmu[&loaded[slot].name].path;
        let causality = format!("{:?}", info.causality).to_lowercase();
        format!("in {} its causality is {causality}", path.display())
    };
    for connection in &connections {
        let (slot, info) = resolve(&connection.from)?;
        if info.causality != Causality::Output {
            return Err(RunError::Scenario(format!(
                "connection source {} is not an output ({})",
                connection.from,
                of_fmu(slot, info)
            )));
        }
        want_output(&connection.from, &mut read)?;
    }
    let metric_ports = match &scenario.metrics {
        Some(spec) => metrics::sensor_ports()
            .into_iter()
            .chain(metrics::command_ports())
            .chain(spec.pose.then(metrics::pose_ports).into_iter().flatten())
            .collect(),
        None => Vec::new(),
    };
    for port in &metric_ports {
        want_output(port, &mut read)?;
    }
    // What `record` names is checked in every run, with or without a
    // series: `check` and `run` passed a misspelt name that `run --series`
    // then refused.
    for port in &scenario.record {
        resolve(port)?;
    }
    if options.series {
        for l in &loaded {
            for v in l.archive.fmu.with_causality(Causality::Output) {
                if v.kind == "Real" {
                    want_output(&format!("{}.{}", l.name, v.name), &mut read)?;
                }
            }
        }
        for port in &scenario.record {
            want_output(port, &mut read)?;
        }
    }
    let mut output_index: BTreeMap<String, usize> = BTreeMap::new();
    let mut first_outputs = Vec::with_capacity(loaded.len());
    let mut total_outputs = 0;
    for ports in &read {
        first_outputs.push(total_outputs);
        for (port, _) in ports {
            output_index.insert(port.clone(), total_outputs);
            total_outputs += 1;
        }
    }

    // Signals, sampled once before the loop on the grid t_k = k·h, k = 0 ..
    // steps + preview: t_k's sample is recorded (and is the metrics'
    // demand), t_(k + preview)'s is what the inputs get at t_k.
    let steps = scenario.steps();
    let h = scenario.step;
    let preview = scenario.preview as usize;
    let mut grid: Vec<f64> = (0..=steps + preview).map(|k| k as f64 * h).collect();
    let mut signal_names = Vec::new();
    let mut signal_samples = Vec::new();
    // A table that ends before the run holds its last value to the end: said,
    // since a table cut short (or in ms read as s) otherwise runs silently.
    let mut table_notes = Vec::new();
    let run_end = steps as f64 * h;
    for (port, trajectory) in &scenario.signal {
        let (_, info) = resolve(port)?;
        let fail = |e: String| RunError::Scenario(format!("signal {port}: {e}"));
        let (samples, table_span) = trajectory
            .sample_to_end(&grid, info.unit.as_deref())
            .map_err(fail)?;
        if let Some((start, _)) = table_span
            && start > trajectory.start + 1e-9 * run_end.max(h)
        {
            table_notes.push(format!(
                "signal {port}: its table starts at {start} s, after its signal starts at {} s; \
                 its first value is held until then",
                trajectory.start
            ));
        }
        if let Some((_, end)) = table_span
            && end < run_end - 1e-9 * run_end.max(h)
        {
            table_notes.push(format!(
                "signal {port}: its table ends at {end} s, before the run's end at {run_end} s; \
                 its last value is held from there"
            ));
        }
        signal_samples.push(samples);
        signal_names.push(port.clone());
    }
    // The communication points t_0 .. t_steps: the grid without its preview.
    grid.truncate(steps + 1);
    let times = grid;
    let signal_now = |s: usize| &signal_samples[s][..=steps];

    // Inputs per FMU.
    let mut inputs: Vec<Vec<(u32, Source)>> = vec![Vec::new(); loaded.len()];
    let mut driven: BTreeMap<String, String> = BTreeMap::new();
    let mut add_input = |port: &str, source: Source, by: &str| -> Result<(), RunError> {
        let (slot, info) = resolve(port)?;
        if info.causality != Causality::Input {
            return Err(RunError::Scenario(format!(
                "{port} is not an input ({})",
                of_fmu(slot, info)
            )));
        }
        if let Some(other) = driven.insert(port.to_owned(), by.to_owned()) {
            return Err(RunError::Scenario(format!(
                "{port} is driven twice: by {other} and by {by}"
            )));
        }
        inputs[slot].push((info.vr, source));
        Ok(())
    };
    for connection in &connections {
        let source = Source::Output(output_index[&connection.from]);
        add_input(&connection.to, source, &connection.from)?;
    }
    for (i, port) in signal_names.iter().enumerate() {
        add_input(port, Source::Signal(i), "a signal")?;
    }

    // Parameter values by FMI name, typed by the variable.
    let mut parameters: Vec<Vec<(u32, TypedValue, String)>> = Vec::with_capacity(loaded.len());
    let mut parameter_value: BTreeMap<String, f64> = BTreeMap::new();
    for l in &loaded {
        let spec = &scenario.fmu[&l.name];
        let mut typed = Vec::new();
        for (name, value) in spec.parameter_values()? {
            let port = format!("{}.{name}", l.name);
            // A value from a parameter set is named with its file.
            let given_in = || match spec.parameter_origin(&name) {
                Some(set) => format!(" (given in {})", set.display()),
                None => String::new(),
            };
            let info = l
                .variable(&name, &port)
                .map_err(|e| RunError::Scenario(format!("{e}{}", given_in())))?;
            let value = value.typed(info.kind).map_err(|wanted| {
                let kind = info.kind;
                let article = if kind.starts_with(['A', 'E', 'I', 'O', 'U']) {
                    "an"
                } else {
                    "a"
                };
                RunError::Scenario(format!(
                    "{port} is {article} {kind} variable, which takes {wanted}; {value} was \
                     given{}",
                    given_in()
                ))
            })?;
            if let TypedValue::Real(v) = value {
                parameter_value.insert(port, v);
            }
            typed.push((info.vr, value, name));
        }
        parameters.push(typed);
    }
    // A parameter's value in this run: the one set, else its start value.
    let value_of = |port: &str| -> Option<f64> {
        parameter_value.get(port).copied().or_else(|| {
            let (instance, variable) = split_port(port)?;
            let slot = *index_of.get(instance)?;
            loaded[slot].archive.fmu.find(variable)?.start
        })
    };

    // Instantiate and initialize every FMU.
    let mut slots: Vec<Slot> = Vec::with_capacity(loaded.len());
    for (i, l) in loaded.iter().enumerate() {
        let instance = l.archive.instantiate(&l.name, false).map_err(|log| {
            RunError::Fmu(format!(
                "{}: fmi2Instantiate returned NULL: {}",
                l.name,
                log_text(&log)
            ))
        })?;
        open.instantiated.insert(scenario.fmu[&l.name].path.clone());
        let (vrs, sources): (Vec<u32>, Vec<Source>) = inputs[i].iter().copied().unzip();
        slots.push(Slot {
            name: l.name.clone(),
            instance,
            output_vrs: read[i].iter().map(|(_, vr)| *vr).collect(),
            first_output: first_outputs[i],
            input_values: vec![0.0; vrs.len()],
            input_vrs: vrs,
            input_sources: sources,
        });
    }
    let mut warnings = table_notes;
    // The run takes whole steps: a duration between two is rounded to the
    // nearer, which the result's simulated_s shows and this says.
    let simulated = scenario.steps() as f64 * scenario.step;
    if (simulated - scenario.duration).abs() > 1e-9 * scenario.duration.max(scenario.step) {
        // Twelve significant digits: 3 × 0.003 prints as 0.009.
        let shown: f64 = format!("{simulated:.12e}").parse().unwrap_or(simulated);
        warnings.push(format!(
            "duration {} s is not a whole number of steps of {} s: the run takes {} steps, {shown} s",
            scenario.duration,
            scenario.step,
            scenario.steps()
        ));
    }
    // A value the FMU refuses that came from a parameter set is named with
    // the set's file, as an unknown name from one is.
    let with_origin = |instance: &str, name: &str, message: String| match scenario.fmu[instance]
        .parameter_origin(name)
    {
        Some(set) => format!("{message} (given in {})", set.display()),
        None => message,
    };
    for (slot, typed) in slots.iter_mut().zip(&parameters) {
        let status = slot.instance.setup(0.0);
        check(slot, "fmi2SetupExperiment", status, 0.0, &mut warnings)?;
        let status = slot.instance.enter_init();
        check(
            slot,
            "fmi2EnterInitializationMode",
            status,
            0.0,
            &mut warnings,
        )?;
        for (vr, value, name) in typed {
            let (call, status) = slot.instance.set_typed(*vr, *value);
            // A value the FMU refuses (out of its range, an output) is the
            // scenario's to fix, as an unknown name is.
            let instance = slot.name.clone();
            check(slot, call, status, 0.0, &mut warnings).map_err(|e| match e {
                RunError::Fmu(message) => RunError::Scenario(with_origin(&instance, name, message)),
                e => e,
            })?;
        }
        let status = slot.instance.exit_init();
        // The FMUs check their parameters together when initialization ends
        // (a range, command_max above command_min): a refusal that names a
        // parameter is the scenario's to fix.
        check(
            slot,
            "fmi2ExitInitializationMode",
            status,
            0.0,
            &mut warnings,
        )
        .map_err(|e| match e {
            RunError::Fmu(message) if message.contains("parameter ") => {
                let named = message
                    .split_once("parameter ")
                    .and_then(|(_, rest)| rest.split_whitespace().next())
                    .unwrap_or("")
                    .to_owned();
                RunError::Scenario(with_origin(&slot.name, &named, message))
            }
            e => e,
        })?;
    }

    if options.check_only {
        for slot in &mut slots {
            let status = slot.instance.terminate();
            check(slot, "fmi2Terminate", status, 0.0, &mut warnings)?;
        }
        return Ok(RunOutput {
            steps: 0,
            wall_s: started.elapsed().as_secs_f64(),
            loop_s: 0.0,
            metrics: None,
            warnings,
            series: None,
        });
    }

    // What is recorded at every step: outputs by buffer index.
    let recorded: Vec<(String, usize)> = output_index
        .iter()
        .filter(|(port, _)| options.series || metric_ports.contains(port))
        .map(|(port, &i)| (port.clone(), i))
        .collect();
    // Without a series only the metrics' window is kept: the samples before
    // it are neither written nor paged in.
    let record_from = match (&scenario.metrics, options.series) {
        (Some(spec), false) => metrics::first_sample(spec, &times),
        _ => 0,
    };
    let mut columns: Vec<Vec<f64>> = recorded
        .iter()
        .map(|_| Vec::with_capacity(steps + 1 - record_from))
        .collect();
    let mut outputs = vec![0.0; total_outputs];

    let loop_started = Instant::now();
    for k in 0..=steps {
        let t = times[k];
        for slot in &mut slots {
            let range = slot.first_output..slot.first_output + slot.output_vrs.len();
            let status = slot
                .instance
                .get_real_into(&slot.output_vrs, &mut outputs[range]);
            check(slot, "fmi2GetReal", status, t, &mut warnings)?;
        }
        if k >= record_from {
            for (column, (_, i)) in columns.iter_mut().zip(&recorded) {
                column.push(outputs[*i]);
            }
        }
        if k == steps {
            break;
        }
        for slot in &mut slots {
            for (value, source) in slot.input_values.iter_mut().zip(&slot.input_sources) {
                *value = match *source {
                    Source::Output(i) => outputs[i],
                    Source::Signal(s) => signal_samples[s][k + preview],
                };
            }
            if !slot.input_vrs.is_empty() {
                let status = slot.instance.set_real(&slot.input_vrs, &slot.input_values);
                check(slot, "fmi2SetReal", status, t, &mut warnings)?;
            }
        }
        for slot in &mut slots {
            let status = slot.instance.do_step_at(t, h);
            check(slot, "fmi2DoStep", status, t, &mut warnings)?;
        }
    }
    let loop_s = loop_started.elapsed().as_secs_f64();
    for slot in &mut slots {
        let status = slot.instance.terminate();
        check(slot, "fmi2Terminate", status, times[steps], &mut warnings)?;
    }
    drop(slots);

    let metrics = match &scenario.metrics {
        Some(spec) => {
            let spacing = match spec.spacing {
                Some(s) => s,
                None => {
                    value_of(&format!("{CONTROLLER}.L")).ok_or_else(|| {
                        RunError::Scenario(
                            "metrics need the x sensors' spacing: give metrics.spacing [um] or a controller with parameter L [mm]"
                                .to_owned(),
                        )
                    })? * 1e3
                }
            };
            let mut available: BTreeMap<&str, &[f64]> = BTreeMap::new();
            for ((port, _), column) in recorded.iter().zip(&columns) {
                available.insert(port.as_str(), column.as_slice());
            }
            for (s, port) in signal_names.iter().enumerate() {
                available.insert(port.as_str(), &signal_now(s)[record_from..]);
            }
            let constant = |port: &str| value_of(port).unwrap_or(0.0);
            Some(metrics::compute(
                spec,
                &times[record_from..],
                spacing,
                &available,
                &constant,
            ))
        }
        None => None,
    };
    let series = if options.series {
        let mut names: Vec<String> = signal_names.clone();
        let mut data: Vec<Vec<f64>> = (0..signal_names.len())
            .map(|s| signal_now(s).to_vec())
            .collect();
        for ((port, _), column) in recorded.iter().zip(columns) {
            names.push(port.clone());
            data.push(column);
        }
        let units = names
            .iter()
            .map(|port| resolve(port).ok().and_then(|(_, info)| info.unit.clone()))
            .collect();
        Some(Series {
            t: times,
            names,
            units,
            columns: data,
        })
    } else {
        None
    };
    Ok(RunOutput {
        steps,
        wall_s: started.elapsed().as_secs_f64(),
        loop_s,
        metrics,
        warnings,
        series,
    })
}

/// Accepts OK and Warning (keeping the warning's log); anything else ends
/// the run with the FMU's log.
#[inline]
fn check(
    slot: &mut Slot,
    call: &'static str,
    status: u32,
    t: f64,
    warnings: &mut Vec<String>,
) -> Result<(), RunError> {
    if status == OK {
        return Ok(());
    }
    failed_or_warned(slot, call, status, t, warnings)
}

#[cold]
#[inline(never)]
fn failed_or_warned(
    slot: &mut Slot,
    call: &'static str,
    status: u32,
    t: f64,
    warnings: &mut Vec<String>,
) -> Result<(), RunError> {
    let log = slot.instance.take_log();
    if status == WARNING {
        for record in log {
            if warnings.len() < KEPT_WARNINGS {
                warnings.push(format!("{} at t = {t} s: {}", slot.name, record.message));
            }
        }
        return Ok(());
    }
    Err(RunError::Fmu(format!(
        "{}: {call} returned status {status} at t = {t} s: {}",
        slot.name,
        log_text(&log)
    )))
}
