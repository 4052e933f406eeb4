//! The master on the workspace's two FMUs, laid out as unpacked FMU folders
//! from the release cdylibs and the committed modelDescriptions (so that
//! `cargo test` needs no `make fmus`): the closed loop tracks, a check
//! stops before the first step, a scenario that does not fit the FMUs is
//! refused by name, runs that share their opened FMUs (a batch) equal runs
//! that open their own, and the step loop allocates nothing.

use counting_allocator::{CountingAllocator, allocations_of};
use std::path::{Path, PathBuf};

use piezo_cosim::scenario::ParameterValue;
use piezo_cosim::trajectory::{TableSource, Trajectory};
use piezo_cosim::{OpenFmus, RunError, RunOptions, Scenario, run, run_with};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("piezo-cosim lives in the workspace")
        .to_owned()
}

/// An unpacked FMU folder: modelDescription.xml and binaries/<platform>/.
fn fmu_folder(into: &Path, package: &str, identifier: &str) -> PathBuf {
    let library = fmi2_import::cdylib_path(package);
    let folder = into.join(identifier);
    let binaries = folder
        .join("binaries")
        .join(fmi2_import::archive::platform_folder());
    std::fs::create_dir_all(&binaries).unwrap();
    std::fs::copy(
        root()
            .join("modelDescription")
            .join(format!("{identifier}.xml")),
        folder.join("modelDescription.xml"),
    )
    .unwrap();
    std::fs::copy(
        &library,
        binaries.join(format!("{identifier}{}", std::env::consts::DLL_SUFFIX)),
    )
    .unwrap();
    folder
}

struct Fmus {
    _dir: tempfile::TempDir,
    plant: PathBuf,
    controller: PathBuf,
}

fn fmus() -> Fmus {
    let dir = tempfile::tempdir().unwrap();
    let plant = fmu_folder(dir.path(), "fmu-plant", "FlexureStage");
    let controller = fmu_folder(dir.path(), "fmu-controller", "PiezoController");
    Fmus {
        _dir: dir,
        plant,
        controller,
    }
}

/// Seed 000's Fig. 7a conditions: a 1 Hz y sine of 5 um about y = 7 um,
/// x held at 8 um, PI on y, after an approach from rest.
fn y_sine(fmus: &Fmus, duration: f64, extra: &str) -> Scenario {
    let text = format!(
        r#"
duration = {duration}
[fmu.plant]
path = "{plant}"
parameters = {{ "noise.enabled" = true, "noise.seed" = 2024 }}
[fmu.controller]
path = "{controller}"
parameters = {{ feedback_x = false, feedback_theta = false, decoupling = false }}
[signal."controller.y_ref"]
offset = 7.0
start = 1.0
approach = 0.5
sines = [{{ amplitude = 5.0, frequency = 1.0, phase = -1.5707963267948966 }}]
[signal."controller.x_ref"]
offset = 8.0
start = 1.0
approach = 0.5
[metrics]
driven = "y"
from = {from}
{extra}
"#,
        from = if duration > 2.0 { 2.0 } else { duration / 2.0 },
        plant = fmus.plant.display(),
        controller = fmus.controller.display(),
    );
    Scenario::parse(&text, false, "y_sine.toml").unwrap()
}

#[test]
fn the_closed_loop_tracks_a_y_sine() {
    let fmus = fmus();
    let output = run(&y_sine(&fmus, 3.0, ""), RunOptions::default()).unwrap();
    assert_eq!(output.steps, 30_000);
    let m = output.metrics.unwrap();
    let rms = m["tracking_rms"].as_f64().unwrap();
    // demo's test_closed_loop: measured 0.0189 um (noise 0.01 um RMS alone).
    assert!(rms > 0.005 && rms < 0.03, "tracking RMS {rms} um");
    assert!((m["demand_span"].as_f64().unwrap() - 10.0).abs() < 1e-6);
    // Without decoupling, y drags the x sensors (Table 3: ~2 um spans).
    assert!(m["coupling_x2_span"].as_f64().unwrap() > 0.5);
    assert_eq!(m["samples"], 10_001);
}

/// A batch opens each FMU once and instantiates it per run: every run's
/// metrics equal, bit for bit, those of a run that opened the FMUs itself,
/// whatever ran before it in the process (another noise seed, a run that
/// an FMU refused, the same scenario again).
#[test]
fn runs_that_share_their_fmus_equal_runs_that_open_their_own() {
    let fmus = fmus();
    let first = y_sine(&fmus, 0.5, "");
    let mut other_seed = first.clone();
    other_seed
        .fmu
        .get_mut("plant")
        .unwrap()
        .parameters
        .insert("noise.seed".to_owned(), ParameterValue::Number(7.0));
    let mut refused = first.clone();
    refused.fmu.get_mut("plant").unwrap().parameters.insert(
        "mode.theta.damping".to_owned(),
        ParameterValue::Number(-1.0),
    );
    let alone = |scenario: &Scenario| run(scenario, RunOptions::default()).unwrap().metrics;
    let mut open = OpenFmus::default();
    let mut shared = |scenario: &Scenario| run_with(scenario, RunOptions::default(), &mut open);
    let a = shared(&first).unwrap().metrics;
    let b = shared(&other_seed).unwrap().metrics;
    assert!(matches!(shared(&refused), Err(RunError::Scenario(_))));
    let a_again = shared(&first).unwrap().metrics;
    assert_eq!(open.len(), 2, "each FMU opened once");
    assert_eq!(a, alone(&first));
    assert_eq!(b, alone(&other_seed));
    assert_ne!(a, b, "the seed moves the noise");
    assert_eq!(a_again, a);
}

