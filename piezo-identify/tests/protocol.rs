//! The identification protocol's behaviour (README, "Protocol"): the fit
//! never looks at the scored part, the state is carried over into it, rests
//! and steps are found and left out, and Levenberg-Marquardt stays in the
//! box and is kept only when it improves the fit part.

use piezo_identify::Record;
use piezo_identify::bouc_wen_fit::{BoucWenFitOptions, identify_bouc_wen};
use piezo_identify::lab_records::{Drive, Excitation, LabRecordSpec, lab_record};
use piezo_identify::protocol::{
    BoucWenSettings, InversePiSettings, NoZeroAlignment, Plan, PlanOptions,
    identify_bouc_wen_protocol, identify_inverse_pi,
};

/// 200 Hz, unipolar 1 Hz sine after 2 s of rest, 12 s of excitation.
fn record() -> Record {
    lab_record(&LabRecordSpec::new(
        200.0,
        Drive::Unipolar,
        Excitation::Sine { frequency: 1.0 },
        12.0,
    ))
    .unwrap()
}

fn split_plan(record: &Record, fit_end: usize) -> Plan {
    Plan::new(
        &record.input,
        record.sample_period,
        fit_end,
        &PlanOptions::default(),
    )
    .unwrap()
}

/// Whatever the scored part holds, the fit and every choice are the same:
/// the protocol never looks past the split.
#[test]
fn the_fit_part_alone_decides_the_model() {
    let record = record();
    let fit_end = record.input.len() / 2;
    let plan = split_plan(&record, fit_end);
    let mut tampered = record.clone();
    for (n, y) in tampered.output.iter_mut().enumerate().skip(fit_end) {
        *y = 1e3 * ((n as f64) * 0.37).sin();
    }
    for u in tampered.input.iter_mut().skip(fit_end + 5) {
        *u = 9.9;
    }
    let settings = InversePiSettings {
        starts: 6,
        ..InversePiSettings::default()
    };
    let a = identify_inverse_pi(&record, &plan, &settings, &|_| {}).unwrap();
    let b = identify_inverse_pi(
        &tampered,
        &split_plan(&tampered, fit_end),
        &settings,
        &|_| {},
    )
    .unwrap();
    assert_eq!(a.params, b.params);
    assert_eq!(a.cross_validation, b.cross_validation);
    assert_eq!(
        (a.smoothing, a.rate_dependent),
        (b.smoothing, b.rate_dependent)
    );
    assert_eq!(a.fit_errors, b.fit_errors);
    assert_ne!(a.unseen, b.unseen, "the scored part is scored");
}

/// A record split mid-cycle is scored with the state the fit part left,
/// which beats starting the model from rest at the split: the error of
/// that wrong start shows in the first cycle after it (until the input has
/// turned at both ends, the model's state is still the assumed one).
#[test]
fn the_scored_part_is_predicted_with_the_state_carried_over() {
    let record = record();
    // On the falling branch at the sine's mean: rest (400 samples), five
    // cycles (1000), half a cycle (100).
    let fit_end = 400 + 5 * 200 + 100;
    let plan = split_plan(&record, fit_end);
    let settings = BoucWenSettings {
        gapso: piezo_identify::gapso::GaPsoOptions {
            generations: 40,
            ..Default::default()
        },
        ..BoucWenSettings::default()
    };
    let fit = identify_bouc_wen_protocol(&record, &plan, &settings, &|_| {}).unwrap();
    // The first cycle after the split, with the state carried over ...
    let mut first_cycle = vec![false; record.input.len()];
    for flag in &mut first_cycle[fit_end..fit_end + 200] {
        *flag = true;
    }
    let carried = fit
        .errors_on(
            &record.input,
            &record.output,
            record.sample_period,
            &first_cycle,
        )
        .bouc_wen;
    // ... and with the model started from rest at the split.
    let from_rest = fit
        .errors_on(
            &record.input[fit_end..],
            &record.output[fit_end..],
            record.sample_period,
            &first_cycle[fit_end..],
        )
        .bouc_wen;
    println!(
        "first cycle after the split: state carried over {:.4} um RMS, model from rest at the split {:.4} um",
        carried.rms, from_rest.rms
    );
    assert_eq!(carried.samples, 200);
    assert!(carried.rms < 0.5 * from_rest.rms);
    // The protocol's own score is the carried one over the whole scored part.
    let unseen = fit.unseen.unwrap().bouc_wen;
    assert_eq!(unseen.samples, record.input.len() - fit_end);
}

/// The rest at 0 V and the step onto the sine are found, left out of the
/// fit with the first loading after the step, and the fit holds the rest.
#[test]
fn rest_and_step_are_found_and_left_out() {
    let record = record();
    let plan = split_plan(&record, 1600);
    assert_eq!(plan.segments.rests, vec![0..400]);
    assert_eq!(plan.segments.steps, vec![400]);
    // Settling to 420, then the first loading: the sine's first maximum
    // (sample 450) and minimum (550).
    assert_eq!(plan.fit_excluded, vec![0..550]);
    assert_eq!(plan.fitted().iter().filter(|f| **f).count(), 1050);
    assert_eq!(plan.scored().iter().filter(|f| **f).count(), 1200);
    // Without detection only the start is left out.
    let kept = Plan::new(
        &record.input,
        record.sample_period,
        1600,
        &PlanOptions {
            detect_segments: false,
            ..PlanOptions::default()
        },
    )
    .unwrap();
    assert!(kept.segments.steps.is_empty() && kept.segments.rests.is_empty());
}

