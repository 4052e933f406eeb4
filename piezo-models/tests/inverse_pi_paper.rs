//! Seed 000's modified inverse P-I model (eq. 3-5) with the `paper` x model,
//! on a short trajectory worked out by hand from the equations.
//!
//! Trajectory y = 1, 3, 6, 4 µm sampled every T = 1 s, so the backward-difference
//! rates are ẏ = 0, 2, 3, −2 µm/s.
//!
//! Paper x model (Table 1, eq. 8, c = 1.033, u1max = 0.55348442):
//!   d = c·[0, 1, 3, 5, 7, 9] = [0, 1.033, 3.099, 5.165, 7.231, 9.297]
//!   r = [0, .25, .5, 1, 1.5, 2.25, 3, 4, 5, 6.5]·u1max/10
//!     = [0, 0.0138371105, 0.027674221, 0.055348442, 0.083022663, 0.1245339945,
//!        0.166045326, 0.221393768, 0.27674221, 0.359764873]
//!
//! n = 1, y = 1: z = w_s1·1 = −0.01351 (1 < d_2). Backlash from memory 0:
//!   H_1 = z; H_i = max(z − r_i, min(z + r_i, 0)) = 0 for i ≥ 2 (|z| < r_2).
//!   G(1) = 0.119e-4 − 2.518e-2 + 1.005 − 0.272 = 0.7078319.
//!   u = G + (k_1·0 + b_1)·H_1 = 0.7078319 + (−1.415)(−0.01351) = 0.72694855.
//! n = 2, y = 3: z = −0.01351·3 + 0.0566·(3 − 1.033) = 0.0708022.
//!   H = [0.0708022, 0.0569650895, 0.043127979, 0.015453758, 0, …] (z − r_i where
//!   positive, else the memory 0). G(3) = 2.5167013. u = 2.55823680882104.
//! n = 3, y = 6: z = −0.01351·6 + 0.0566·4.967 + 0.02915·2.901 + (−0.02259)·0.835
//!   = 0.2657737; H_i = z − r_i for i ≤ 8 (0.044379932 for i = 8), H_9 = H_10 = 0.
//!   G(6) = 4.8540904. u = 6.03186157929948.
//! n = 4, y = 4 (reversal): z = 0.14015635. Operators whose play covers the
//!   reversal keep their memory: H = [0.14015635, 0.1539934605, 0.167830571,
//!   0.195504792, 0.182751037, 0.1412397055, 0.099728374, 0.044379932, 0, 0].
//!   G(4) = 3.3458816. u = 4.48138517154276 (ẏ = −2 changes every weight).
//! (Exact rational arithmetic, rounded for printing.)

use piezo_models::inverse_pi::{InversePiModels, ModifiedInversePi, inverse_pi_trajectory};

const Y: [f64; 4] = [1.0, 3.0, 6.0, 4.0];
const RATES: [f64; 4] = [0.0, 2.0, 3.0, -2.0];
const HAND_COMPUTED_U: [f64; 4] = [
    0.72694855,
    2.55823680882104,
    6.03186157929948,
    4.48138517154276,
];

#[test]
fn paper_x_model_matches_the_hand_computed_samples() {
    let models = InversePiModels::paper();
    let mut model = ModifiedInversePi::new(models.x);
    for n in 0..4 {
        let u = model.evaluate(Y[n], RATES[n]);
        let expected = HAND_COMPUTED_U[n];
        assert!(
            (u - expected).abs() <= 1e-12 * expected.abs(),
            "sample {}: model {u} V, by hand {expected} V",
            n + 1
        );
    }
    // The trajectory helper derives the same rates by backward difference.
    let u = inverse_pi_trajectory(&models.x, &Y, 1.0);
    for n in 0..4 {
        assert!((u[n] - HAND_COMPUTED_U[n]).abs() <= 1e-12 * HAND_COMPUTED_U[n].abs());
    }
}

#[test]
fn paper_thresholds_follow_eq_5() {
    let x = InversePiModels::paper().x;
    let d = x.dead_zone_thresholds();
    for (got, want) in d.iter().zip([0.0, 1.033, 3.099, 5.165, 7.231, 9.297]) {
        assert!((got - want).abs() < 1e-12, "{d:?}");
    }
    let r = x.backlash_thresholds();
    assert!((r[9] - 0.359764873).abs() < 1e-12, "{r:?}");
    assert_eq!(r[0], 0.0);
}

#[test]
fn paper_models_validate_and_reset_restores_the_start() {
    let models = InversePiModels::paper();
    models.x.validate("x").unwrap();
    models.y.validate("y").unwrap();
    let mut model = ModifiedInversePi::new(models.y);
    let first = model.evaluate(2.0, 0.0);
    model.evaluate(8.0, 5.0);
    model.reset();
    assert_eq!(model.evaluate(2.0, 0.0), first);
}

