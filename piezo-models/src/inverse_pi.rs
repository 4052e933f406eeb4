//! The modified inverse Prandtl-Ishlinskii model of seed 000 §3.1 (eq. 1-5):
//! the feedforward that turns a demanded displacement into a command voltage.
//!
//! ```text
//! u(t) = G(y) + Σ_{i=1..10} w_h,i · H_{r_i}[z](t)        eq. (3)
//! z(t) = Σ_{j=1..6}  w_s,j · S_{d_j}[y](t)
//! w_h,i = k_i · ẏ + b_i                                    eq. (4)
//! G(y) = a1·y³ + a2·y² + a3·y + a4
//! d = c·[0, 1, 3, 5, 7, 9],  r = [0, 0.25, 0.5, 1, 1.5, 2.25, 3, 4, 5, 6.5]·u1max/10   eq. (5)
//! ```
//!
//! y is the demanded displacement [µm], ẏ its rate [µm/s], u the command [V].
//! Eq. (3) as printed writes the dead-zone weights as w_s(ẏ); eq. (4), the
//! text around it ("the weights of the backlash operators change linearly
//! with the input rate") and Table 1 (a k_i and b_i for each of the ten
//! backlash operators, one w_s,i for each dead zone) make the backlash
//! weights the rate-dependent ones, and so does this model.
//! The backlash operators (eq. 1) keep one memory each; eq. 1's initial value
//! `max(u(0) − r, min(u(0) + r, 0))` is the backlash update from a memory of 0,
//! so the memories start at 0 and the first sample needs no special case.
//! Seed 000 adds that "the start state of the backlash operator is determined
//! by the initial energy condition of the actuation devices": an actuator
//! that rests after being operated (as FlexureStage's stacks do) starts on the
//! descending branch of its working loop, which `rest_cycle` gives: the
//! memories start where a demand 0 → `rest_cycle` → 0 leaves them.
//!
//! Given c, w_s and u1max the model is linear in (a, k, b): see
//! [`linear_regressors`], which identification uses to solve that part exactly.

use serde::{Deserialize, Serialize};

use crate::flexure_stage::ParamError;
use crate::parameter::Range;

pub const BACKLASH_OPERATORS: usize = 10;
pub const DEAD_ZONE_OPERATORS: usize = 6;
/// Number of coefficients of the linear part: a (4), k (10), b (10).
pub const LINEAR_COEFFICIENTS: usize = 4 + 2 * BACKLASH_OPERATORS;

/// eq. (5): dead-zone thresholds in units of c.
const DEAD_ZONE_PATTERN: [f64; DEAD_ZONE_OPERATORS] = [0.0, 1.0, 3.0, 5.0, 7.0, 9.0];
/// eq. (5): backlash thresholds in units of u1max/10.
const BACKLASH_PATTERN: [f64; BACKLASH_OPERATORS] =
    [0.0, 0.25, 0.5, 1.0, 1.5, 2.25, 3.0, 4.0, 5.0, 6.5];

/// The largest demanded rate eq. (4)'s weights take [µm/s]. A backward
/// difference over a step of subnormal length (legal in FMI: any step size
/// above 0) overflows to ±∞, and with it the weights, whose k_i of both signs
/// (or 0) then add to NaN. 1e12 µm/s is a million metres per second, eight
/// orders above the fastest demand the seeds track (10 µm at 100 Hz, about
/// 4·10³ µm/s): no demand a stage can follow reaches it, and k_i·rate·h_i
/// stays finite for every model a fit produces.
pub const MAX_DEMAND_RATE: f64 = 1e12;

/// The demanded rate as eq. (4)'s weights take it: within ±[`MAX_DEMAND_RATE`].
fn bounded_rate(rate: f64) -> f64 {
    rate.clamp(-MAX_DEMAND_RATE, MAX_DEMAND_RATE)
}

/// Backlash (play) operator, eq. (1): the output follows the input with a
/// play of ±r around its previous value.
pub fn backlash(input: f64, threshold: f64, previous: f64) -> f64 {
    (input - threshold).max((input + threshold).min(previous))
}

/// One-sided dead-zone operator, eq. (2).
pub fn dead_zone(input: f64, threshold: f64) -> f64 {
    if threshold > 0.0 {
        (input - threshold).max(0.0)
    } else {
        input
    }
}

