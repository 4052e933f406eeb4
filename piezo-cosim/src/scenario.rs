//! A scenario: everything one closed-loop run is, as data (TOML or JSON).
//!
//! ```toml
//! step = 1e-4            # communication step [s] (default: seed 000's 10 kHz)
//! duration = 4.0         # simulated time [s]
//! preview = 2            # samples of reference preview (default 2, as demo/cosim.py)
//!
//! [fmu.plant]
//! path = "../dist/FlexureStage.fmu"     # a .fmu or its unpacked folder
//! parameter_sets = ["../dist/presets/FlexureStage.xy200s.json"]
//! parameters = { "noise.enabled" = true, "noise.seed" = 2024 }
//!
//! [fmu.controller]
//! path = "../dist/PiezoController.fmu"
//! parameters = { decoupling = true, feedback_x = false }
//!
//! [signal."controller.y_ref"]          # a trajectory driving an input
//! offset = 5.0
//! sines = [{ amplitude = 5.0, frequency = 1.0, phase = -1.5707963267948966 }]
//!
//! [metrics]
//! driven = "y"           # x | y | theta | xy | ytheta
//! from = 2.0             # start of the measured window [s]: 2 samples or more of the run's whole steps
//! pose = false           # also the couplings on the plant's pose outputs x, y, theta_z
//! ```
//!
//! Without `[[connection]]` entries the FMUs are wired as the stage's closed
//! loop ([`stage_wiring`]). Relative paths are relative to the scenario file.
//! Unknown keys are refused, with the file, line and column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::trajectory::Trajectory;

/// The seed 000 controller's sample period (§2: the DS1103 at 10 kHz).
pub const DEFAULT_STEP: f64 = 1e-4;
/// Samples of preview of the references (demo/cosim.py: with 2, the command
/// applied over [t_k, t_k+1] aims at r(t_k+1), which makes up for the
/// master's one sample of compute delay).
pub const DEFAULT_PREVIEW: u32 = 2;

/// Instance names of the stage's closed loop (demo/cosim.py's PLANT_INSTANCE,
/// CONTROLLER_INSTANCE).
pub const PLANT: &str = "plant";
pub const CONTROLLER: &str = "controller";

/// The stage's closed loop as (source, destination) pairs, the table of
/// demo/cosim.py (COMMANDS, SENSORS; a test keeps the two equal): the
/// controller's commands drive the plant's amplifier channels, the plant's
/// sensors feed the controller.
pub const STAGE_COMMANDS: [(&str, &str); 3] = [("u1", "u1"), ("u2", "u2"), ("u3", "u3")];
pub const STAGE_SENSORS: [(&str, &str); 3] = [("s1", "s1"), ("s2", "s2"), ("s3", "s3")];

/// One closed-loop run.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Communication step [s].
    #[serde(default = "default_step")]
    pub step: f64,
    /// Simulated time [s]; the run has round(duration / step) steps.
    pub duration: f64,
    /// Every signal is given this many steps ahead: r(t_k + preview·step) at t_k.
    #[serde(default = "default_preview")]
    pub preview: u32,
    /// The FMUs, by instance name.
    pub fmu: BTreeMap<String, FmuSpec>,
    /// Output-to-input connections; absent: [`stage_wiring`].
    #[serde(default)]
    pub connection: Option<Vec<Connection>>,
    /// Trajectories driving inputs, by `instance.variable`.
    #[serde(default)]
    pub signal: BTreeMap<String, Trajectory>,
    /// The experiment's figures, computed after the run.
    #[serde(default)]
    pub metrics: Option<MetricsSpec>,
    /// Variables (`instance.variable`) recorded in the time series besides
    /// every Real output and every signal.
    #[serde(default)]
    pub record: Vec<String>,
}

fn default_step() -> f64 {
    DEFAULT_STEP
}

fn default_preview() -> u32 {
    DEFAULT_PREVIEW
}

/// An FMU and the parameter values it gets in initialization mode.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FmuSpec {
    /// A `.fmu` file or the folder it is unpacked in.
    pub path: PathBuf,
    /// Parameter sets `{ "<FMI name>": value }` (JSON), applied in order.
    #[serde(default)]
    pub parameter_sets: Vec<PathBuf>,
    /// Values by FMI name, applied after the sets (they win).
    #[serde(default)]
    pub parameters: BTreeMap<String, ParameterValue>,
}

pub use fmi2_import::parameter_set::ParameterValue;
use fmi2_import::parameter_set::json_problem;

/// `from` output drives `to` input, both `instance.variable`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Connection {
    pub from: String,
    pub to: String,
}

