//! `piezo-cosim run SCENARIO`: runs one co-simulation scenario (TOML or JSON,
//! see `piezo_cosim::scenario`) and prints its result as JSON.
//! `piezo-cosim batch RUNS.jsonl`: runs one scenario per line, each FMU
//! opened once, and prints one result per line as it completes.
//!
//! Exit status: 0 the run completed (batch: every line's run completed); 1
//! an FMU refused a call or failed a step; 2 the scenario is malformed or
//! does not fit the FMUs. A batch answers every line and then exits with
//! the highest status of its lines, so `piezo-cosim batch runs.jsonl && ...`
//! goes on only when every run completed.

use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use piezo_cosim::{OpenFmus, RunError, RunOptions, RunOutput, Scenario, run, run_with, series};
use result_files::{is_device, same_file};
use serde_json::json;

#[derive(Parser)]
#[command(
    name = "piezo-cosim",
    version,
    about = "Co-simulation master for FMI 2.0 co-simulation FMUs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Runs a scenario; prints {status, steps, wall_s, metrics, warnings} as JSON.
    Run {
        /// Scenario file (.toml or .json), or `-` for JSON on stdin (relative
        /// paths then relative to the working directory).
        scenario: PathBuf,
        /// Writes the time series (every Real output and signal) as CSV.
        #[arg(long, value_name = "FILE.csv")]
        series: Option<PathBuf>,
        /// Writes the JSON result to this file instead of stdout.
        #[arg(long, value_name = "FILE.json")]
        out: Option<PathBuf>,
        /// Ends with the process PID that started it (Linux): a run whose
        /// caller was killed (a dask worker) does not run on as an orphan.
        #[arg(long, value_name = "PID")]
        parent: Option<u32>,
    },
    /// Runs many scenarios in one process: one JSON scenario per line (as
    /// `run -` takes it); prints one JSON result per line, in order, each as
    /// its run completes: `run`'s result with the line number, or
    /// {status: "error", exit, error, line} for a run that failed (the
    /// others still run). Each FMU is opened once and instantiated per run.
    /// Exits with the highest `exit` of its lines: 0 only when every run
    /// completed.
    Batch {
        /// JSON Lines file of scenarios (paths relative to its folder), or
        /// `-` for stdin (paths relative to the working directory).
        scenarios: PathBuf,
        /// As for `run`.
        #[arg(long, value_name = "PID")]
        parent: Option<u32>,
    },
    /// Checks a scenario against its FMUs without stepping: loads them,
    /// resolves every connection, signal and parameter, initializes.
    Check {
        /// Scenario file (.toml or .json), or `-` for JSON on stdin.
        scenario: PathBuf,
    },
    /// Prints every metric a run can report as JSON: {name: {unit, range,
    /// description}}, the unit of a driven-axis figure by axis.
    Metrics,
}

/// Asks the kernel to kill this process when its parent ends, then checks
/// that the parent is still `pid` (it may have ended before the request).
#[cfg(target_os = "linux")]
fn exit_with_parent(pid: u32) {
    // SAFETY: prctl with PR_SET_PDEATHSIG takes a signal number and no pointer.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) };
    // SAFETY: getppid has no preconditions.
    if unsafe { libc::getppid() } as u32 != pid {
        eprintln!("the parent process {pid} has ended");
        std::process::exit(1);
    }
}

#[cfg(not(target_os = "linux"))]
fn exit_with_parent(_pid: u32) {}

fn load(path: &Path) -> Result<Scenario, String> {
    if path.as_os_str() == "-" {
        let mut text = String::new();
        std::io::stdin()
            .read_to_string(&mut text)
            .map_err(|e| format!("stdin: {e}"))?;
        Scenario::parse(&text, true, "<stdin>").map_err(|e| e.0)
    } else {
        Scenario::from_file(path).map_err(|e| e.0)
    }
}

/// The 1-based line of a scenario's text where the port an error message
/// starts with (`instance.variable: ...`, `instance` one of `instances`) is
/// written: the port in quotes (a signal or a connection), else the variable
/// as a whole name inside the instance's `[fmu.instance]` tables (a
/// parameter). None for any other message, or a port written nowhere (a
/// value from a parameter set, which names its own file).
fn line_of_port<'a>(
    text: &str,
    message: &str,
    instances: impl Iterator<Item = &'a str>,
) -> Option<usize> {
    let instances: Vec<&str> = instances.collect();
    // `controller.decoupling is a Boolean variable ...`, `plant.x: ...`,
    // `connection source plant.u1 is not an output ...`
    let named = message
        .strip_prefix("connection source ")
        .or_else(|| message.strip_prefix("connection destination "))
        .unwrap_or(message);
    let port = named
        .split(|c: char| c == ':' || c.is_whitespace())
        .next()?;
    if let Some((instance, variable)) = port.split_once('.')
        && instances.contains(&instance)
    {
        if let Some(line) = piezo_cosim::scenario::line_of_quoted(text, port) {
            return Some(line);
        }
        return line_in_instance_table(text, instance, variable);
    }
    // What an FMU refused, in its log: `controller: fmi2SetReal ...: value
    // reference 6 (u1) cannot be set`, `... parameter translation.kp = -0.1
    // is outside ...`.
    let (instance, log) = message.split_once(": ")?;
    if !instances.contains(&instance) {
        return None;
    }
    let named = log
        .split_once("parameter ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .or_else(|| {
            log.split_once("value reference ")
                .and_then(|(_, rest)| rest.split_once('(')?.1.split_once(')'))
                .map(|(name, _)| name)
        })?;
    line_in_instance_table(text, instance, named)
}