/// Parameters of one modified inverse P-I model (one per actuator channel).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InversePiParams {
    /// Slopes of the backlash weights with the demanded rate, eq. (4) [V·s/µm²].
    pub k: [f64; BACKLASH_OPERATORS],
    /// Intercepts of the backlash weights, eq. (4) [V/µm].
    pub b: [f64; BACKLASH_OPERATORS],
    /// Dead-zone weights w_s [1].
    pub ws: [f64; DEAD_ZONE_OPERATORS],
    /// Scale of the dead-zone thresholds, eq. (5) [µm].
    pub c: f64,
    /// Largest magnitude of the dead-zone superposition z over the working
    /// range; scales the backlash thresholds, eq. (5) [µm].
    pub u1max: f64,
    /// Cubic input function G(y) = a1·y³ + a2·y² + a3·y + a4 [V/µm³, V/µm², V/µm, V].
    pub a: [f64; 4],
    /// The working loop the actuator rests on [µm]: the memories start where
    /// a demand 0 → `rest_cycle` → 0 leaves them. 0: eq. (1)'s zero memories,
    /// a de-energized actuator that was never operated (the paper's Table 1).
    #[serde(default)]
    pub rest_cycle: f64,
}

impl InversePiParams {
    pub fn dead_zone_thresholds(&self) -> [f64; DEAD_ZONE_OPERATORS] {
        dead_zone_thresholds(self.c)
    }

    pub fn backlash_thresholds(&self) -> [f64; BACKLASH_OPERATORS] {
        backlash_thresholds(self.u1max)
    }

    /// The cubic input function G(y).
    pub fn cubic(&self, y: f64) -> f64 {
        let [a1, a2, a3, a4] = self.a;
        ((a1 * y + a2) * y + a3) * y + a4
    }

    /// 0: eq. 1's zero memories; a demand's amplitude otherwise [µm].
    pub const REST_CYCLE: Range = Range::NON_NEGATIVE;
    /// c and u1max: the thresholds of eq. 5 scale with them and must be
    /// increasing.
    pub const THRESHOLD_SCALE: Range = Range::POSITIVE;

    /// Checks that every value is finite and in its declared range; `name`
    /// prefixes the parameter paths in the error.
    pub fn validate(&self, name: &str) -> Result<(), ParamError> {
        for (field, values) in [
            ("k", &self.k[..]),
            ("b", &self.b[..]),
            ("ws", &self.ws[..]),
            ("a", &self.a[..]),
        ] {
            for (i, v) in values.iter().enumerate() {
                Range::FINITE.check(&format!("{name}.{field}[{i}]"), *v)?;
            }
        }
        Self::REST_CYCLE.check(&format!("{name}.rest_cycle"), self.rest_cycle)?;
        Self::THRESHOLD_SCALE.check(&format!("{name}.c"), self.c)?;
        Self::THRESHOLD_SCALE.check(&format!("{name}.u1max"), self.u1max)
    }
}

/// eq. (5): d = c·[0, 1, 3, 5, 7, 9].
pub fn dead_zone_thresholds(c: f64) -> [f64; DEAD_ZONE_OPERATORS] {
    DEAD_ZONE_PATTERN.map(|p| c * p)
}

/// eq. (5): r = [0, 0.25, …, 6.5]·u1max/10.
pub fn backlash_thresholds(u1max: f64) -> [f64; BACKLASH_OPERATORS] {
    BACKLASH_PATTERN.map(|p| p * u1max / 10.0)
}

/// The dead-zone superposition z = Σ w_s,j·S_{d_j}[y].
pub fn dead_zone_superposition(y: f64, ws: &[f64; DEAD_ZONE_OPERATORS], c: f64) -> f64 {
    dead_zone_thresholds(c)
        .iter()
        .zip(ws)
        .map(|(d, w)| w * dead_zone(y, *d))
        .sum()
}

/// The u1max of eq. (5) for a working range y ∈ [0, y_max]: the largest |z|.
/// z is piecewise linear in y with breaks at the dead-zone thresholds, so its
/// extremes lie at 0, y_max or a threshold inside the range.
pub fn u1max_over_range(ws: &[f64; DEAD_ZONE_OPERATORS], c: f64, y_max: f64) -> f64 {
    let mut candidates = vec![0.0, y_max];
    candidates.extend(dead_zone_thresholds(c).into_iter().filter(|d| *d < y_max));
    candidates
        .into_iter()
        .map(|y| dead_zone_superposition(y, ws, c).abs())
        .fold(0.0, f64::max)
}