/// Which experiment of the papers a run is, for its metrics. Read by hand
/// ([`Driven::NAMES`]): serde_json's derived reading answers a value of
/// another kind (`driven = true`) with a bare "expected value".
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Driven {
    /// A single-axis run on y: tracking in y, coupling in x, x2, x3 (Table 3).
    Y,
    /// A single-axis run on x: tracking in x, coupling in y.
    X,
    /// A single-axis run on theta_z: tracking in theta, coupling in y.
    Theta,
    /// A contour (the circle of eq. 14-15): contour error.
    Xy,
    /// y and theta_z together (eq. 16).
    Ytheta,
}

impl Driven {
    /// Every value, and its name in a scenario (as Serialize writes it; a
    /// test keeps the two equal).
    pub const ALL: [Driven; 5] = [
        Driven::Y,
        Driven::X,
        Driven::Theta,
        Driven::Xy,
        Driven::Ytheta,
    ];
    pub const NAMES: [&'static str; 5] = ["y", "x", "theta", "xy", "ytheta"];
}

impl<'de> Deserialize<'de> for Driven {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = Driven;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "one of `{}`", Driven::NAMES.join("`, `"))
            }
            fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<Driven, E> {
                let known = Driven::NAMES.iter().position(|n| *n == name);
                known
                    .map(|i| Driven::ALL[i])
                    .ok_or_else(|| E::unknown_variant(name, &Driven::NAMES))
            }
        }
        deserializer.deserialize_str(Name)
    }
}

/// How the metrics are taken.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MetricsSpec {
    pub driven: Driven,
    /// Start of the measured window [s], absolute time (whole cycles after
    /// the settling ones).
    pub from: f64,
    /// Spacing L of the two x sensors [µm]; default: the controller's `L`
    /// [mm] (its value in this run) × 1000.
    #[serde(default)]
    pub spacing: Option<f64>,
    /// The demanded contour of an `xy` run: a circle.
    #[serde(default)]
    pub contour: Option<Circle>,
    /// Also measure a single-axis run's couplings on the plant's pose
    /// outputs `x`, `y`, `theta_z` (FlexureStage's platform pose, free of
    /// sensor noise): `pose_coupling_*_span`. A coupling of a few tenths of
    /// a µm spans the sensors' noise too (about 0.04 µm over thousands of
    /// samples at 0.005 µm RMS); on the pose it does not.
    #[serde(default)]
    pub pose: bool,
}

/// A circle in the xy plane [µm].
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Circle {
    pub centre: [f64; 2],
    pub radius: f64,
}

/// Why a scenario cannot be run.
#[derive(Debug)]
pub struct ScenarioError(pub String);

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ScenarioError {}

/// A variable of an instance, from `instance.variable` (the variable name
/// may contain dots and brackets: `plant.pzt[1].A`).
pub fn split_port(port: &str) -> Option<(&str, &str)> {
    port.split_once('.')
        .filter(|(instance, variable)| !instance.is_empty() && !variable.is_empty())
}

/// The stage's closed loop: every command and sensor of [`STAGE_COMMANDS`]
/// and [`STAGE_SENSORS`] between [`CONTROLLER`] and [`PLANT`].
pub fn stage_wiring() -> Vec<Connection> {
    let commands = STAGE_COMMANDS.iter().map(|(from, to)| Connection {
        from: format!("{CONTROLLER}.{from}"),
        to: format!("{PLANT}.{to}"),
    });
    let sensors = STAGE_SENSORS.iter().map(|(from, to)| Connection {
        from: format!("{PLANT}.{from}"),
        to: format!("{CONTROLLER}.{to}"),
    });
    commands.chain(sensors).collect()
}

