//! The plant's calibration fingerprints measured through its FMU: the
//! procedures and targets of [`piezo_models::fingerprint`] (written once
//! there), driving a [`PlantFmu`] instead of the model, as any importer
//! would drive the packaged stage. `plant-fingerprints` runs them; the
//! Python tests call it.
//!
//! A step the FMU refuses is kept as the first error and ends the
//! measurement's use of that instance (its readings become NaN, every later
//! step is skipped), since the procedures cannot stop midway; [`measure`]
//! returns that error instead of the figures.

use std::cell::RefCell;

use piezo_models::fingerprint::{self, Fingerprints, Stage, StageSource};

use crate::plant::{PlantError, PlantFmu, PlantSession};

/// One instance of the plant FMU as the procedures drive it.
pub struct FmuStage<'a> {
    session: Option<PlantSession<'a>>,
    sensors: [f64; 3],
    failure: &'a RefCell<Option<PlantError>>,
}

impl FmuStage<'_> {
    fn fail(&mut self, error: PlantError) {
        self.session = None;
        self.sensors = [f64::NAN; 3];
        self.failure.borrow_mut().get_or_insert(error);
    }
}

/// A [`FmuStage`] saved: its serialized FMU state and its time.
pub struct FmuSnapshot {
    state: Vec<u8>,
    time: f64,
    sensors: [f64; 3],
}

impl Stage for FmuStage<'_> {
    type Snapshot = Option<FmuSnapshot>;

    fn step(&mut self, commands: [f64; 3], period: f64) {
        let Some(session) = self.session.as_mut() else {
            return;
        };
        match session.step(commands, period) {
            Ok(sensors) => self.sensors = sensors,
            Err(error) => self.fail(error),
        }
    }

    fn sensors(&self) -> [f64; 3] {
        self.sensors
    }

    fn snapshot(&self) -> Option<FmuSnapshot> {
        let session = self.session.as_ref()?;
        match session.snapshot() {
            Ok(state) => Some(FmuSnapshot {
                state,
                time: session.time(),
                sensors: self.sensors,
            }),
            Err(error) => {
                self.failure.borrow_mut().get_or_insert(error);
                None
            }
        }
    }

    fn restore(&mut self, snapshot: &Option<FmuSnapshot>) {
        let (Some(session), Some(snapshot)) = (self.session.as_mut(), snapshot) else {
            return;
        };
        match session.restore(&snapshot.state, snapshot.time) {
            Ok(()) => self.sensors = snapshot.sensors,
            Err(error) => self.fail(error),
        }
    }
}

/// The plant FMU as a source of fresh instances at rest.
pub struct FmuStages<'a> {
    plant: &'a PlantFmu,
    spacing_um: f64,
    failure: &'a RefCell<Option<PlantError>>,
}

impl<'a> StageSource for FmuStages<'a> {
    type Stage = FmuStage<'a>;

    fn fresh(&self) -> FmuStage<'a> {
        let mut stage = FmuStage {
            session: None,
            sensors: [0.0; 3],
            failure: self.failure,
        };
        match self.plant.session() {
            Ok(session) => stage.session = Some(session),
            Err(error) => stage.fail(error),
        }
        stage
    }

    fn sensor_spacing_um(&self) -> f64 {
        self.spacing_um
    }
}

/// Why the fingerprints could not be measured.
#[derive(Debug, thiserror::Error)]
pub enum FingerprintError {
    #[error(transparent)]
    Plant(#[from] PlantError),
    #[error("{0}: the plant has no Real parameter L (sensor spacing [mm]) to read")]
    NoSpacing(String),
}

/// Every fingerprint of `plant`, measured through its FMU, the
/// Ziegler-Nichols figures read as `reading` says.
pub fn measure(
    plant: &PlantFmu,
    reading: fingerprint::ZieglerNicholsReading,
) -> Result<Fingerprints, FingerprintError> {
    let spacing_mm = plant
        .start("L")
        .ok_or_else(|| FingerprintError::NoSpacing(plant.path().display().to_string()))?;
    let failure = RefCell::new(None);
    let stages = FmuStages {
        plant,
        spacing_um: spacing_mm * 1e3,
        failure: &failure,
    };
    let fingerprints = fingerprint::measure_with(&stages, reading);
    match failure.into_inner() {
        Some(error) => Err(error.into()),
        None => Ok(fingerprints),
    }
}