/// The backlash memories of one model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
struct BacklashMemories([f64; BACKLASH_OPERATORS]);

impl BacklashMemories {
    /// The memories a demand 0 → `top` → 0 leaves, from zero memories. z is
    /// piecewise linear in y with breaks at the dead-zone thresholds, so its
    /// path is exact through those breaks; the play operators' memory depends
    /// only on the extremes of their input, not on its speed.
    fn after_cycle(
        top: f64,
        ws: &[f64; DEAD_ZONE_OPERATORS],
        c: f64,
        thresholds: &[f64; BACKLASH_OPERATORS],
    ) -> BacklashMemories {
        let mut memories = BacklashMemories::default();
        if top.is_nan() || top <= 0.0 {
            return memories;
        }
        // The thresholds ascend (eq. 5), so this is the path up, then down.
        let breaks = dead_zone_thresholds(c);
        let inside = |d: &f64| *d > 0.0 && *d < top;
        let mut visit = |y: f64| {
            memories.advance(dead_zone_superposition(y, ws, c), thresholds);
        };
        visit(0.0);
        breaks.iter().filter(|d| inside(d)).for_each(|d| visit(*d));
        visit(top);
        breaks
            .iter()
            .rev()
            .filter(|d| inside(d))
            .for_each(|d| visit(*d));
        visit(0.0);
        memories
    }

    /// Advances every operator with input z; returns their outputs.
    fn advance(
        &mut self,
        z: f64,
        thresholds: &[f64; BACKLASH_OPERATORS],
    ) -> [f64; BACKLASH_OPERATORS] {
        for (memory, r) in self.0.iter_mut().zip(thresholds) {
            *memory = backlash(z, *r, *memory);
        }
        self.0
    }
}

/// A modified inverse P-I model with its operator memories (streaming use:
/// one call of [`evaluate`](Self::evaluate) per sample, no allocation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModifiedInversePi {
    params: InversePiParams,
    dead_zone_thresholds: [f64; DEAD_ZONE_OPERATORS],
    backlash_thresholds: [f64; BACKLASH_OPERATORS],
    memories: BacklashMemories,
}

impl ModifiedInversePi {
    /// A model at its rest: memories after a demand 0 → `rest_cycle` → 0 (all
    /// 0 for `rest_cycle` = 0).
    pub fn new(params: InversePiParams) -> Self {
        let backlash_thresholds = params.backlash_thresholds();
        ModifiedInversePi {
            dead_zone_thresholds: params.dead_zone_thresholds(),
            memories: BacklashMemories::after_cycle(
                params.rest_cycle,
                &params.ws,
                params.c,
                &backlash_thresholds,
            ),
            backlash_thresholds,
            params,
        }
    }

    pub fn params(&self) -> &InversePiParams {
        &self.params
    }

    /// Takes `from`'s backlash memories, keeping this model's parameters and
    /// thresholds ([`crate::restore`]).
    pub(crate) fn carry_memories(&mut self, from: &Self) {
        self.memories = from.memories;
    }

    /// The backlash memories (the model's dynamic state).
    pub(crate) fn memories(&self) -> [f64; BACKLASH_OPERATORS] {
        self.memories.0
    }

    /// Back to the rest the model started from.
    pub fn reset(&mut self) {
        self.memories = BacklashMemories::after_cycle(
            self.params.rest_cycle,
            &self.params.ws,
            self.params.c,
            &self.backlash_thresholds,
        );
    }

    /// One sample of eq. (3)-(5): the command [V] for demanded displacement
    /// `y` [µm] moving at `y_rate` [µm/s]; advances the backlash memories.
    /// Eq. (4)'s weights take the rate within ±[`MAX_DEMAND_RATE`].
    pub fn evaluate(&mut self, y: f64, y_rate: f64) -> f64 {
        let p = &self.params;
        let y_rate = bounded_rate(y_rate);
        let z: f64 = self
            .dead_zone_thresholds
            .iter()
            .zip(&p.ws)
            .map(|(d, w)| w * dead_zone(y, *d))
            .sum();
        let h = self.memories.advance(z, &self.backlash_thresholds);
        let weighted: f64 = (0..BACKLASH_OPERATORS)
            .map(|i| (p.k[i] * y_rate + p.b[i]) * h[i])
            .sum();
        p.cubic(y) + weighted
    }
}

