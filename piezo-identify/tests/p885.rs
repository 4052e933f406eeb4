//! (d) Real data: the PI P-885.91 stack (shared/data/piezo-p885). The
//! proposed model is fitted on `Model_Vi_Do.dat` and evaluated on
//! `Test_Vi_Do_Di.dat`, which the fit never sees; likewise the classical P-I
//! model. The proposed model must predict the unseen file's voltage better.
//!
//! Protocol (README, "P-885"), the same as
//! `piezo-identify inverse-pi Model_Vi_Do.dat --input 0 --output 4 --rate 200
//!  --validate Test_Vi_Do_Di.dat --warm-up 0.1 --smooth 2 --rate-independent
//!  --decimation 2`:
//! - displacement: centred 5-sample moving average (sensor noise, see
//!   `validation::centred_moving_average`), then one offset, the smallest
//!   smoothed displacement of the identification file after its first 0.1 s,
//!   subtracted from both files;
//! - the first 0.1 s (20 samples) of each file run the models from the
//!   de-energized state but are not fitted nor scored: both files start with
//!   a step from 0 V to about 1.8 V that the sensor reads as a 50 ms
//!   transient 3-4 µm below anything later, which no hysteresis model
//!   describes;
//! - constant backlash weights (k = 0): the identification file is a single
//!   1 Hz sine of one amplitude, so ẏ is a function of y and direction and
//!   the rate slopes k of eq. (4) are not identifiable from it (README gives
//!   the rate-dependent figures too);
//! - the search on every 2nd sample (100 Hz), 30 starts, seed 0; the linear
//!   part and all errors on every sample.

use std::path::Path;

use piezo_identify::fit::score;
use piezo_identify::validation::{
    ErrorReport, ScaleReference, centred_moving_average, displacement_offset, shifted,
};
use piezo_identify::{
    ClassicalPi, Column, FitOptions, FitQuality, ReadOptions, Record, Sampling, fit_classical_pi,
    fit_modified_inverse_pi, read_record,
};
use piezo_models::ModifiedInversePi;

/// A copy of ../shared/data/piezo-p885 (MIT, LICENSE beside it), so that a
/// fresh clone tests on it without the workplace folder.
const DATA: &str = "tests/data/piezo-p885";
const WARM_UP: usize = 20;
const SMOOTHING_HALF_WIDTH: usize = 2;

fn print(name: &str, quality: &FitQuality, reference: &ScaleReference) {
    let e = ErrorReport::new(quality, reference);
    println!(
        "  {name:<28} RMS {:.4} V ({:.2} % of span, {:.3} um), max {:.4} V ({:.2} %, {:.3} um)",
        e.rms_volts,
        e.rms_percent,
        e.rms_displacement_um,
        e.max_volts,
        e.max_percent,
        e.max_displacement_um
    );
}

/// The identification and the unseen test record: input column 0 [V],
/// displacement column 4 [µm], 200 Hz.
fn p885_records() -> (Record, Record) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(DATA);
    let columns = ReadOptions {
        input: Column::Index(0),
        output: Column::Index(4),
        sampling: Sampling::Rate(200.0),
    };
    (
        read_record(&dir.join("Model_Vi_Do.dat"), &columns).unwrap(),
        read_record(&dir.join("Test_Vi_Do_Di.dat"), &columns).unwrap(),
    )
}

#[test]
fn proposed_model_predicts_the_unseen_p885_file_better_than_classical_pi() {
    let (identification, test) = p885_records();
    assert_eq!(identification.input.len(), 8027);
    assert_eq!(test.input.len(), 14155);
    let dt = identification.sample_period;

    let smoothed = centred_moving_average(&identification.output, SMOOTHING_HALF_WIDTH);
    let offset = displacement_offset(&smoothed, WARM_UP);
    // README of the data: a sensor offset of about −96 µm around the middle
    // of a ~45 µm swing, so the bottom lies near −119 µm.
    assert!((-121.0..-117.0).contains(&offset), "offset {offset}");
    let y = shifted(&smoothed, offset);
    let y_test = shifted(
        &centred_moving_average(&test.output, SMOOTHING_HALF_WIDTH),
        offset,
    );
    let u = &identification.input;

    let options = FitOptions {
        decimation: 2,
        warm_up_samples: WARM_UP,
        rate_dependent: false,
        ..FitOptions::default()
    };
    let proposed = fit_modified_inverse_pi(&y, u, dt, &options).unwrap();
    let classical = fit_classical_pi(&y, u, dt, &options).unwrap();
    // The classical model also without smoothing, so that it is judged at its
    // better variant (on this record it is: README).
    let raw_y = shifted(&identification.output, offset);
    let raw_y_test = shifted(&test.output, offset);
    let classical_raw = fit_classical_pi(&raw_y, u, dt, &options).unwrap();

    let proposed_test = score(
        &mut ModifiedInversePi::new(proposed.params),
        &y_test,
        &test.input,
        dt,
        WARM_UP,
    );
    let classical_test = score(
        &mut ClassicalPi::new(classical.params),
        &y_test,
        &test.input,
        dt,
        WARM_UP,
    );
    let classical_raw_test = score(
        &mut ClassicalPi::new(classical_raw.params),
        &raw_y_test,
        &test.input,
        dt,
        WARM_UP,
    );

    let reference = ScaleReference::of(u, &y, WARM_UP);
    println!(
        "offset {offset:.4} um; input span {:.4} V, stroke {:.4} um, mean gain {:.4} um/V; proposed c = {:.5} um, u1max = {:.4} um",
        reference.input_span,
        reference.stroke,
        reference.mean_gain(),
        proposed.params.c,
        proposed.params.u1max
    );
    println!(
        "Model_Vi_Do.dat (identification, {} samples scored):",
        proposed.quality.samples
    );
    print("proposed", &proposed.quality, &reference);
    print("classical", &classical.quality, &reference);
    print("classical (unsmoothed)", &classical_raw.quality, &reference);
    println!(
        "Test_Vi_Do_Di.dat (unseen, {} samples scored):",
        proposed_test.samples
    );
    print("proposed", &proposed_test, &reference);
    print("classical", &classical_test, &reference);
    print("classical (unsmoothed)", &classical_raw_test, &reference);

    // On the identification file the proposed model's freedom shows plainly
    // (measured: 0.0099 against 0.038 V RMS).
    assert!(proposed.quality.rms < 0.5 * classical.quality.rms);
    // On the unseen file: at least 10 % lower RMS than the better classical
    // variant. Across seeds 0-2 and search decimation 1-2 the proposed test
    // RMS stayed within 0.0564-0.0579 V (README), so 10 % is far outside the
    // search's own variability: the claim is "clearly better", not a tie.
    let best_classical = classical_test.rms.min(classical_raw_test.rms);
    assert!(
        proposed_test.rms < 0.9 * best_classical,
        "proposed {} V vs classical {} V RMS on the unseen file",
        proposed_test.rms,
        best_classical
    );
}