impl Scenario {
    /// Reads a `.toml` or `.json` scenario file; relative paths in it become
    /// relative to its folder.
    pub fn from_file(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ScenarioError(format!("{}: {e}", path.display())))?;
        let json = path.extension().is_some_and(|e| e == "json");
        let mut scenario = Scenario::parse(&text, json, &path.display().to_string())?;
        scenario.resolve_paths(path.parent().unwrap_or(Path::new("")));
        Ok(scenario)
    }

    /// Parses scenario text; `origin` names it in errors (a file name, `-`).
    pub fn parse(text: &str, json: bool, origin: &str) -> Result<Scenario, ScenarioError> {
        // A UTF-8 byte-order mark (Windows editors write one) is no JSON; lines
        // and columns are counted after it, as an editor shows them.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let scenario: Scenario = if json {
            from_json(text).map_err(|(line, column, problem)| {
                ScenarioError(format!("{origin}:{line}:{column}: {problem}"))
            })?
        } else {
            toml::from_str(text).map_err(|e| {
                let (line, column) = e
                    .span()
                    .map(|span| line_and_column(text, span.start))
                    .unwrap_or((0, 0));
                ScenarioError(format!(
                    "{origin}:{line}:{column}: {}",
                    e.message().trim_end()
                ))
            })?
        };
        scenario.validate().map_err(|e| {
            let line = e.line(text, json);
            ScenarioError(match line {
                Some(line) => format!("{origin}:{line}: {}", e.message),
                None => format!("{origin}: {}", e.message),
            })
        })?;
        Ok(scenario)
    }

    /// Parses line `line` of a JSON Lines file of scenarios (`piezo-cosim
    /// batch`): one scenario as JSON on one line; errors name `origin`, the
    /// line and the column.
    pub fn parse_json_line(
        text: &str,
        origin: &str,
        line: usize,
    ) -> Result<Scenario, ScenarioError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let scenario: Scenario = from_json(text).map_err(|(_, column, problem)| {
            // The text is one line of the file: the file's line is the place.
            ScenarioError(format!("{origin}:{line}:{column}: {problem}"))
        })?;
        scenario
            .validate()
            .map_err(|e| ScenarioError(format!("{origin}:{line}: {}", e.message)))?;
        Ok(scenario)
    }

    /// Makes every relative path relative to `base`.
    pub fn resolve_paths(&mut self, base: &Path) {
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        for fmu in self.fmu.values_mut() {
            resolve(&mut fmu.path);
            fmu.parameter_sets.iter_mut().for_each(resolve);
        }
        for signal in self.signal.values_mut() {
            if let Some(table) = &mut signal.table {
                resolve(&mut table.file);
            }
        }
    }

    /// Every file the run reads: the FMUs, their parameter sets, the
    /// reference tables (resolved as [`resolve_paths`](Self::resolve_paths)
    /// leaves them).
    pub fn input_files(&self) -> Vec<&Path> {
        let mut files = Vec::new();
        for fmu in self.fmu.values() {
            files.push(fmu.path.as_path());
            files.extend(fmu.parameter_sets.iter().map(PathBuf::as_path));
        }
        files.extend(
            self.signal
                .values()
                .filter_map(|s| s.table.as_ref().map(|t| t.file.as_path())),
        );
        files
    }

    /// The connections of the run.
    pub fn connections(&self) -> Vec<Connection> {
        self.connection.clone().unwrap_or_else(stage_wiring)
    }

    /// Number of communication steps.
    pub fn steps(&self) -> usize {
        (self.duration / self.step).round() as usize
    }

    /// Checks what does not need the FMUs.
    fn validate(&self) -> Result<(), Invalid> {
        if !(self.step.is_finite() && self.step > 0.0) {
            return Err(Invalid::key(
                "step",
                format!(
                    "step must be a positive number of seconds, not {}",
                    self.step
                ),
            ));
        }
        if !(self.duration.is_finite() && self.duration >= self.step) {
            return Err(Invalid::key(
                "duration",
                format!(
                    "duration must be at least one step ({} s), not {}",
                    self.step, self.duration
                ),
            ));
        }
        if self.duration / self.step > 1e9 {
            return Err(Invalid::key(
                "duration",
                format!(
                    "{} s at {} s per step is more than 1e9 steps",
                    self.duration, self.step
                ),
            ));
        }
        // The signals are sampled up to t_(steps + preview): a preview past
        // the run's end previews nothing the run uses.
        if self.preview as usize > self.steps() {
            return Err(Invalid::first_key(
                &["preview", "step", "duration"],
                format!(
                    "the run's {} steps (duration {} s at {} s a step) are fewer than its preview \
                     of {} samples (`preview`, {DEFAULT_PREVIEW} unless given): a shorter step, a \
                     longer duration or a shorter preview",
                    self.steps(),
                    self.duration,
                    self.step,
                    self.preview,
                ),
            ));
        }
        if self.fmu.is_empty() {
            return Err(Invalid::anywhere("no [fmu.<instance>] table".to_owned()));
        }
        let instance_of = |port: &str, what: &str| -> Result<(), Invalid> {
            let (instance, _) = split_port(port).ok_or_else(|| {
                Invalid::port(port, format!("{what} {port:?} is not `instance.variable`"))
            })?;
            if self.fmu.contains_key(instance) {
                Ok(())
            } else {
                Err(Invalid::port(
                    port,
                    format!(
                        "{what} {port:?}: no FMU instance {instance:?} (instances: {})",
                        self.fmu.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                ))
            }
        };
        // The default wiring is written nowhere: an instance it does not
        // know is the one to point at, not the wiring's port.
        if self.connection.is_none()
            && !(self.fmu.contains_key(PLANT) && self.fmu.contains_key(CONTROLLER))
        {
            let unknown = self
                .fmu
                .keys()
                .find(|name| ![PLANT, CONTROLLER].contains(&name.as_str()))
                .cloned();
            return Err(Invalid {
                message: format!(
                    "the stage's default wiring connects FMU instances \"{PLANT}\" and \
                     \"{CONTROLLER}\"; this scenario's are {}: name them so, or give \
                     [[connection]] entries",
                    self.fmu
                        .keys()
                        .map(|k| format!("{k:?}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                written: unknown.map_or(Written::Anywhere, Written::Instance),
            });
        }
        for connection in self.connections() {
            instance_of(&connection.from, "connection source")?;
            instance_of(&connection.to, "connection destination")?;
        }
        for (port, trajectory) in &self.signal {
            instance_of(port, "signal")?;
            trajectory
                .validate()
                .map_err(|e| Invalid::port(port, format!("signal {port:?}: {e}")))?;
        }
        for port in &self.record {
            instance_of(port, "recorded variable")?;
        }
        if let Some(metrics) = &self.metrics {
            // The window is the communication points t_k = k·step at or
            // after `from` (`metrics::first_sample`), of the run's whole
            // steps: a `from` inside the duration but past the last point
            // (2.02 of a 2.04 s run rounded to 2 s) left none, and one at
            // the last point left one sample, whose spans are all 0.
            let window = if metrics.from.is_finite() {
                let first = ((metrics.from - crate::metrics::WINDOW_SLACK) / self.step)
                    .ceil()
                    .max(0.0);
                (self.steps() as f64 + 1.0 - first).max(0.0)
            } else {
                0.0
            };
            if window < 2.0 {
                return Err(Invalid::table_key(
                    "metrics",
                    "from",
                    format!(
                        "metrics.from ({}) leaves {} of the run's samples to measure (it takes \
                         {} steps of {} s, to {} s); metrics need 2 or more",
                        metrics.from,
                        window,
                        self.steps(),
                        self.step,
                        self.steps() as f64 * self.step
                    ),
                ));
            }
            if let Some(spacing) = metrics.spacing
                && !(spacing.is_finite() && spacing > 0.0)
            {
                return Err(Invalid::table_key(
                    "metrics",
                    "spacing",
                    format!(
                        "metrics.spacing ({spacing}) must be a positive distance between the x \
                         sensors [um]"
                    ),
                ));
            }
            if let Some(circle) = &metrics.contour
                && !(circle.centre.iter().all(|c| c.is_finite())
                    && circle.radius.is_finite()
                    && circle.radius > 0.0)
            {
                return Err(Invalid::table_key(
                    "metrics",
                    "contour",
                    format!(
                        "metrics.contour: a circle needs a finite centre and a positive radius \
                         [um] (centre = [{}, {}], radius = {})",
                        circle.centre[0], circle.centre[1], circle.radius
                    ),
                ));
            }
            if metrics.driven == Driven::Xy && metrics.contour.is_none() {
                return Err(Invalid::table_key(
                    "metrics",
                    "driven",
                    "metrics of an xy run need the demanded contour: contour = { centre = [x, y], radius = r }"
                        .to_owned(),
                ));
            }
        }
        Ok(())
    }
}

/// A problem [`Scenario::validate`] found, and where it is written.
#[derive(Debug)]
struct Invalid {
    message: String,
    written: Written,
}

/// What locates a problem in a scenario's text.
#[derive(Debug)]
enum Written {
    /// A port, written in quotes: a signal's key, a connection's end, a
    /// recorded variable.
    Port(String),
    /// A key of a table (`""`: the top level, before any table header).
    Key {
        table: &'static str,
        key: &'static str,
    },
    /// The first of these top-level keys the text writes.
    FirstKey(&'static [&'static str]),
    /// An FMU instance, by its `[fmu.<name>]` header.
    Instance(String),
    /// The whole scenario.
    Anywhere,
}

impl Invalid {
    fn port(port: &str, message: String) -> Invalid {
        Invalid {
            message,
            written: Written::Port(port.to_owned()),
        }
    }

    fn key(key: &'static str, message: String) -> Invalid {
        Invalid::table_key("", key, message)
    }

    fn table_key(table: &'static str, key: &'static str, message: String) -> Invalid {
        Invalid {
            message,
            written: Written::Key { table, key },
        }
    }

    fn first_key(keys: &'static [&'static str], message: String) -> Invalid {
        Invalid {
            message,
            written: Written::FirstKey(keys),
        }
    }

    fn anywhere(message: String) -> Invalid {
        Invalid {
            message,
            written: Written::Anywhere,
        }
    }

    /// The 1-based line of `text` where the problem is written, if it can be
    /// found: the first line holding the quoted port (TOML or JSON), or the
    /// key's line inside its table (TOML).
    fn line(&self, text: &str, json: bool) -> Option<usize> {
        match &self.written {
            Written::Port(port) => return line_of_quoted(text, port),
            Written::FirstKey(keys) => {
                return keys
                    .iter()
                    .find_map(|key| Invalid::table_key("", key, String::new()).line(text, json));
            }
            Written::Instance(name) if !json => {
                let headers = [format!("[fmu.{name}]"), format!("[fmu.\"{name}\"]")];
                text.lines().position(|line| {
                    let line = line.split('#').next().unwrap_or("").trim();
                    headers.iter().any(|h| line.starts_with(h.as_str()))
                })
            }
            Written::Instance(name) => line_of_quoted(text, name).map(|line| line - 1),
            Written::Key { .. } if json => None,
            Written::Key { table, key } => {
                let mut current = "";
                text.lines().position(|line| {
                    let line = line.split('#').next().unwrap_or("").trim();
                    if let Some(header) = line.strip_prefix('[') {
                        current = header.trim_end_matches(']').trim();
                        return false;
                    }
                    current == *table
                        && line
                            .strip_prefix(*key)
                            .is_some_and(|rest| rest.trim_start().starts_with('='))
                })
            }
            Written::Anywhere => None,
        }
        .map(|at| at + 1)
    }
}

/// The 1-based line of `text` (TOML or JSON) that first writes `port` in
/// double quotes, as a signal's key, a connection's end or a recorded
/// variable are written.
pub fn line_of_quoted(text: &str, port: &str) -> Option<usize> {
    let quoted = format!("\"{port}\"");
    text.lines()
        .position(|line| line.contains(&quoted))
        .map(|at| at + 1)
}

/// 1-based line and column of a byte offset.
fn line_and_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before
        .rfind('\n')
        .map_or(before.len(), |i| before.len() - i - 1)
        + 1;
    (line, column)
}

