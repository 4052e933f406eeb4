//! The rivals of seed 000's proposed model, and one streaming interface for
//! all of them.
//!
//! Seed 000 §3.1 compares its proposed modified inverse P-I model (eq. 3-5:
//! cubic G(y) in parallel with 10 rate-weighted backlash operators fed by 6
//! dead-zone operators, [`piezo_models::ModifiedInversePi`]) with two
//! "traditional" inverse P-I models, 10 backlash + 6 dead-zone operators and
//! 10 backlash + 10 dead-zone operators, and says the latter has as many
//! parameters as the proposed one. The proposed model has 31: a (4), k (10),
//! b (10), w_s (6) and c. A traditional 10 + 10 model has 31 only if its
//! backlash weights are rate dependent like eq. (4) (k, b, 10 w_s and c) and
//! it has no cubic. So the traditional models here are eq. (3)-(5) without G(y):
//!
//! ```text
//! u = Σ_{i=1..10} (k_i·ẏ + b_i) · H_{r_i}[z],   z = Σ_j w_s,j · S_{d_j}[y]
//! ```
//!
//! with the backlash thresholds of eq. (5) (r = [0, 0.25, …, 6.5]·u1max/10,
//! u1max the largest |z| over [0, y_max]) and dead-zone thresholds c·[0, 1, 3,
//! 5, 7, 9] for six operators (eq. 5) and c·[0, 1, …, 9] for ten (the paper
//! does not print them; evenly spaced in units of c is the reading that keeps
//! the first six as close as possible to eq. 5's spacing).
//!
//! The classical P-I model is the textbook one: 10 backlash operators acting
//! directly on y with constant weights, plus a constant offset,
//! `u = w_0 + Σ_i w_i·H_{r_i}[y]`, thresholds r_i = i·(y_max − y_min)/10,
//! i = 0…9, evenly spaced over the displacement range of the identification
//! data (r_0 = 0 is the linear term).
//!
//! All backlash memories start at 0, the de-energized state of eq. (1).
//! Per-sample evaluation allocates nothing.

use piezo_models::ModifiedInversePi;
use piezo_models::inverse_pi::{BACKLASH_OPERATORS, backlash, backlash_thresholds, dead_zone};
use serde::{Deserialize, Serialize};

/// eq. (5): dead-zone thresholds of six operators, in units of c.
pub const SIX_DEAD_ZONE_PATTERN: [f64; 6] = [0.0, 1.0, 3.0, 5.0, 7.0, 9.0];
/// Dead-zone thresholds of ten operators, in units of c (the reading
/// documented in the module comment).
pub const TEN_DEAD_ZONE_PATTERN: [f64; 10] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];

/// Number of backlash operators of the classical P-I model.
pub const CLASSICAL_OPERATORS: usize = 10;

/// The dead-zone pattern of a traditional model with `D` dead-zone operators:
/// eq. (5)'s for six, evenly spaced for any other count.
pub fn dead_zone_pattern<const D: usize>() -> [f64; D] {
    if D == SIX_DEAD_ZONE_PATTERN.len() {
        std::array::from_fn(|j| SIX_DEAD_ZONE_PATTERN[j])
    } else {
        std::array::from_fn(|j| j as f64)
    }
}

/// z = Σ_j w_s,j · S_{d_j}[y] for any number of dead-zone operators.
pub fn dead_zone_sum(y: f64, weights: &[f64], thresholds: &[f64]) -> f64 {
    weights
        .iter()
        .zip(thresholds)
        .map(|(w, d)| w * dead_zone(y, *d))
        .sum()
}

/// The u1max of eq. (5) for any number of dead-zone operators: the largest |z|
/// over y ∈ [0, y_max]. z is piecewise linear in y with breaks at the
/// thresholds, so the extremes are at 0, y_max or a threshold inside.
/// (Generalises `piezo_models::inverse_pi::u1max_over_range`, which is fixed
/// at six operators.)
pub fn u1max_for(weights: &[f64], thresholds: &[f64], y_max: f64) -> f64 {
    let mut largest = dead_zone_sum(y_max, weights, thresholds).abs();
    for &d in thresholds {
        if d > 0.0 && d < y_max {
            largest = largest.max(dead_zone_sum(d, weights, thresholds).abs());
        }
    }
    largest
}

/// One sample of an inverse hysteresis model with operator memories.
pub trait InverseHysteresis {
    /// The command [V] for displacement `y` [µm] moving at `y_rate` [µm/s];
    /// advances the operator memories. Allocates nothing.
    fn evaluate(&mut self, y: f64, y_rate: f64) -> f64;
    /// Back to the de-energized start (all memories 0).
    fn reset(&mut self);
}