/// An FMU that declares `canBeInstantiatedOnlyOncePerProcess` is refused,
/// by name and with what to do, by the second run of a process, and runs in
/// a process of its own.
#[test]
fn an_fmu_instantiable_once_per_process_is_not_shared_by_runs() {
    let fmus = fmus();
    let description = fmus.plant.join("modelDescription.xml");
    let text = std::fs::read_to_string(&description).unwrap();
    let once = text.replace(
        "canBeInstantiatedOnlyOncePerProcess=\"false\"",
        "canBeInstantiatedOnlyOncePerProcess=\"true\"",
    );
    assert_ne!(once, text);
    std::fs::write(&description, once).unwrap();
    let scenario = y_sine(&fmus, 0.05, "");
    let mut open = OpenFmus::default();
    // A run refused before it instantiates anything does not count.
    let mut unfit = scenario.clone();
    unfit
        .fmu
        .get_mut("plant")
        .unwrap()
        .parameters
        .insert("pzt[4].A".to_owned(), ParameterValue::Number(1.0));
    assert!(matches!(
        run_with(&unfit, RunOptions::default(), &mut open),
        Err(RunError::Scenario(_))
    ));
    run_with(&scenario, RunOptions::default(), &mut open).unwrap();
    let Err(RunError::Scenario(message)) = run_with(&scenario, RunOptions::default(), &mut open)
    else {
        panic!("a second instance in one process was not refused");
    };
    assert!(
        message.contains("only once per process") && message.contains("runs_per_task = 1"),
        "{message}"
    );
    run(&scenario, RunOptions::default()).unwrap();
}

#[test]
fn series_hold_every_output_and_signal() {
    let fmus = fmus();
    let options = RunOptions {
        series: true,
        check_only: false,
    };
    let output = run(&y_sine(&fmus, 0.01, ""), options).unwrap();
    let series = output.series.unwrap();
    assert_eq!(series.t.len(), 101);
    for name in [
        "controller.y_ref",
        "controller.x_ref",
        "plant.s1",
        "plant.theta_z",
        "controller.u1",
        "controller.e_y",
    ] {
        assert_eq!(series.column(name).map(<[f64]>::len), Some(101), "{name}");
    }
    // Jacobi with one sample of compute delay: the plant's first command
    // reaches it one step after the controller computed it.
    let u1 = series.column("controller.u1").unwrap();
    assert_eq!(u1[0], 0.0);
}

#[test]
fn a_check_initializes_without_a_step() {
    let fmus = fmus();
    let options = RunOptions {
        series: false,
        check_only: true,
    };
    let output = run(&y_sine(&fmus, 3.0, ""), options).unwrap();
    assert_eq!(output.steps, 0);
    assert!(output.metrics.is_none());
    assert!(output.warnings.is_empty(), "{:?}", output.warnings);
    // A duration between two whole steps is said, with the steps taken.
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.step = 3e-3;
    let output = run(&scenario, options).unwrap();
    assert_eq!(
        output.warnings,
        [
            "duration 0.01 s is not a whole number of steps of 0.003 s: the run takes 3 steps, 0.009 s"
        ]
    ); // A table that ends before the run holds its last value, and says so
    // (a table cut short, or in ms read as s, ran silently).
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("y.csv");
    std::fs::write(&table, "t,y\n0,7\n1,8\n").unwrap();
    let mut scenario = y_sine(&fmus, 3.0, "");
    scenario.signal.insert(
        "controller.y_ref".into(),
        Trajectory {
            table: Some(TableSource {
                file: table,
                column: "y".into(),
                time: "t".into(),
            }),
            start: 1.0,
            ..Trajectory::default()
        },
    );
    let output = run(&scenario, options).unwrap();
    assert_eq!(
        output.warnings,
        [
            "signal controller.y_ref: its table ends at 2 s, before the run's end at 3 s; its last value is held from there"
        ]
    );
    // One that starts after its signal does holds its first value before,
    // and says so too (it ran silently).
    std::fs::write(dir.path().join("y.csv"), "t,y\n0.5,7\n3,8\n").unwrap();
    let output = run(&scenario, options).unwrap();
    assert_eq!(
        output.warnings,
        [
            "signal controller.y_ref: its table starts at 1.5 s, after its signal starts at 1 s; its first value is held until then"
        ]
    );
}