/// A scenario from JSON text, or the line, the column and the problem,
/// which names the key it is at (`metrics.driven: unknown variant ...`).
fn from_json(text: &str) -> Result<Scenario, (usize, usize, String)> {
    let located = |key: &str, error: serde_json::Error| {
        let problem = match key {
            // The document itself, or the text ended before a key.
            "." | "?" => json_problem(&error),
            key => format!("{key}: {}", json_problem(&error)),
        };
        (error.line(), error.column(), problem)
    };
    let mut reader = serde_json::Deserializer::from_str(text);
    let scenario = serde_path_to_error::deserialize(&mut reader).map_err(|e| {
        let key = key_path(e.path());
        located(&key, e.into_inner())
    })?;
    reader.end().map_err(|e| located(".", e))?;
    Ok(scenario)
}

/// A key's path as a scenario writes it: `fmu.plant.parameters."noise.seed"`.
/// serde_path_to_error joins every key with dots, so an FMI name that holds
/// dots or brackets (`noise.seed`, `pzt[2].beta`) would read as several
/// levels; such a key is quoted, as TOML quotes it.
fn key_path(path: &serde_path_to_error::Path) -> String {
    use serde_path_to_error::Segment;
    if path.iter().next().is_none() {
        return ".".to_owned();
    }
    let bare = |key: &str| {
        !key.is_empty()
            && key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    };
    let mut text = String::new();
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => text.push_str(&format!("[{index}]")),
            segment => {
                if !text.is_empty() {
                    text.push('.');
                }
                match segment {
                    Segment::Map { key } if !bare(key) => {
                        // JSON's escapes are TOML's basic string's.
                        text.push_str(&serde_json::to_string(key).unwrap_or_default())
                    }
                    segment => text.push_str(&segment.to_string()),
                }
            }
        }
    }
    text
}