/// Backward-difference rates of a sampled trajectory (the first rate is 0).
pub fn backward_rates(y: &[f64], sample_period: f64) -> Vec<f64> {
    (0..y.len())
        .map(|n| {
            if n == 0 {
                0.0
            } else {
                (y[n] - y[n - 1]) / sample_period
            }
        })
        .collect()
}

/// The model over a sampled trajectory, from the de-energized start, with
/// rates by backward difference.
pub fn inverse_pi_trajectory(params: &InversePiParams, y: &[f64], sample_period: f64) -> Vec<f64> {
    let mut model = ModifiedInversePi::new(*params);
    y.iter()
        .zip(backward_rates(y, sample_period))
        .map(|(y, rate)| model.evaluate(*y, rate))
        .collect()
}

/// Regressors of the part of eq. (3) that is linear once c, w_s and u1max are
/// fixed: row n is [y³, y², y, 1, ẏ·H_1 … ẏ·H_10, H_1 … H_10], so that
/// u_n = row_n · [a1 … a4, k1 … k10, b1 … b10].
pub fn linear_regressors(
    c: f64,
    ws: &[f64; DEAD_ZONE_OPERATORS],
    u1max: f64,
    y: &[f64],
    sample_period: f64,
) -> Vec<[f64; LINEAR_COEFFICIENTS]> {
    let thresholds = backlash_thresholds(u1max);
    let mut memories = BacklashMemories::default();
    y.iter()
        .zip(backward_rates(y, sample_period))
        .map(|(&y, rate)| {
            // The rate as `ModifiedInversePi::evaluate` weights it.
            let rate = bounded_rate(rate);
            let h = memories.advance(dead_zone_superposition(y, ws, c), &thresholds);
            let mut row = [0.0; LINEAR_COEFFICIENTS];
            row[..4].copy_from_slice(&[y * y * y, y * y, y, 1.0]);
            for i in 0..BACKLASH_OPERATORS {
                row[4 + i] = rate * h[i];
                row[4 + BACKLASH_OPERATORS + i] = h[i];
            }
            row
        })
        .collect()
}