#[test]
fn a_scenario_that_does_not_fit_is_refused_by_name() {
    let fmus = fmus();
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.signal.insert(
        "controller.z_ref".into(),
        piezo_cosim::trajectory::Trajectory::constant(1.0),
    );
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    assert!(
        matches!(&error, RunError::Scenario(m) if m.contains("controller.z_ref") && m.contains("no variable")),
        "{error}"
    );

    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.connection = Some(vec![piezo_cosim::scenario::Connection {
        from: "plant.s1".into(),
        to: "controller.y_ref".into(),
    }]);
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    assert!(error.to_string().contains("driven twice"), "{error}");

    // The plant and the controller given the other way round: the default
    // wiring, written nowhere, is named by the FMU whose variable it is.
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.signal.clear();
    scenario.metrics = None;
    let plant = scenario.fmu.remove("plant").unwrap();
    let controller = scenario.fmu.remove("controller").unwrap();
    scenario.fmu.insert("plant".into(), controller);
    scenario.fmu.insert("controller".into(), plant);
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    assert_eq!(
        error.to_string(),
        format!(
            "connection source controller.u1 is not an output (in {} its causality is input)",
            fmus.plant.display()
        )
    );

    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario
        .fmu
        .get_mut("controller")
        .unwrap()
        .parameters
        .insert(
            "hysteresis_model".into(),
            piezo_cosim::scenario::ParameterValue::Number(1.5),
        );
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    assert!(
        error.to_string().contains(
            "controller.hysteresis_model is an Integer variable, which takes a whole number; \
             1.5 was given"
        ),
        "{error}"
    );
    // A value from a parameter set names the set.
    let set = std::env::temp_dir().join(format!("cosim-set-{}.json", std::process::id()));
    std::fs::write(&set, r#"{"x.cc": 1.0}"#).unwrap();
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario
        .fmu
        .get_mut("controller")
        .unwrap()
        .parameter_sets
        .push(set.clone());
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    std::fs::remove_file(&set).ok();
    assert!(
        error.to_string().contains(&format!(
            "controller.x.cc: {} has no variable \"x.cc\" (did you mean \"x.c\"?) (given in {})",
            fmus.controller.display(),
            set.display()
        )),
        "{error}"
    );
    // So does a value from a set that the FMU refuses, as the scenario's.
    std::fs::write(&set, r#"{"translation.kp": -0.05}"#).unwrap();
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    std::fs::remove_file(&set).ok();
    assert!(
        matches!(&error, RunError::Scenario(m)
            if m.contains("translation.kp = -0.05 is outside its allowed range")
                && m.ends_with(&format!("(given in {})", set.display()))),
        "{error}"
    );
}

/// A misspelt name in `record` is refused by `check` and by a run without a
/// series, as a run with one refuses it: it passed both and was ignored by
/// sweeps.
#[test]
fn a_recorded_name_is_checked_with_or_without_a_series() {
    let fmus = fmus();
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.record = vec!["plant.pzt[1].A".into(), "controller.kpp".into()];
    for options in [
        RunOptions {
            check_only: true,
            ..RunOptions::default()
        },
        RunOptions::default(),
        RunOptions {
            series: true,
            ..RunOptions::default()
        },
    ] {
        let error = run(&scenario, options).unwrap_err();
        assert!(
            matches!(&error, RunError::Scenario(m)
                if m.starts_with("controller.kpp: ") && m.contains("has no variable \"kpp\"")),
            "{error}"
        );
    }
    scenario.record.pop();
    assert!(run(&scenario, RunOptions::default()).is_ok());
}

/// A parameter value the FMU refuses ends the run with the FMU's log, as
/// the scenario's problem (exit 2), not an FMU's failure while running.
#[test]
fn a_refused_value_ends_the_run_with_the_fmus_log() {
    let fmus = fmus();
    let mut scenario = y_sine(&fmus, 0.01, "");
    scenario.fmu.get_mut("plant").unwrap().parameters.insert(
        "mode.theta.frequency".into(),
        piezo_cosim::scenario::ParameterValue::Number(-1.0),
    );
    let error = run(&scenario, RunOptions::default()).unwrap_err();
    let RunError::Scenario(message) = error else {
        panic!("a scenario error expected, got {error}");
    };
    assert!(message.starts_with("plant: fmi2"), "{message}");
    assert!(message.contains("mode.theta.frequency"), "{message}");
}

#[test]
fn the_step_loop_allocates_nothing() {
    let fmus = fmus();
    let short = y_sine(&fmus, 0.2, "");
    let long = y_sine(&fmus, 0.6, "");
    run(&short, RunOptions::default()).unwrap();
    let a = allocations_of(|| {
        run(&short, RunOptions::default()).unwrap();
    });
    let b = allocations_of(|| {
        run(&long, RunOptions::default()).unwrap();
    });
    // Loading, wiring and metrics allocate a fixed number of times; 4000
    // more steps add none.
    assert_eq!(a, b, "allocations: {a} for 2000 steps, {b} for 6000");
}