/// Seed 001's model on the same real records: the asymmetric Bouc-Wen model
/// fitted by GA-PSO (eq. 5), refined by Levenberg-Marquardt, predicting the
/// displacement of the unseen file from its voltage. Same smoothing and
/// warm-up as above; the sensor offset is fitted with p and q.
///
/// The yardstick is the best model without hysteresis, y = g·u + offset by
/// least squares on the identification file: whatever the Bouc-Wen model
/// adds must show on data it has not seen.
#[test]
fn bouc_wen_predicts_the_unseen_p885_file_better_than_a_linear_model() {
    use piezo_identify::bouc_wen_fit::{
        BoucWenFitOptions, identify_bouc_wen, predict, prediction_error,
    };
    use piezo_identify::least_squares::solve_least_squares;

    let (identification, test) = p885_records();
    let y = centred_moving_average(&identification.output, SMOOTHING_HALF_WIDTH);
    let y_test = centred_moving_average(&test.output, SMOOTHING_HALF_WIDTH);
    let u = &identification.input;

    let options = BoucWenFitOptions {
        decimation: 2,
        warm_up_samples: WARM_UP,
        ..BoucWenFitOptions::default()
    };
    let fit = identify_bouc_wen(u, &y, &options, |_, _| {}).unwrap();
    let best = fit.best();
    let gapso_test = prediction_error(
        &predict(fit.gapso.params, fit.gapso.offset, &test.input),
        &y_test,
        WARM_UP,
    );
    let refined_test = prediction_error(
        &predict(best.params, best.offset, &test.input),
        &y_test,
        WARM_UP,
    );

    let rows = u.len() - WARM_UP;
    let regressors =
        nalgebra::DMatrix::from_fn(rows, 2, |i, j| if j == 0 { u[WARM_UP + i] } else { 1.0 });
    let line = solve_least_squares(regressors, &y[WARM_UP..]).coefficients;
    let linear_test: Vec<f64> = test.input.iter().map(|v| line[0] * v + line[1]).collect();
    let linear_test = prediction_error(&linear_test, &y_test, WARM_UP);

    println!(
        "Bouc-Wen on Model_Vi_Do.dat: GA-PSO RMS {:.4} um ({} evaluations, {:.1} s), refined {:.4} um; {:?}, offset {:.3} um",
        fit.gapso.rms, fit.gapso_evaluations, fit.gapso_seconds, best.rms, best.params, best.offset
    );
    for (name, e) in [
        ("GA-PSO", &gapso_test),
        ("refined", &refined_test),
        ("linear", &linear_test),
    ] {
        println!(
            "Test_Vi_Do_Di.dat (unseen) {name:<8} RMS {:.4} um ({:.2} % of {:.2} um), range {:+.3}..{:+.3} um",
            e.rms, e.rms_percent, e.stroke, e.min, e.max
        );
    }

    assert!(best.rms <= fit.gapso.rms);
    // Measured: 0.97 um, 2.37 % of the unseen file's stroke (README); the
    // bound leaves room for the search's seed-to-seed spread, not for a
    // regression to the linear model's figure.
    assert!(
        refined_test.rms_percent < 3.0,
        "refined Bouc-Wen RMS {:.3} % on the unseen file",
        refined_test.rms_percent
    );
    assert!(
        refined_test.rms < 0.6 * linear_test.rms,
        "Bouc-Wen {} um vs linear {} um RMS on the unseen file",
        refined_test.rms,
        linear_test.rms
    );
}