/// The 1-based line of `text` that writes `key` (a whole name) inside the
/// tables of `instance` (`[fmu.instance]` and its subtables).
fn line_in_instance_table(text: &str, instance: &str, key: &str) -> Option<usize> {
    let is_name_char = |c: char| c.is_alphanumeric() || c == '_';
    let holds = |line: &str, needle: &str| {
        line.match_indices(needle).any(|(at, _)| {
            let before = line[..at].chars().next_back();
            let after = line[at + needle.len()..].chars().next();
            !before.is_some_and(is_name_char) && !after.is_some_and(is_name_char)
        })
    };
    let own_table = [format!("[fmu.{instance}"), format!("[fmu.\"{instance}\"")];
    let mut inside = false;
    for (at, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            inside = own_table.iter().any(|table| {
                trimmed
                    .strip_prefix(table.as_str())
                    .is_some_and(|rest| rest.starts_with(']') || rest.starts_with('.'))
            });
        } else if inside && holds(line.split('#').next().unwrap_or(""), key) {
            return Some(at + 1);
        }
    }
    None
}

/// The 1-based line of the `path` of the FMU an error message starts with
/// (`/dist/F.fmu: No such file or directory`), `paths` being each
/// instance's path as resolved.
fn line_of_fmu_path<'a>(
    text: &str,
    message: &str,
    mut paths: impl Iterator<Item = (&'a str, &'a Path)>,
) -> Option<usize> {
    let (instance, _) =
        paths.find(|(_, path)| message.starts_with(&format!("{}: ", path.display())))?;
    line_in_instance_table(text, instance, "path").or_else(|| {
        // A JSON scenario: the first "path" after the instance's key.
        let key = text.find(&format!("\"{instance}\""))?;
        let path = key + text[key..].find("\"path\"")?;
        Some(text[..path].matches('\n').count() + 1)
    })
}

/// Where the results go: the process's standard output, moved to a
/// descriptor of its own, with standard output itself pointed at the error
/// stream (Linux). An FMU may print (a C runtime's printf, a tool's log):
/// that text then lands among the errors, never inside the JSON a caller
/// parses line by line.
fn results_output() -> Box<dyn Write> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::FromRawFd;
        // SAFETY: dup takes a descriptor number; 1 is the standard output.
        let results = unsafe { libc::dup(1) };
        if results >= 0 {
            // SAFETY: dup2 takes descriptor numbers; 2 and 1 are the
            // standard streams, and nothing has been written to 1 yet.
            if unsafe { libc::dup2(2, 1) } >= 0 {
                // SAFETY: `results` was just opened by dup and is owned by
                // nothing else.
                return Box::new(unsafe { std::fs::File::from_raw_fd(results) });
            }
            // SAFETY: `results` is open and nothing else owns it.
            unsafe { libc::close(results) };
        }
    }
    Box::new(std::io::stdout())
}

/// Writes one result line and flushes it.
fn emit(output: &mut dyn Write, line: &str) -> std::io::Result<()> {
    output.write_all(format!("{line}\n").as_bytes())?;
    output.flush()
}

/// The exit status of a run that did not complete.
fn exit_code(e: &RunError) -> u8 {
    match e {
        RunError::Scenario(_) => 2,
        RunError::Fmu(_) => 1,
    }
}

/// A completed run's result, as `run` prints it.
fn result_json(scenario: &Scenario, output: &RunOutput) -> serde_json::Value {
    let simulated = output.steps as f64 * scenario.step;
    json!({
        "status": "ok",
        "steps": output.steps,
        "simulated_s": simulated,
        "wall_s": output.wall_s,
        "loop_s": output.loop_s,
        "realtime_factor": simulated / output.wall_s,
        "metrics": output.metrics,
        "warnings": output.warnings,
    })
}