impl InverseHysteresis for ModifiedInversePi {
    fn evaluate(&mut self, y: f64, y_rate: f64) -> f64 {
        ModifiedInversePi::evaluate(self, y, y_rate)
    }

    fn reset(&mut self) {
        ModifiedInversePi::reset(self);
    }
}

/// The model over a sampled trajectory from the de-energized start, rates by
/// backward difference (the first rate 0), as `inverse_pi_trajectory` does.
pub fn predict<M: InverseHysteresis>(model: &mut M, y: &[f64], sample_period: f64) -> Vec<f64> {
    model.reset();
    let mut previous = y.first().copied().unwrap_or(0.0);
    y.iter()
        .map(|&y| {
            let rate = (y - previous) / sample_period;
            previous = y;
            model.evaluate(y, rate)
        })
        .collect()
}

/// Parameters of a traditional inverse P-I model with `D` dead-zone operators
/// (module comment): eq. (3)-(5) without the cubic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraditionalInversePiParams<const D: usize> {
    /// Slopes of the backlash weights with the rate, eq. (4) [V·s/µm²].
    pub k: [f64; BACKLASH_OPERATORS],
    /// Intercepts of the backlash weights, eq. (4) [V/µm].
    pub b: [f64; BACKLASH_OPERATORS],
    /// Dead-zone weights w_s [1].
    pub ws: [f64; D],
    /// Scale of the dead-zone thresholds [µm].
    pub c: f64,
    /// Largest |z| over the working range; scales the backlash thresholds [µm].
    pub u1max: f64,
}

impl<const D: usize> TraditionalInversePiParams<D> {
    pub fn dead_zone_thresholds(&self) -> [f64; D] {
        dead_zone_pattern::<D>().map(|p| p * self.c)
    }

    /// Number of identified parameters: k, b, w_s and c (u1max follows from
    /// them and the data range).
    pub const PARAMETER_COUNT: usize = 2 * BACKLASH_OPERATORS + D + 1;
}

/// A traditional inverse P-I model with its backlash memories.
#[derive(Clone, Debug, PartialEq)]
pub struct TraditionalInversePi<const D: usize> {
    params: TraditionalInversePiParams<D>,
    dead_zone_thresholds: [f64; D],
    backlash_thresholds: [f64; BACKLASH_OPERATORS],
    /// The backlash operator outputs of the previous sample (eq. 1).
    backlash_memories: [f64; BACKLASH_OPERATORS],
}

impl<const D: usize> TraditionalInversePi<D> {
    pub fn new(params: TraditionalInversePiParams<D>) -> Self {
        TraditionalInversePi {
            dead_zone_thresholds: params.dead_zone_thresholds(),
            backlash_thresholds: backlash_thresholds(params.u1max),
            params,
            backlash_memories: [0.0; BACKLASH_OPERATORS],
        }
    }

    pub fn params(&self) -> &TraditionalInversePiParams<D> {
        &self.params
    }
}

impl<const D: usize> InverseHysteresis for TraditionalInversePi<D> {
    fn evaluate(&mut self, y: f64, y_rate: f64) -> f64 {
        let p = &self.params;
        let z = dead_zone_sum(y, &p.ws, &self.dead_zone_thresholds);
        let mut u = 0.0;
        for i in 0..BACKLASH_OPERATORS {
            // eq. (1) on z, weighted by eq. (4)'s rate-dependent weight.
            let h = backlash(z, self.backlash_thresholds[i], self.backlash_memories[i]);
            self.backlash_memories[i] = h;
            u += (p.k[i] * y_rate + p.b[i]) * h;
        }
        u
    }

    fn reset(&mut self) {
        self.backlash_memories = [0.0; BACKLASH_OPERATORS];
    }
}

/// Parameters of the classical P-I model (module comment).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassicalPiParams {
    /// Constant weight of each backlash operator [V/µm].
    pub weights: [f64; CLASSICAL_OPERATORS],
    /// Backlash thresholds on y [µm].
    pub thresholds: [f64; CLASSICAL_OPERATORS],
    /// Constant term [V].
    pub offset: f64,
}

impl ClassicalPiParams {
    /// Number of identified parameters: the weights and the offset.
    pub const PARAMETER_COUNT: usize = CLASSICAL_OPERATORS + 1;

    /// r_i = i·span/20, i = 0…9, over a range `span` of the model's input:
    /// a loop over the whole range moves every operator (an operator moves
    /// once the input has travelled 2r from its last turning point).
    pub fn evenly_spaced_thresholds(span: f64) -> [f64; CLASSICAL_OPERATORS] {
        std::array::from_fn(|i| i as f64 * span / (2 * CLASSICAL_OPERATORS) as f64)
    }
}

/// A classical P-I model with its backlash memories.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassicalPi {
    params: ClassicalPiParams,
    backlash_memories: [f64; CLASSICAL_OPERATORS],
}

