//! Seed 001's XY200S preset: the committed parameter set is what the
//! conversion of the printed Tables 1-2 produces (so nobody edits it by hand
//! or forgets to regenerate it), and each converted model follows its printed
//! model on the identification run.

use piezo_identify::xy200s::{
    IDENTIFICATION_RATE, PRINTED_H_XX, PRINTED_H_XY, PRINTED_H_YX, PRINTED_H_YY,
    identification_input, printed_response, xy200s_preset,
};
use piezo_models::FlexureStageParams;

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

#[test]
fn committed_preset_is_the_conversion_of_the_printed_tables() {
    let preset = xy200s_preset().unwrap();
    for model in &preset.models {
        println!(
            "{}: printed span {:.3} um, rate-independent fit RMS {:.4} um ({:.3} %), output scale {:.4}",
            model.name,
            model.printed_span_um,
            model.rms_um,
            100.0 * model.rms_um / model.printed_span_um,
            model.stroke_scale
        );
    }
    assert_eq!(
        preset.stage,
        FlexureStageParams::xy200s(),
        "piezo-models/presets/xy200s_stage.json is stale: run `make xy200s-preset`"
    );
    let printed: Vec<_> = preset.models.iter().map(|m| m.printed).collect();
    assert_eq!(
        printed,
        [PRINTED_H_XX, PRINTED_H_YY, PRINTED_H_XY, PRINTED_H_YX]
    );
    // The rate-independent reading cannot follow the printed asymmetry term
    // exactly (it acts in time, not in voltage), and the plant's models must
    // rise on every branch. Measured: H_XX 3.13 %, H_YY 1.19 %, H_XY 0.10 %,
    // H_YX 0.035 % of each printed span; the bounds catch a conversion that
    // falls off its optimum.
    for (model, bound_percent) in preset.models.iter().zip([3.5, 1.5, 0.2, 0.1]) {
        let percent = 100.0 * model.rms_um / model.printed_span_um;
        assert!(percent < bound_percent, "{}: {percent} %", model.name);
    }
}

/// The XY200S preset's X actuator sinks on small cycles (docs/seed001.md,
/// "Why seed 000's feedforward drifts on the XY200S"). The printed H_XX, run
/// in time as the conversion reads it, does the same: after seed 001's
/// identification sine, five 1 s cycles 0 -> 30 -> 0 V (the preset's 0 -> 2
/// -> 0 V command) each end lower than the last. So the ratchet comes with
/// the printed model under this reading; docs/seed001.md prints the drops,
/// compared here (1 % or a unit of the last digit).
#[test]
fn printed_h_xx_sinks_on_small_cycles_as_the_preset_does() {
    let exercise = identification_input();
    let cycle = IDENTIFICATION_RATE as usize; // samples in a 1 s cycle
    let mut input = exercise.clone();
    for _ in 0..5 {
        input.extend((1..=cycle).map(|i| {
            let phase = i as f64 / cycle as f64;
            30.0 * (1.0 - (2.0 * phase - 1.0).abs())
        }));
    }
    let y_mm = printed_response(&PRINTED_H_XX, &input, 1.0 / IDENTIFICATION_RATE);
    let ends_um: Vec<f64> = (0..=5)
        .map(|c| 1000.0 * y_mm[exercise.len() - 1 + c * cycle])
        .collect();
    let drops: Vec<f64> = ends_um.windows(2).map(|w| w[1] - w[0]).collect();
    let measured = drops
        .iter()
        .map(|d| format!("{:.2}", -d))
        .collect::<Vec<_>>()
        .join(", ");
    println!("printed H_XX at 0 V after the exercise: {ends_um:.3?} um; drops {measured} um");
    assert!(
        drops.iter().all(|d| *d < 0.0),
        "every cycle ends lower: {drops:?}"
    );
    let printed = docs_figures::text_between(
        "seed001.md",
        "lower it by",
        "um (`cargo test --release -p piezo-identify --test xy200s",
    )
    .expect("docs/seed001.md no longer prints the printed H_XX's drops");
    assert!(
        docs_figures::same_numbers(&printed, &measured),
        "docs/seed001.md prints {printed:?}, measured {measured:?}"
    );
}