/// `piezo-cosim batch`: every line of `source` run in turn, one result line
/// each, flushed as it is written (a caller reads them as they come and
/// knows which run a stall belongs to).
fn batch(source: &Path, results: &mut dyn Write) -> ExitCode {
    let (reader, origin, base): (Box<dyn BufRead>, String, Option<&Path>) =
        if source.as_os_str() == "-" {
            (
                Box::new(std::io::stdin().lock()),
                "<stdin>".to_owned(),
                None,
            )
        } else {
            match std::fs::File::open(source) {
                Ok(file) => (
                    Box::new(std::io::BufReader::new(file)),
                    source.display().to_string(),
                    Some(source.parent().unwrap_or(Path::new(""))),
                ),
                Err(e) => {
                    eprintln!("{}: {e}", source.display());
                    return ExitCode::from(2);
                }
            }
        };
    let mut open = OpenFmus::default();
    // The highest exit status of the lines answered so far.
    let mut worst = 0u8;
    for (index, line) in reader.lines().enumerate() {
        let number = index + 1;
        let line = match line {
            Ok(line) => line,
            Err(e) => {
                eprintln!("{origin}:{number}: {e}");
                return ExitCode::from(2);
            }
        };
        if line.trim().is_empty() {
            continue;
        }
        let outcome = Scenario::parse_json_line(&line, &origin, number)
            .map_err(RunError::from)
            .and_then(|mut scenario| {
                if let Some(base) = base {
                    scenario.resolve_paths(base);
                }
                run_with(&scenario, RunOptions::default(), &mut open)
                    .map(|output| result_json(&scenario, &output))
            });
        let mut result = outcome.unwrap_or_else(|e| {
            worst = worst.max(exit_code(&e));
            json!({"status": "error", "exit": exit_code(&e), "error": e.to_string()})
        });
        result["line"] = json!(number);
        if emit(results, &result.to_string()).is_err() {
            // The reader has gone: nobody wants the remaining runs.
            return ExitCode::from(1);
        }
    }
    ExitCode::from(worst)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let mut results = results_output();
    let (scenario, series_path, out, check_only) = match cli.command {
        Command::Run {
            scenario,
            series,
            out,
            parent,
        } => {
            if let Some(pid) = parent {
                exit_with_parent(pid);
            }
            (scenario, series, out, false)
        }
        Command::Batch { scenarios, parent } => {
            if let Some(pid) = parent {
                exit_with_parent(pid);
            }
            return batch(&scenarios, &mut *results);
        }
        Command::Check { scenario } => (scenario, None, None, true),
        Command::Metrics => {
            let json = piezo_cosim::metrics::definitions_json();
            let text = serde_json::to_string_pretty(&json).expect("JSON prints");
            return match writeln!(results, "{text}") {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("{e}");
                    ExitCode::FAILURE
                }
            };
        }
    };
    if let Some(path) = &series_path
        && path.extension().is_none_or(|e| e != "csv")
        && !is_device(path)
        && !path.is_dir()
    {
        eprintln!(
            "{}: the series is written as CSV (name it .csv); `python -m demo.master` also writes Parquet",
            path.display()
        );
        return ExitCode::from(2);
    }
    // A folder the series or the results cannot be written in is found
    // before the run, not after it; so is a path that is a folder, or the
    // scenario itself (written over, it was lost), or one path for both.
    if let (Some(series), Some(out)) = (&series_path, &out)
        && same_file(series, out)
    {
        eprintln!(
            "--series and --out both name {}: give each its own file",
            out.display()
        );
        return ExitCode::from(2);
    }
    for path in [&series_path, &out].into_iter().flatten() {
        if let Err(e) = result_files::check_destination(path) {
            eprintln!("{}: {e}", path.display());
            return ExitCode::from(2);
        }
        if same_file(path, &scenario) {
            eprintln!(
                "{}: is the scenario being run; writing there would overwrite it, so give \
                 another name",
                path.display()
            );
            return ExitCode::from(2);
        }
    }
    let scenario_path = scenario;
    let scenario = match load(&scenario_path) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    // Nor may a result overwrite a file the run reads (a reference table,
    // a parameter set, an FMU).
    for path in [&series_path, &out].into_iter().flatten() {
        if let Some(input) = scenario
            .input_files()
            .into_iter()
            .find(|f| same_file(path, f))
        {
            eprintln!(
                "{}: is {}, which the scenario reads; writing there would overwrite it, so \
                 give another name",
                path.display(),
                input.display()
            );
            return ExitCode::from(2);
        }
    }
    let options = RunOptions {
        series: series_path.is_some(),
        check_only,
    };
    let output = match run(&scenario, options) {
        Ok(output) => output,
        Err(e) => {
            match (&e, std::fs::read_to_string(&scenario_path)) {
                // A scenario problem found against the FMUs (a misspelt
                // variable, an unknown instance) is named where it is written.
                (RunError::Scenario(message), Ok(text)) => {
                    let instances = scenario.fmu.keys().map(String::as_str);
                    let paths = scenario
                        .fmu
                        .iter()
                        .map(|(k, f)| (k.as_str(), f.path.as_path()));
                    match line_of_port(&text, message, instances)
                        .or_else(|| line_of_fmu_path(&text, message, paths))
                    {
                        Some(line) => eprintln!("{}:{line}: {message}", scenario_path.display()),
                        None => eprintln!("{}: {message}", scenario_path.display()),
                    }
                }
                _ => eprintln!("{e}"),
            }
            return ExitCode::from(exit_code(&e));
        }
    };
    if let (Some(path), Some(series)) = (&series_path, &output.series)
        && let Err(e) = series::write_csv(series, path)
    {
        eprintln!("{e}");
        return ExitCode::from(1);
    }
    if check_only {
        let line = json!({"status": "ok", "warnings": output.warnings}).to_string();
        return match emit(&mut *results, &line) {
            Ok(()) => ExitCode::SUCCESS,
            Err(_) => ExitCode::from(1),
        };
    }
    let result = result_json(&scenario, &output);
    let text = result.to_string();
    match out {
        Some(path) => {
            if let Err(e) = result_files::write_atomically(&path, |out| writeln!(out, "{text}")) {
                eprintln!("{}: {e}", path.display());
                return ExitCode::from(1);
            }
        }
        None => {
            if emit(&mut *results, &text).is_err() {
                return ExitCode::from(1);
            }
        }
    }
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::{line_of_fmu_path, line_of_port};

    const SCENARIO: &str = r#"duration = 1.0