/// A record of a Bouc-Wen model whose n (3.5) lies beyond the default box
/// (n ≤ 3): GA-PSO ends at the wall, and the refinement may not leave it.
/// The refinement is kept only when it lowers the fitted RMS.
#[test]
fn refinement_stays_in_the_box_and_must_improve_the_fit() {
    let truth = piezo_models::BoucWenParams {
        p: 0.1,
        q: -0.8,
        a: 0.03,
        beta: 0.01,
        gamma: 0.004,
        n: 3.5,
        delta: 0.0002,
    };
    let u: Vec<f64> = (0..2000)
        .map(|n| 50.0 * (1.0 - (std::f64::consts::TAU * n as f64 / 400.0).cos()))
        .collect();
    let y = piezo_models::simulate(truth, &u);
    for within in [false, true] {
        let options = BoucWenFitOptions {
            gapso: piezo_identify::gapso::GaPsoOptions {
                generations: 40,
                ..Default::default()
            },
            refine_within_bounds: within,
            ..BoucWenFitOptions::default()
        };
        let fit = identify_bouc_wen(&u, &y, &options, |_, _| {}).unwrap();
        let refined = fit.refined.as_ref().unwrap();
        println!(
            "within bounds {within}: GA-PSO n {:.4} RMS {:.3e}; refined n {:.4} RMS {:.3e}, kept {}",
            fit.gapso.params.n, fit.gapso.rms, refined.params.n, refined.rms, fit.refinement_kept
        );
        if fit.refinement_kept {
            assert!(refined.rms < fit.gapso.rms);
        } else {
            assert_eq!(refined, &fit.gapso);
        }
        if within {
            assert!(fit.best().params.n <= 3.0, "n {}", fit.best().params.n);
        }
    }
}

/// A second session of the same experiment with its sensor zeroed elsewhere
/// (offset −40 µm instead of −42.7 µm, other noise): both records begin at
/// rest at 0 V, the second's rest reads 2.7 µm higher, and read from the fit
/// record's zero it is its twin with the fit record's zero. A file that does
/// not begin at rest, or rests at another input, has no zero to compare.
#[test]
fn a_validation_file_is_read_from_the_fit_records_zero_by_their_rests() {
    let spec = LabRecordSpec::new(
        200.0,
        Drive::Unipolar,
        Excitation::Sine { frequency: 1.0 },
        12.0,
    );
    let fit = lab_record(&spec).unwrap();
    let session = |sensor_offset_um| {
        lab_record(&LabRecordSpec {
            sensor_offset_um,
            noise_seed: 9,
            ..spec
        })
        .unwrap()
    };
    let (moved, twin) = (session(-40.0), session(-42.7));
    let plan = split_plan(&fit, fit.input.len());
    let alignment = plan
        .zero_alignment(&fit, &moved)
        .expect("both begin at rest at 0 V");
    assert_eq!(alignment.rest_input, 0.0);
    // 2 s of rest at 200 Hz less the 0.1 s settling: means of 380 samples of
    // 0.02 µm noise, each within about 0.001 µm; 0.005 µm is 3σ of their
    // difference and more.
    assert_eq!(alignment.fit_rest, 20..400);
    assert!((alignment.shift - 2.7).abs() < 0.005, "{alignment:?}");
    let aligned = alignment.aligned(&moved.output);
    let largest = aligned
        .iter()
        .zip(&twin.output)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(largest < 0.005, "{largest}");

    // Begun mid-excitation: no rest at its start.
    let late = Record {
        input: moved.input[600..].to_vec(),
        output: moved.output[600..].to_vec(),
        sample_period: moved.sample_period,
    };
    assert_eq!(
        plan.zero_alignment(&fit, &late),
        Err(NoZeroAlignment::NotAtRest {
            record: "validation file"
        })
    );
    // Resting at 1 V, not 0 V.
    let mut lifted = moved.clone();
    for u in &mut lifted.input[..400] {
        *u = 1.0;
    }
    assert!(matches!(
        plan.zero_alignment(&fit, &lifted),
        Err(NoZeroAlignment::DifferentInputs { fit, validation }) if fit == 0.0 && validation == 1.0
    ));
    // Rests are found for the zero whether or not they are left out of the
    // fit (--keep-rest-and-steps), and the settling time is in seconds of
    // each file's own sampling: the same session taken at 1 kHz.
    let kept = Plan::new(
        &fit.input,
        fit.sample_period,
        fit.input.len(),
        &PlanOptions {
            detect_segments: false,
            ..PlanOptions::default()
        },
    )
    .unwrap();
    let fast = lab_record(&LabRecordSpec {
        sample_rate: 1000.0,
        sensor_offset_um: -40.0,
        ..spec
    })
    .unwrap();
    let alignment = kept.zero_alignment(&fit, &fast).unwrap();
    assert_eq!(alignment.fit_rest, 20..400);
    assert_eq!(alignment.validation_rest, 100..2000);
    assert!((alignment.shift - 2.7).abs() < 0.005, "{alignment:?}");
    // A rest shorter than the settling time leaves nothing to read.
    let settle_longer = Plan::new(
        &fit.input,
        fit.sample_period,
        fit.input.len(),
        &PlanOptions {
            segments: piezo_identify::segments::SegmentOptions {
                settle_seconds: 2.5,
                ..Default::default()
            },
            ..PlanOptions::default()
        },
    )
    .unwrap();
    assert!(matches!(
        settle_longer.zero_alignment(&fit, &moved),
        Err(NoZeroAlignment::RestWithinSettling {
            record: "fit record",
            ..
        })
    ));
}