/// The coefficient vector [a, k, b] matching [`linear_regressors`].
pub fn linear_coefficients(params: &InversePiParams) -> [f64; LINEAR_COEFFICIENTS] {
    let mut theta = [0.0; LINEAR_COEFFICIENTS];
    theta[..4].copy_from_slice(&params.a);
    theta[4..4 + BACKLASH_OPERATORS].copy_from_slice(&params.k);
    theta[4 + BACKLASH_OPERATORS..].copy_from_slice(&params.b);
    theta
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backlash_follows_eq_1() {
        // Rising past the play, reversing inside it, then falling past it.
        let r = 0.5;
        let mut h = backlash(0.0, r, 0.0);
        assert_eq!(h, 0.0, "eq. 1 initial value at u(0) = 0");
        let mut out = Vec::new();
        for u in [0.4, 1.0, 2.0, 1.8, 1.5, 1.0, 0.0] {
            h = backlash(u, r, h);
            out.push(h);
        }
        assert_eq!(out, vec![0.0, 0.5, 1.5, 1.5, 1.5, 1.5, 0.5]);
        // Initial value of eq. 1 for u(0) outside the play: max(u−r, min(u+r, 0)).
        assert_eq!(backlash(2.0, r, 0.0), 1.5);
        assert_eq!(backlash(-2.0, r, 0.0), -1.5);
        // r = 0 is the identity.
        assert_eq!(backlash(3.7, 0.0, 1.0), 3.7);
    }

    #[test]
    fn dead_zone_follows_eq_2() {
        assert_eq!(dead_zone(5.0, 0.0), 5.0);
        assert_eq!(dead_zone(-1.0, 0.0), -1.0);
        assert_eq!(dead_zone(5.0, 3.0), 2.0);
        assert_eq!(dead_zone(2.0, 3.0), 0.0);
    }

    /// A step of the smallest positive length after a jump of the demand
    /// (the backward difference overflows to ±∞): the command is the one at
    /// the largest rate eq. (4) takes, finite, where the unbounded rate gave
    /// NaN through the k_i of both signs and the zero ones.
    #[test]
    fn a_rate_that_overflows_gives_a_finite_command() {
        // A zero k_i among them: 0·∞ alone made NaN.
        let params = InversePiParams {
            k: [0.1, -0.2, 0.05, 0.0, 0.3, -0.1, 0.02, 0.04, -0.06, 0.0],
            rest_cycle: 10.0,
            ..test_params()
        };
        let subnormal_period = f64::from_bits(1);
        for jump in [3.0, -3.0] {
            let rate = jump / subnormal_period;
            assert!(rate.is_infinite());
            let mut model = ModifiedInversePi::new(params);
            let mut at_the_bound = model.clone();
            let u = model.evaluate(5.0 + jump, rate);
            let bound = at_the_bound.evaluate(5.0 + jump, jump.signum() * MAX_DEMAND_RATE);
            assert!(u.is_finite(), "jump {jump}: {u}");
            assert_eq!(u, bound, "jump {jump}");
        }
    }

    #[test]
    fn u1max_is_the_largest_magnitude_of_z() {
        let ws = [1.0, -2.0, 0.0, 0.0, 0.0, 0.0];
        // z = y − 2·max(y − 1, 0): peak 1 at y = 1, then falls to −1 at y = 3.
        assert_eq!(u1max_over_range(&ws, 1.0, 3.0), 1.0);
        assert_eq!(u1max_over_range(&ws, 1.0, 4.0), 2.0);
    }

    /// A model with weights of both signs, from zero memories.
    fn test_params() -> InversePiParams {
        InversePiParams {
            k: [0.1, -0.2, 0.05, 0.0, 0.3, -0.1, 0.02, 0.04, -0.06, 0.08],
            b: [1.0, 0.5, -0.3, 0.2, 0.1, 0.4, -0.2, 0.3, 0.1, -0.05],
            ws: [0.9, 0.05, -0.02, 0.01, 0.03, -0.01],
            c: 1.1,
            u1max: 11.0,
            a: [1e-4, -0.02, 0.9, -0.1],
            rest_cycle: 0.0,
        }
    }

    #[test]
    fn regressors_reproduce_the_model() {
        let params = test_params();
        let y: Vec<f64> = (0..400)
            .map(|n| 6.0 + 5.0 * (n as f64 * 0.05).sin())
            .collect();
        let direct = inverse_pi_trajectory(&params, &y, 1e-3);
        let theta = linear_coefficients(&params);
        let rows = linear_regressors(params.c, &params.ws, params.u1max, &y, 1e-3);
        for (n, (row, u)) in rows.iter().zip(&direct).enumerate() {
            let via_rows: f64 = row.iter().zip(&theta).map(|(r, t)| r * t).sum();
            assert!(
                (via_rows - u).abs() <= 1e-12 * u.abs().max(1.0),
                "sample {n}: {via_rows} vs {u}"
            );
        }
    }
}

/// The inverse models of the x pair (PZT2 and PZT3 share one) and of y (PZT1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InversePiModels {
    pub x: InversePiParams,
    pub y: InversePiParams,
}

/// Seed 000's identified models as printed, the single source of
/// [`InversePiModels::paper`].
const PAPER_JSON: &str = include_str!("../presets/inverse_pi_paper.json");

impl InversePiModels {
    /// Seed 000's models, as printed: Table 1 (x: k_i and w_s,i in units of
    /// 10⁻² as its column headers say; y: k_i in units of 10⁻³; b_i and y's
    /// w_s,i as printed), c_x = 1.033 and c_y = 0.716 (§3.1), G from eq. (8)
    /// and (9). The paper does not print u1max; it is taken as the largest
    /// |z| over the working range y ∈ [0, stroke] (12.74 µm for x, 12.22 µm
    /// for y, §2), see [`u1max_over_range`]: the largest z itself would be 0
    /// for y, whose first dead-zone weight is negative.
    pub fn paper() -> Self {
        serde_json::from_str(PAPER_JSON).expect("presets/inverse_pi_paper.json parses (tested)")
    }
}