/// The command a model gives on a quasi-static ramp 0 → `top` → 0 µm (rate
/// 0): (at 6 µm rising, at 6 µm falling, at the top, lowest, highest) [V].
fn quasi_static_ramp(params: piezo_models::InversePiParams, top: f64) -> [f64; 5] {
    let mut model = ModifiedInversePi::new(params);
    let steps = 20_000;
    let (mut rising_6, mut falling_6, mut at_top) = (f64::NAN, f64::NAN, f64::NAN);
    let (mut lowest, mut highest) = (f64::INFINITY, f64::NEG_INFINITY);
    for n in 0..=2 * steps {
        let y = top * (1.0 - (n as f64 - steps as f64).abs() / steps as f64);
        let u = model.evaluate(y, 0.0);
        lowest = lowest.min(u);
        highest = highest.max(u);
        let near_6 = (y - 6.0).abs() <= 0.5 * top / steps as f64;
        if near_6 && n < steps {
            rising_6 = u;
        } else if near_6 {
            falling_6 = u;
        } else if n == steps {
            at_top = u;
        }
    }
    [rising_6, falling_6, at_top, lowest, highest]
}

/// Table 1's y column of w_s is read × 10⁻² (MODEL.md §7): the y model,
/// like the x model, must command about the 0..10 V that eq. (6) drove the
/// paper's stage with over its stroke, and about G(y) of eq. (9). Taken as
/// printed it asks −14 V to reach 6 µm and under 3 V for the top of the
/// stroke. Bounds: the eq. (6) range 0..11 V widened by 0.5 V for the
/// hysteresis around G; the middle of the loop at 6 µm (the mean of the
/// rising and falling commands) within 0.5 V of G(6) = 4.11 V, the cubic
/// that carries the model's slope; the top of the stroke above 8 V.
#[test]
fn paper_y_model_commands_the_papers_voltage_range() {
    let models = InversePiModels::paper();
    let top = 12.22; // the plant's y stroke at 10 V (MODEL.md §5), as u1max is taken
    let [rising_6, falling_6, at_top, lowest, highest] = quasi_static_ramp(models.y, top);
    assert!(
        lowest >= -0.5 && highest <= 11.5,
        "y model commands {lowest:.2}..{highest:.2} V on its stroke"
    );
    let g6 = models.y.a[0] * 216.0 + models.y.a[1] * 36.0 + models.y.a[2] * 6.0 + models.y.a[3];
    assert!(
        ((rising_6 + falling_6) / 2.0 - g6).abs() <= 0.5,
        "6 um: {rising_6:.3} V rising, {falling_6:.3} V falling, G(6) = {g6:.3} V"
    );
    assert!(at_top > 8.0, "top of the stroke: {at_top:.2} V");
    // The letter of the table (w_s 100 times larger) fails each of these.
    let mut printed = models.y;
    for w in &mut printed.ws {
        *w *= 100.0;
    }
    printed.u1max *= 100.0;
    let [rising_6, _, at_top, lowest, highest] = quasi_static_ramp(printed, top);
    assert!(rising_6 < -10.0 && at_top < 3.0 && lowest < -15.0 && highest > 35.0);
}

/// The widest gap between the rising and the falling command over the third
/// of three quasi-static ramps 0 → `top` → 0 µm: the loop's width [V].
fn quasi_static_loop_width(params: piezo_models::InversePiParams, top: f64) -> f64 {
    let mut model = ModifiedInversePi::new(params);
    let steps = 20_000;
    let mut rising = vec![0.0; steps + 1];
    let mut width: f64 = 0.0;
    for cycle in 0..3 {
        for n in 0..=2 * steps {
            let k = n.min(2 * steps - n);
            let u = model.evaluate(top * k as f64 / steps as f64, 0.0);
            if cycle == 2 && n <= steps {
                rising[k] = u;
            } else if cycle == 2 {
                width = width.max((u - rising[k]).abs());
            }
        }
    }
    width
}

/// MODEL.md §7's figures for the choice between 10⁻² and 10⁻¹: the paper's
/// numbers rule out the printed scale but not 10⁻¹, whose y model stays in
/// −0.38..8.98 V on the ramp from rest, with a loop 3.28 V wide once
/// cycled; 10⁻² gives 0.33 V; the x model's loop is 1.40 V wide. Printed
/// with --nocapture; asserted within 0.01 V.
#[test]
fn the_y_loop_under_either_remaining_reading_beside_the_x_loop() {
    let models = InversePiModels::paper();
    let mut tenth = models.y;
    for w in &mut tenth.ws {
        *w *= 10.0;
    }
    tenth.u1max *= 10.0;
    let [_, _, _, lowest, highest] = quasi_static_ramp(tenth, 12.22);
    let widths = [
        quasi_static_loop_width(models.y, 12.22),
        quasi_static_loop_width(tenth, 12.22),
        quasi_static_loop_width(models.x, 12.74),
    ];
    println!(
        "y x 1e-1: {lowest:.2}..{highest:.2} V; loop widths: y x 1e-2 {:.2} V, y x 1e-1 {:.2} V, x {:.2} V",
        widths[0], widths[1], widths[2]
    );
    assert!((lowest + 0.38).abs() < 0.01 && (highest - 8.98).abs() < 0.01);
    for (got, documented) in widths.iter().zip([0.33, 3.28, 1.40]) {
        assert!((got - documented).abs() < 0.01, "{widths:?}");
    }
}