impl ClassicalPi {
    pub fn new(params: ClassicalPiParams) -> Self {
        ClassicalPi {
            params,
            backlash_memories: [0.0; CLASSICAL_OPERATORS],
        }
    }

    pub fn params(&self) -> &ClassicalPiParams {
        &self.params
    }
}

impl InverseHysteresis for ClassicalPi {
    /// Rate independent: `y_rate` is ignored.
    fn evaluate(&mut self, y: f64, _y_rate: f64) -> f64 {
        let p = &self.params;
        let mut u = p.offset;
        for i in 0..CLASSICAL_OPERATORS {
            let h = backlash(y, p.thresholds[i], self.backlash_memories[i]);
            self.backlash_memories[i] = h;
            u += p.weights[i] * h;
        }
        u
    }

    fn reset(&mut self) {
        self.backlash_memories = [0.0; CLASSICAL_OPERATORS];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use piezo_models::InversePiParams;
    use piezo_models::inverse_pi::{inverse_pi_trajectory, u1max_over_range};

    fn sine(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| 6.0 - 5.0 * (i as f64 * 0.02).cos() + 0.5 * (i as f64 * 0.07).sin())
            .collect()
    }

    #[test]
    fn patterns_follow_eq_5_and_the_ten_operator_reading() {
        assert_eq!(dead_zone_pattern::<6>(), SIX_DEAD_ZONE_PATTERN);
        assert_eq!(dead_zone_pattern::<10>(), TEN_DEAD_ZONE_PATTERN);
        assert_eq!(TraditionalInversePiParams::<10>::PARAMETER_COUNT, 31);
        assert_eq!(TraditionalInversePiParams::<6>::PARAMETER_COUNT, 27);
    }

    #[test]
    fn u1max_for_six_operators_matches_piezo_models() {
        let ws = [1.0, -0.7, 0.3, -0.2, 0.5, -0.1];
        let thresholds = SIX_DEAD_ZONE_PATTERN.map(|p| p * 0.8);
        for y_max in [0.5, 3.0, 7.9, 12.2] {
            assert_eq!(
                u1max_for(&ws, &thresholds, y_max),
                u1max_over_range(&ws, 0.8, y_max)
            );
        }
    }

    #[test]
    fn predict_matches_inverse_pi_trajectory() {
        let params = InversePiParams {
            k: [0.01, -0.02, 0.0, 0.03, 0.0, 0.01, 0.0, -0.01, 0.02, 0.0],
            b: [0.9, 0.1, -0.2, 0.05, 0.1, 0.0, 0.2, -0.1, 0.05, 0.02],
            ws: [1.0, 0.2, -0.1, 0.05, 0.0, 0.1],
            c: 1.1,
            u1max: 12.0,
            a: [1e-4, -0.01, 0.3, 0.2],
            rest_cycle: 0.0,
        };
        let y = sine(500);
        let direct = inverse_pi_trajectory(&params, &y, 1e-3);
        let streamed = predict(&mut ModifiedInversePi::new(params), &y, 1e-3);
        assert_eq!(direct, streamed);
    }

    #[test]
    fn traditional_model_with_unit_weight_is_the_backlash_chain() {
        // w_s = [1, 0, …]: z = y; one unit-weight operator with r = 0 is u = y.
        let mut b = [0.0; BACKLASH_OPERATORS];
        b[0] = 1.0;
        let mut ws = [0.0; 10];
        ws[0] = 1.0;
        let params = TraditionalInversePiParams {
            k: [0.0; BACKLASH_OPERATORS],
            b,
            ws,
            c: 1.0,
            u1max: 10.0,
        };
        let y = sine(300);
        let u = predict(&mut TraditionalInversePi::new(params), &y, 1e-3);
        assert_eq!(u, y);
    }

    #[test]
    fn classical_model_follows_eq_1_per_operator() {
        let mut weights = [0.0; CLASSICAL_OPERATORS];
        weights[3] = 2.0;
        let params = ClassicalPiParams {
            weights,
            thresholds: ClassicalPiParams::evenly_spaced_thresholds(10.0),
            offset: 0.5,
        };
        assert_eq!(params.thresholds[3], 1.5);
        let params = ClassicalPiParams {
            thresholds: ClassicalPiParams::evenly_spaced_thresholds(20.0),
            ..params
        };
        assert_eq!(params.thresholds[3], 3.0);
        let u = predict(&mut ClassicalPi::new(params), &[1.0, 5.0, 4.0, -2.0], 1.0);
        // Backlash with r = 3 from memory 0: 0, 2, 2 (inside the play), then
        // dragged down to −2 + 3 = 1.
        assert_eq!(u, vec![0.5, 4.5, 4.5, 2.5]);
    }
}
