//! `piezo-identify`: fits the hysteresis models of both papers to
//! voltage/displacement records and to plant FMUs, scores them on unseen data,
//! and writes the presets the FMUs start from. This file is the command line
//! (the subcommands and their dispatch); each subcommand's arguments, run and
//! printing live in `commands/` by concern. All I/O lives in the binary; the
//! library does the math.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
use commands::bouc_wen::{BoucWenArgs, bouc_wen};
use commands::compare::{CompareArgs, compare};
use commands::inverse_pi::{InversePiArgs, inverse_pi};
use commands::records::{LabRecordArgs, Xy200sPresetArgs, write_lab_record, xy200s_preset};
use commands::stage::{DecouplingArgs, StageArgs, decoupling, stage};

#[derive(Parser)]
#[command(
    name = "piezo-identify",
    version,
    about = "Identify piezo hysteresis models (seed 000's modified inverse Prandtl-Ishlinskii, seed 001's asymmetric Bouc-Wen) from voltage/displacement records",
    after_help = "Exit status: 0 done; 2 what was given does not fit (arguments, a record's file, line and problem, an FMU or parameter set, an output path), refused before any fit; 1 the work failed on sound input (an FMU call while running, a closed loop that does not track, an optimizer, writing a result)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit the proposed modified inverse P-I model (seed 000 eq. 3-5) to a
    /// record, with the classical P-I model and a straight line as
    /// baselines; score all three on the rest of the record (--split,
    /// --validate-from) or on a second file (--validate).
    InversePi(InversePiArgs),
    /// Seed 000's model comparison: F (eq. 7) and evaluation time of the
    /// proposed model and the traditional 10+6 and 10+10 models.
    Compare(CompareArgs),
    /// Seed 000's whole identification on a plant FMU: eq. (6) records and
    /// inverse-model fits of x and y, then single-axis closed-loop runs and
    /// the decoupling compensations (Table 2). Writes a controller preset
    /// (piezo_models::ControllerParams) that PiezoController's start values
    /// come from.
    Stage(StageArgs),
    /// Fit one decoupling compensation D(f) = clamp(dk*f + db, q, p) (seed 000
    /// eq. 11, Table 2) to a record of (driving demand, coupling error).
    Decoupling(DecouplingArgs),
    /// Fit seed 001's asymmetric Bouc-Wen model (eq. 3-4) by GA-PSO on the
    /// RMS of eq. (5), then refine it by Levenberg-Marquardt inside the
    /// search box; from a record (voltage, displacement) or from a plant FMU
    /// driven by seed 001 §5.2's sine, with the classical P-I model and
    /// straight lines as baselines. Also fits the coupling models H_XY,
    /// H_YX: give the coupled displacement as the output (or --read coupled).
    BoucWen(BoucWenArgs),
    /// Build seed 001's XY200S stage as a FlexureStage parameter set from
    /// the printed Tables 1-2 (units and conversion: piezo_identify::xy200s).
    Xy200sPreset(Xy200sPresetArgs),
    /// Write a record taken from the simulated stage (FlexureStage, y
    /// actuator) the way a lab takes one: rest at 0 V, a step onto a sine
    /// or a staircase, a sensor offset and noise; columns time [s], command [V],
    /// displacement [um].
    LabRecord(LabRecordArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::InversePi(args) => inverse_pi(args),
        Command::Compare(args) => compare(args),
        Command::Stage(args) => stage(args),
        Command::Decoupling(args) => decoupling(args),
        Command::BoucWen(args) => bouc_wen(args),
        Command::Xy200sPreset(args) => xy200s_preset(args),
        Command::LabRecord(args) => write_lab_record(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            eprintln!("{}", failure.message());
            ExitCode::from(failure.exit_status())
        }
    }
}