/// Reads a parameter set `{ "<FMI name>": value, ... }` (the format of
/// dist/presets/*.json).
pub fn read_parameter_set(path: &Path) -> Result<Vec<(String, ParameterValue)>, ScenarioError> {
    fmi2_import::parameter_set::read_parameter_set(path).map_err(ScenarioError)
}

impl FmuSpec {
    /// Every parameter value of this FMU, the sets first, then the
    /// scenario's own values; a later value of a name replaces an earlier one.
    pub fn parameter_values(&self) -> Result<BTreeMap<String, ParameterValue>, ScenarioError> {
        let mut values = BTreeMap::new();
        for set in &self.parameter_sets {
            values.extend(read_parameter_set(set)?);
        }
        values.extend(self.parameters.iter().map(|(k, v)| (k.clone(), *v)));
        Ok(values)
    }

    /// Where the value of parameter `name` comes from, for messages: the
    /// parameter set that gives it (the last one, as it wins), or None for
    /// the scenario's own `parameters`.
    pub fn parameter_origin(&self, name: &str) -> Option<&Path> {
        if self.parameters.contains_key(name) {
            return None;
        }
        self.parameter_sets
            .iter()
            .rev()
            .find(|set| read_parameter_set(set).is_ok_and(|v| v.iter().any(|(n, _)| n == name)))
            .map(PathBuf::as_path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
duration = 1.0
[fmu.plant]
path = "p.fmu"
[fmu.controller]
path = "c.fmu"
"#;

    #[test]
    fn defaults_are_the_demos_master() {
        let s = Scenario::parse(MINIMAL, false, "s.toml").unwrap();
        assert_eq!((s.step, s.preview, s.steps()), (1e-4, 2, 10_000));
        assert_eq!(s.connections(), stage_wiring());
        assert_eq!(s.connections().len(), 6);
    }

    /// A scenario saved with a UTF-8 byte-order mark (as Windows editors
    /// save) reads as its twin without one, in TOML, JSON and a batch line;
    /// its errors are placed as an editor shows the text.
    #[test]
    fn a_byte_order_mark_is_not_part_of_the_scenario() {
        let plain = Scenario::parse(MINIMAL, false, "s.toml").unwrap();
        let marked = Scenario::parse(&format!("\u{feff}{MINIMAL}"), false, "s.toml").unwrap();
        assert_eq!(marked.connections(), plain.connections());
        let json = r#"{"duration": 1.0, "fmu": {"plant": {"path": "p.fmu"}, "controller": {"path": "c.fmu"}}}"#;
        let marked = Scenario::parse(&format!("\u{feff}{json}"), true, "s.json").unwrap();
        assert_eq!(marked.steps(), 10_000);
        let line = Scenario::parse_json_line(&format!("\u{feff}{json}"), "runs.jsonl", 1).unwrap();
        assert_eq!(line.steps(), 10_000);
        let e = Scenario::parse("\u{feff}{\"duration\": }", true, "s.json")
            .unwrap_err()
            .0;
        assert!(e.starts_with("s.json:1:14: "), "{e}");
    }

    #[test]
    fn driven_reads_the_names_it_writes() {
        for (driven, name) in Driven::ALL.iter().zip(Driven::NAMES) {
            assert_eq!(
                serde_json::to_string(driven).unwrap(),
                format!("\"{name}\"")
            );
            assert_eq!(
                serde_json::from_str::<Driven>(&format!("\"{name}\"")).unwrap(),
                *driven
            );
        }
    }

    #[test]
    fn a_driven_axis_of_another_kind_or_name_says_what_it_may_be() {
        let base = r#"{"duration": 1.0, "fmu": {"plant": {"path": "p.fmu"},
            "controller": {"path": "c.fmu"}}, "metrics": {"driven": DRIVEN}}"#;
        for (value, problem) in [
            (
                "true",
                "metrics.driven: invalid type: boolean `true`, expected one of `y`, `x`, `theta`, `xy`, `ytheta`",
            ),
            (
                "\"z\"",
                "metrics.driven: unknown variant `z`, expected one of `y`, `x`, `theta`, `xy`, `ytheta`",
            ),
        ] {
            let text = base.replace("DRIVEN", value);
            let e = Scenario::parse(&text, true, "s.json").unwrap_err().0;
            // The line of the value, and the column serde_json stopped at.
            assert!(
                e.starts_with("s.json:2:") && e.ends_with(&format!(": {problem}")),
                "{e}"
            );
            let toml = format!("{MINIMAL}\n[metrics]\ndriven = {value}\n");
            let e = Scenario::parse(&toml, false, "s.toml").unwrap_err().0;
            assert!(e.starts_with("s.toml:9:10: "), "{e}");
            assert!(
                e.contains("expected one of `y`, `x`, `theta`, `xy`, `ytheta`"),
                "{e}"
            );
        }
    }

