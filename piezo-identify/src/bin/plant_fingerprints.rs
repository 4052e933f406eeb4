//! `plant-fingerprints`: measures a FlexureStage FMU's calibration
//! fingerprints through FMI (the procedures and seed 000's targets of
//! `piezo_models::fingerprint`) and judges each against its tolerance.
//!
//! Prints the checks as JSON (`--json`) or as a Markdown table; `--out DIR`
//! also writes `DIR/report.md` and `DIR/fingerprints.json`.
//!
//! Exit status: 0 every check holds; 1 a check fails; 2 the FMU or the
//! parameter set could not be loaded or driven.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use piezo_identify::fingerprints::measure;
use piezo_identify::plant::{PlantFmu, read_parameter_set};
use piezo_models::fingerprint::{Check, Fingerprints, ZieglerNicholsReading};
use serde_json::json;

#[derive(Parser)]
#[command(
    name = "plant-fingerprints",
    version,
    about = "Measures a FlexureStage FMU's calibration fingerprints through FMI beside seed 000's figures"
)]
struct Args {
    /// The plant FMU (.fmu file or unpacked folder).
    #[arg(long, default_value = "dist/FlexureStage.fmu")]
    fmu: PathBuf,
    /// A parameter set { "<FMI name>": value } set before initialization.
    #[arg(long, value_name = "FILE.json")]
    parameters: Option<PathBuf>,
    /// Prints {fmu, wall_s, fingerprints, checks} as JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Also writes report.md and fingerprints.json into this folder.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Where the Ziegler-Nichols test's loop runs: on the stage moving at
    /// seed 000's Fig. 7 speed (the default preset is calibrated so), or at
    /// a held point (the 3dof_memory and 3dof_no_memory presets are).
    #[arg(long, value_enum, default_value = "while-moving")]
    ziegler_nichols: Reading,
}

/// [`ZieglerNicholsReading`] as the command line names it.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Reading {
    WhileMoving,
    Held,
}

impl From<Reading> for ZieglerNicholsReading {
    fn from(reading: Reading) -> Self {
        match reading {
            Reading::WhileMoving => ZieglerNicholsReading::WhileMoving,
            Reading::Held => ZieglerNicholsReading::Held,
        }
    }
}

/// `value` to six decimals, without trailing zeros (0.111111, 12.74, 790).
fn significant(value: f64) -> String {
    let text = format!("{value:.6}");
    text.trim_end_matches('0').trim_end_matches('.').to_owned()
}

fn table(args: &Args, fingerprints: &Fingerprints, checks: &[Check]) -> String {
    let c = &fingerprints.couplings;
    let mut lines = vec![
        "# FlexureStage calibration fingerprints".to_owned(),
        String::new(),
        format!(
            "Measured through `{}` by `plant-fingerprints` (procedures and targets: \
             piezo-models/src/fingerprint.rs).",
            args.fmu.display()
        ),
        format!(
            "x home command: {:.6} V; sweep amplitudes: y {:.4} V, x {:.4} V, rotation ±{:.4} V.",
            fingerprints.x_home_command,
            c.y_sweep_amplitude,
            c.x_sweep_amplitude,
            c.rotation_sweep_amplitude
        ),
        match fingerprints.ziegler_nichols {
            ZieglerNicholsReading::WhileMoving => {
                "Ziegler-Nichols figures read on the stage moving at 25 V/s \
                 (`--ziegler-nichols while-moving`)."
            }
            ZieglerNicholsReading::Held => {
                "Ziegler-Nichols figures read at a held point (`--ziegler-nichols held`)."
            }
        }
        .to_owned(),
        String::new(),
        "| figure | seed 000 | simulated | error | tolerance | within | where |".to_owned(),
        "|---|---|---|---|---|---|---|".to_owned(),
    ];
    for check in checks {
        let unit = |value: String| match check.unit {
            "" => value,
            unit => format!("{value} {unit}"),
        };
        let paper = check
            .paper
            .map_or_else(|| check.rule.clone(), |p| unit(significant(p)));
        let (error, tolerance) = match check.relative_error {
            Some(e) => (format!("{:+.1} %", 100.0 * e), check.rule.clone()),
            None => (String::new(), String::new()),
        };
        lines.push(format!(
            "| {} | {paper} | {} | {error} | {tolerance} | {} | {} |",
            check.name,
            unit(format!("{:.5}", check.measured)),
            if check.within { "yes" } else { "NO" },
            check.source
        ));
    }
    lines.push(String::new());
    lines.join("\n")
}

fn main() -> ExitCode {
    let args = Args::parse();
    let started = Instant::now();
    let plant = PlantFmu::open(&args.fmu).map_err(|e| e.to_string());
    let plant = plant.and_then(|plant| match &args.parameters {
        None => Ok(plant),
        Some(path) => {
            let set = read_parameter_set(path)?;
            plant.with_parameters(&set).map_err(|e| e.to_string())
        }
    });
    let fingerprints = match plant
        .and_then(|plant| measure(&plant, args.ziegler_nichols.into()).map_err(|e| e.to_string()))
    {
        Ok(f) => f,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let checks = fingerprints.checks();
    let document = json!({
        "fmu": args.fmu.display().to_string(),
        "wall_s": started.elapsed().as_secs_f64(),
        "fingerprints": fingerprints,
        "checks": checks,
    });
    let report = table(&args, &fingerprints, &checks);
    if let Some(out) = &args.out {
        let written = std::fs::create_dir_all(out)
            .and_then(|()| result_files::write_bytes(&out.join("report.md"), report.as_bytes()))
            .and_then(|()| {
                result_files::write_bytes(
                    &out.join("fingerprints.json"),
                    (document.to_string() + "\n").as_bytes(),
                )
            });
        if let Err(e) = written {
            eprintln!("{}: {e}", out.display());
            return ExitCode::from(2);
        }
    }
    if args.json {
        println!("{document}");
    } else {
        print!("{report}");
    }
    if checks.iter().all(|c| c.within) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}
