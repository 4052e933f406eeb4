//! The subcommands of `piezo-identify` and what they share; the library does
//! the math, these modules parse, load, print and write.

/// `println!` that goes on when nobody reads the standard output any more
/// (`piezo-identify … | head -1`): the summary is for a reader, the files a
/// command writes after it are the work, and `println!` would panic there
/// (exit 101, nothing written).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

pub(crate) mod arguments;
pub(crate) mod bouc_wen;
pub(crate) mod compare;
pub(crate) mod inverse_pi;
pub(crate) mod progress;
pub(crate) mod records;
pub(crate) mod report;
pub(crate) mod stage;

use piezo_identify::FitError;
use piezo_identify::plant::PlantError;
use piezo_identify::protocol::ProtocolError;
use piezo_identify::stage::StageError;

/// Why a subcommand stopped short; `main` turns it into the exit status, so
/// that a script can tell a mistake in what it passed from a failure of the
/// work (the same split as `piezo-cosim`'s 2 and 1).
#[derive(Debug)]
pub(crate) enum Failure {
    /// What was given does not fit: a record that cannot be read, an option
    /// the data cannot take, an FMU or parameter set that is not the plant's,
    /// an output path with no folder to write in. Exit 2, as for an argument
    /// the parser refuses; nothing was computed or written.
    Input(String),
    /// The work failed on what was given: an FMU refused a call or failed a
    /// step, a closed-loop run did not track, an optimizer gave up, a result
    /// could not be written. Exit 1.
    Run(String),
}

impl Failure {
    /// The process exit status that says which kind of failure it was.
    pub(crate) fn exit_status(&self) -> u8 {
        match self {
            Failure::Input(_) => 2,
            Failure::Run(_) => 1,
        }
    }

    pub(crate) fn message(&self) -> &str {
        match self {
            Failure::Input(message) | Failure::Run(message) => message,
        }
    }
}

/// Most of what a subcommand refuses is its input, and those checks return
/// plain messages; the places where the work itself fails say `Run`.
impl From<String> for Failure {
    fn from(message: String) -> Self {
        Failure::Input(message)
    }
}

/// A plant FMU's problem: one that is not a plant of FlexureStage's
/// interface, or that refuses the parameter set or its start (set-up,
/// parameters, initialization), is what was given; a call that fails once
/// it runs (an input, a step, a state) is the run's.
pub(crate) fn plant_failure(error: PlantError) -> Failure {
    match error {
        PlantError::Archive { .. } | PlantError::Interface { .. } | PlantError::Start { .. } => {
            Failure::Input(error.to_string())
        }
        PlantError::Call { .. } => Failure::Run(error.to_string()),
    }
}

/// A fit on a record, named by the record: an optimizer that gave up is the
/// run's failure; everything else (too few samples, nothing left to fit or
/// score, no excitation) says what the record or the options lack.
pub(crate) fn protocol_failure(record: &str, error: ProtocolError) -> Failure {
    let message = format!("{record}: {error}");
    match error {
        ProtocolError::Fit(FitError::Optimizer(_)) => Failure::Run(message),
        _ => Failure::Input(message),
    }
}

/// The stage identification of a plant FMU: the FMU's own problems as
/// [`plant_failure`] sorts them; a plant without the sensor spacing is not
/// FlexureStage's interface; a loop that does not track, and a fit that fails
/// on the records the runs made, are the run's.
pub(crate) fn stage_failure(plant: &std::path::Path, error: StageError) -> Failure {
    match error {
        StageError::Plant(e) => plant_failure(e),
        StageError::NoSpacing(_) => Failure::Input(format!("{}: {error}", plant.display())),
        _ => Failure::Run(format!("{}: {error}", plant.display())),
    }
}