    #[test]
    fn a_key_holding_dots_or_brackets_is_quoted_in_its_path() {
        let text = r#"{"duration": 1.0, "fmu": {"plant": {"path": "p.fmu",
            "parameters": {"noise.enabled": true, "pzt[2].beta": "high"}},
            "controller": {"path": "c.fmu", "parameters": {"decoupling": "yes"}}}}"#;
        let e = Scenario::parse(text, true, "s.json").unwrap_err().0;
        assert!(
            e.starts_with("s.json:2:71: fmu.plant.parameters.\"pzt[2].beta\": invalid type"),
            "{e}"
        );
        let e = Scenario::parse(&text.replace("\"high\"", "1.0"), true, "s.json")
            .unwrap_err()
            .0;
        assert!(
            e.contains(": fmu.controller.parameters.decoupling: invalid type"),
            "{e}"
        );
    }

    #[test]
    fn an_unknown_key_names_file_line_and_key() {
        let text = format!("{MINIMAL}\n[metrics]\ndriven = \"y\"\nfrom = 0.5\nform = 1\n");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(e.starts_with("s.toml:11:"), "{e}");
        assert!(e.contains("unknown field `form`"), "{e}");
    }

    #[test]
    fn a_json_line_names_its_line_and_column() {
        let e = Scenario::parse_json_line(r#"{"duration": 1.0, "fmu": 3}"#, "runs.jsonl", 7)
            .unwrap_err()
            .0;
        assert!(
            e.starts_with("runs.jsonl:7:26: fmu: invalid type: integer `3`"),
            "{e}"
        );
        assert!(!e.contains("at line 1"), "{e}");
        let e = Scenario::parse_json_line(r#"{"duration": 1.0, "fmu": {}}"#, "runs.jsonl", 8)
            .unwrap_err()
            .0;
        assert_eq!(e, "runs.jsonl:8: no [fmu.<instance>] table");
    }

    #[test]
    fn a_json_scenario_and_a_parameter_set_name_the_place_once() {
        let e = Scenario::parse("{\n  \"duration\": \"long\"\n}", true, "run.json")
            .unwrap_err()
            .0;
        assert!(
            e.starts_with("run.json:2:20: duration: invalid type: string \"long\""),
            "{e}"
        );
        assert!(!e.contains("at line"), "{e}");
        let file = std::env::temp_dir().join(format!("set-{}.json", std::process::id()));
        std::fs::write(&file, "{\"x.c\": 1,\n\"L\" 2}").unwrap();
        let e = read_parameter_set(&file).unwrap_err().0;
        std::fs::remove_file(&file).unwrap();
        assert_eq!(e, format!("{}:2:5: expected `:`", file.display()));
    }

    #[test]
    fn a_preview_longer_than_the_run_is_refused() {
        let text = MINIMAL.replace("duration = 1.0", "duration = 1.0\npreview = 10001");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert_eq!(
            e,
            "s.toml:3: the run's 10000 steps (duration 1 s at 0.0001 s a step) are fewer than \
             its preview of 10001 samples (`preview`, 2 unless given): a shorter step, a longer \
             duration or a shorter preview"
        );
        // Not written, the default preview is pointed at by the step.
        let text = MINIMAL.replace("duration = 1.0", "duration = 0.2\nstep = 0.15");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(
            e.starts_with("s.toml:3: the run's 1 steps (duration 0.2 s at 0.15 s a step)"),
            "{e}"
        );
        let text = MINIMAL.replace("duration = 1.0", "duration = 1.0\npreview = 10000");
        assert!(Scenario::parse(&text, false, "s.toml").is_ok());
    }

    #[test]
    fn a_wrong_type_names_the_line() {
        let e = Scenario::parse("duration = \"long\"\n", false, "s.toml")
            .unwrap_err()
            .0;
        assert!(e.starts_with("s.toml:1:"), "{e}");
    }

    #[test]
    fn json_errors_name_line_and_column() {
        let e = Scenario::parse("{\n \"duration\": 1.0,\n \"fmu\": 3\n}", true, "s.json")
            .unwrap_err()
            .0;
        assert!(e.starts_with("s.json:3:"), "{e}");
    }

    /// A port of an unknown instance is named at the line that writes it:
    /// a signal's table, a connection's end, a recorded variable, in TOML
    /// and in JSON.
    /// A misspelt instance under the default wiring was named by the
    /// wiring's port, which the scenario does not write ("connection source
    /// \"controller.u1\": no FMU instance"); it is named at its header.
    #[test]
    fn the_default_wiring_names_the_instance_it_lacks() {
        let text = MINIMAL.replace("[fmu.controller]", "[fmu.controler]");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert_eq!(
            e,
            "s.toml:5: the stage's default wiring connects FMU instances \"plant\" and \
             \"controller\"; this scenario's are \"controler\", \"plant\": name them so, or \
             give [[connection]] entries"
        );
    }

    #[test]
    fn ports_must_name_an_instance() {
        let text = format!("{MINIMAL}\n[signal.\"ctrl.y_ref\"]\noffset = 1.0\n");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert_eq!(
            e,
            "s.toml:8: signal \"ctrl.y_ref\": no FMU instance \"ctrl\" (instances: controller, plant)"
        );
        let text = MINIMAL.replace(
            "duration = 1.0",
            "duration = 1.0\nrecord = [\"plant.x\",\n  \"plant.y\", \"stage.y\"]",
        ) + "[[connection]]\nfrom = \"plant.y\"\nto = \"ctrl.y\"\n";
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(
            e.starts_with("s.toml:11: connection destination \"ctrl.y\""),
            "{e}"
        );
        let text = text.replace("\"ctrl.y\"", "\"controller.y\"");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(
            e.starts_with("s.toml:4: recorded variable \"stage.y\""),
            "{e}"
        );
        let json = "{\n \"duration\": 1.0,\n \"fmu\": {\"plant\": {\"path\": \"p.fmu\"}, \"controller\": {\"path\": \"c.fmu\"}},\n \
                    \"record\": [\"plant.x\",\n  \"plant_x\"]\n}";
        let e = Scenario::parse(json, true, "s.json").unwrap_err().0;
        assert_eq!(
            e,
            "s.json:5: recorded variable \"plant_x\" is not `instance.variable`"
        );
    }

    /// A top-level or [metrics] value out of range is named at its line;
    /// in JSON, where keys are not located, at the file.
    #[test]
    fn a_value_out_of_range_names_its_line() {
        let text = MINIMAL.replace("duration = 1.0", "# a run\nstep = -1e-4\nduration = 1.0");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(e.starts_with("s.toml:3: step must be a positive"), "{e}");
        let text = format!("{MINIMAL}\n[metrics]\ndriven = \"y\"\nfrom = 1.5 # after the end\n");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(e.starts_with("s.toml:10: metrics.from (1.5)"), "{e}");
        // Inside the duration, but past the last whole step (2.04 s at 0.1 s
        // per step runs 20 steps, to 2 s), or at it: no window to measure.
        for (from, left) in [("2.02", 0), ("2", 1)] {
            let text = format!(
                "{}\n[metrics]\ndriven = \"y\"\nfrom = {from}\n",
                MINIMAL.replace("duration = 1.0", "duration = 2.04\nstep = 0.1")
            );
            let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
            assert_eq!(
                e,
                format!(
                    "s.toml:11: metrics.from ({from}) leaves {left} of the run's samples to \
                     measure (it takes 20 steps of 0.1 s, to 2 s); metrics need 2 or more"
                )
            );
        }
        let text = format!(
            "{}\n[metrics]\ndriven = \"y\"\nfrom = 1.9\n",
            MINIMAL.replace("duration = 1.0", "duration = 2.04\nstep = 0.1")
        );
        assert!(Scenario::parse(&text, false, "s.toml").is_ok());
        let json =
            "{\n \"duration\": 1.0,\n \"step\": 0,\n \"fmu\": {\"p\": {\"path\": \"p.fmu\"}}\n}";
        let e = Scenario::parse(json, true, "s.json").unwrap_err().0;
        assert!(e.starts_with("s.json: step must be a positive"), "{e}");
    }

    #[test]
    fn variable_names_keep_their_dots() {
        assert_eq!(split_port("plant.pzt[1].A"), Some(("plant", "pzt[1].A")));
        assert_eq!(split_port("plant"), None);
        assert_eq!(split_port(".x"), None);
    }

    #[test]
    fn xy_metrics_need_the_contour() {
        let text = format!("{MINIMAL}\n[metrics]\ndriven = \"xy\"\nfrom = 0.5\n");
        let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
        assert!(e.contains("contour"), "{e}");
    }

    /// A sensor spacing of 0 or below, or a circle of no radius, made null or
    /// meaningless figures with exit 0; each is refused at its line.
    #[test]
    fn metric_geometry_must_be_positive() {
        for (metrics, line, said) in [
            (
                "driven = \"theta\"\nfrom = 0.5\nspacing = 0.0",
                11,
                "metrics.spacing (0) must be a positive distance between the x sensors [um]",
            ),
            (
                "driven = \"theta\"\nfrom = 0.5\nspacing = -5.0",
                11,
                "metrics.spacing (-5) must be a positive distance between the x sensors [um]",
            ),
            (
                "driven = \"xy\"\nfrom = 0.5\ncontour = { centre = [0, 2], radius = -1 }",
                11,
                "metrics.contour: a circle needs a finite centre and a positive radius [um] \
                 (centre = [0, 2], radius = -1)",
            ),
        ] {
            let text = format!("{MINIMAL}\n[metrics]\n{metrics}\n");
            let e = Scenario::parse(&text, false, "s.toml").unwrap_err().0;
            assert_eq!(e, format!("s.toml:{line}: {said}"));
        }
        let text = format!(
            "{MINIMAL}\n[metrics]\ndriven = \"xy\"\nfrom = 0.5\ncontour = {{ centre = [6, 6], radius = 5 }}\n"
        );
        assert!(Scenario::parse(&text, false, "s.toml").is_ok());
    }

    #[test]
    fn parameters_accept_integers_reals_and_booleans() {
        let text = format!(
            "{MINIMAL}\n[fmu.plant.parameters]\n\"noise.seed\" = 7\n\"noise.enabled\" = true\nL = 73.5\n"
        );
        let s = Scenario::parse(&text, false, "s.toml").unwrap();
        let p = &s.fmu["plant"].parameters;
        assert_eq!(p["noise.seed"], ParameterValue::Number(7.0));
        assert_eq!(p["noise.enabled"], ParameterValue::Boolean(true));
        assert_eq!(p["L"], ParameterValue::Number(73.5));
    }
}