# feedbak_y in a comment is not where it is written
[fmu.plant]
path = "p.fmu"
parameters = { feedbak_y = 1.0 }

[fmu.controller]
path = "c.fmu"
parameters = { feedforward = true,
  feedbak_y = true }

[signal."controller.x_reff"]
offset = 0.0
"#;

    fn line(message: &str) -> Option<usize> {
        line_of_port(SCENARIO, message, ["plant", "controller"].into_iter())
    }

    #[test]
    fn a_port_is_found_in_its_instances_table_or_quoted() {
        assert_eq!(
            line("controller.feedbak_y: c.fmu has no variable"),
            Some(10)
        );
        assert_eq!(line("plant.feedbak_y: p.fmu has no variable"), Some(5));
        assert_eq!(line("controller.x_reff: c.fmu has no variable"), Some(12));
        // Written nowhere (a parameter set's value), another instance, not a port.
        assert_eq!(line("controller.gain: c.fmu has no variable"), None);
        assert_eq!(line("stage.feedbak_y: no FMU instance"), None);
        assert_eq!(line("/tmp/c.fmu: cannot be opened"), None);
        // A value of the wrong type, and what an FMU refused in its log.
        assert_eq!(
            line("controller.feedforward is a Boolean variable, which takes true or false"),
            Some(9)
        );
        assert_eq!(
            line(
                "controller: fmi2ExitInitializationMode returned status 3 at t = 0 s: \
                 [logStatusError] fmi2ExitInitializationMode: parameter feedbak_y = -1 is \
                 outside its allowed range"
            ),
            Some(10)
        );
        assert_eq!(
            line(
                "plant: fmi2SetReal returned status 3 at t = 0 s: [logStatusError] \
                 fmi2SetReal: value reference 6 (feedbak_y) cannot be set"
            ),
            Some(5)
        );
        assert_eq!(line("controller: fmi2DoStep returned status 3"), None);
        // A connection's end the FMU does not have that way round: the
        // connection that writes it (SCENARIO's own signal key here).
        assert_eq!(
            line(
                "connection source controller.x_reff is not an output (in c.fmu its causality is input)"
            ),
            Some(12)
        );
    }

    #[test]
    fn a_missing_fmu_is_found_at_its_path() {
        let paths = [
            ("plant", std::path::Path::new("/work/p.fmu")),
            ("controller", std::path::Path::new("/work/c.fmu")),
        ];
        let at = |message| line_of_fmu_path(SCENARIO, message, paths.into_iter());
        assert_eq!(
            at("/work/c.fmu: No such file or directory (os error 2)"),
            Some(8)
        );
        assert_eq!(at("/work/p.fmu: not an FMU archive"), Some(4));
        assert_eq!(at("/work/other.fmu: No such file"), None);
        let json = "{\"duration\": 1.0, \"fmu\": {\n  \"plant\": {\"path\": \"p.fmu\"},\n  \
                    \"controller\":\n    {\"path\": \"c.fmu\"}}}";
        let at = |message| line_of_fmu_path(json, message, paths.into_iter());
        assert_eq!(
            at("/work/p.fmu: No such file or directory (os error 2)"),
            Some(2)
        );
        assert_eq!(
            at("/work/c.fmu: No such file or directory (os error 2)"),
            Some(4)
        );
    }
}
