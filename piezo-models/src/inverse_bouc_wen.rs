//! Seed 001's inverse-model feedforward (eq. 6) and its model-based
//! decoupling (eq. 7-16), for the XY axes of either stage.
//!
//! # Inverse model, eq. (6)
//!
//! Seed 001 writes the inverse as v = y_r/p − q·h, with h the state of the
//! model; the inverse of eq. (4)'s y = p·v + q·h is v = (y_r − q·h)/p, so
//! the printed q·h lacks its 1/p. And h itself moves with v, so taken sample
//! by sample that formula uses a state one sample old. Here eq. (6) is solved exactly instead: v is the
//! input for which the forward model, advanced from its current state along
//! the straight path to v, outputs y_r (p·v + q·h(v) = y_r). The forward map
//! is increasing along a branch (dy/du = p + q·dh/du > 0 for any loop a
//! piezo draws), so a safeguarded Newton iteration, with dy/du from eq. (3)
//! and bisection whenever a Newton step leaves the bracket, finds it in two
//! or three steps at 10 kHz. `solve` leaves the state alone; `commit`
//! advances it to the command actually applied (after feedback and
//! limiting), so the model follows the actuator, not the feedforward alone.
//!
//! # Model-based decoupling, eq. (7)-(16)
//!
//! D_x = H_XX[v_x] + H_XY[v_y] (eq. 8). Eq. (9)-(10) add to v_x the voltage
//! v_xy = H_XX⁻¹ H_XY[v_y]; with the printed plus sign that doubles the
//! coupled displacement, and §4's text compensates it "by applying an
//! opposite driving voltage", so the sign is read as a minus. Through the
//! inverse feedforward that is the same as asking H_XX⁻¹ for
//! u_x − H_XY[v_y] instead of u_x. So the decoupling here is a correction of the references
//! (as seed 000's eq. 11 is), and it works with either feedforward: the
//! [`CouplingEstimator`] runs H_XY and H_YX forward on the applied commands
//! and gives the coupled displacements to subtract. Each estimate uses the
//! other axis's command of the previous sample (Jacobi: v_y(t) is not known
//! when v_x(t) is computed, and the reverse): one sample late, 100 µs at
//! 10 kHz against seed 001's 2 Hz signals.
//!
//! On the 3-DOF stage the x pair plays X: H_XX is the model of each of PZT2
//! and PZT3, H_YX is driven by the pair's mean command, H_XY (PZT1 into x)
//! is subtracted from both x_r2 and x_r3; the rotation coupling of PZT1 is
//! not modelled by seed 001 and stays to the feedback.

use crate::parameter::Range;
use serde::{Deserialize, Serialize};

use crate::bouc_wen::{AsymmetricBoucWen, BoucWenParams};

/// Newton iterations at most per solve (two or three suffice; the cap
/// bounds the work of a pathological parameter set).
const MAX_ITERATIONS: usize = 40;

/// |y(v) − y_r| accepted as solved, relative to 1 + |y_r| [µm].
const RELATIVE_TOLERANCE: f64 = 1e-12;

/// The four Bouc-Wen models of seed 001's controller, inputs in command volts
/// (the controller's outputs), outputs in µm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoucWenModels {
    /// H_XX: one x-pair channel's command → x (PZT2 and PZT3 each).
    pub x: BoucWenParams,
    /// H_YY: PZT1's command → y.
    pub y: BoucWenParams,
    /// H_XY: PZT1's command → x (the coupling of eq. 8).
    pub x_from_y: BoucWenParams,
    /// H_YX: the x pair's mean command → y.
    pub y_from_x: BoucWenParams,
    /// The working loop the actuators rest on, in command volts: every model
    /// starts at the 0 V end of its loop between 0 and this command
    /// (`AsymmetricBoucWen::at_exercised_rest`), as the plant's stacks rest
    /// after being operated. 0: seed 001's virgin state h = 0.
    #[serde(default)]
    pub rest_cycle: f64,
    /// Every model closes its minor loops with a return-point memory
    /// (`bouc_wen::ReturnPointMemory`), as the plant's stacks do with its
    /// `return_point_memory`: the inverse then follows a stage whose small
    /// loops close, which eq. (3) alone does not (its minor loops drift).
    /// `false`: seed 001's eq. (3) as integrated.
    #[serde(default)]
    pub return_point_memory: bool,
}

impl BoucWenModels {
    /// 0: the virgin state; a working loop's amplitude otherwise [V].
    pub const REST_CYCLE: Range = Range::NON_NEGATIVE;
}

/// Eq. (6), solved exactly (module comment).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InverseBoucWen {
    model: AsymmetricBoucWen,
    /// Input substep of the state integration [V].
    max_du: f64,
}

impl InverseBoucWen {
    /// At rest (v = 0, h at the rest of the loop to `rest_cycle`, 0 for a
    /// virgin model), with a return-point memory where `memory` is set;
    /// `max_du` as for `AsymmetricBoucWen::advance_to`.
    pub fn new(params: BoucWenParams, rest_cycle: f64, memory: bool, max_du: f64) -> Self {
        InverseBoucWen {
            model: forward_model(params, rest_cycle, memory),
            max_du,
        }
    }

    pub fn params(&self) -> &BoucWenParams {
        self.model.params()
    }

    /// Takes `from`'s point, keeping this model's parameters, rest and
    /// substep ([`crate::restore`]).
    fn carry_point(&mut self, from: &Self) {
        self.model.carry_point(&from.model);
    }

    /// The model's output at its current state [µm].
    pub fn output(&self) -> f64 {
        self.model.output()
    }

    /// The input v [V] that brings the model's output to `y_r` [µm] from its
    /// current state; the state does not move (see [`commit`](Self::commit)).
    pub fn solve(&self, y_r: f64) -> f64 {
        let u0 = self.model.input();
        let y0 = self.model.output();
        let tolerance = RELATIVE_TOLERANCE * (1.0 + y_r.abs());
        if !y_r.is_finite() || (y_r - y0).abs() <= tolerance {
            return if y_r.is_finite() { u0 } else { f64::NAN };
        }
        let direction = (y_r - y0).signum();
        // The first step uses the slope at the start; a non-positive slope
        // (no loop of a real piezo has one) falls back to p.
        let fallback = self.params().p.abs().max(f64::MIN_POSITIVE);
        let slope = self.model.output_slope(direction);
        let slope = if slope > 0.0 { slope } else { fallback };
        let (mut lo, mut hi) = if direction > 0.0 {
            (u0, f64::INFINITY)
        } else {
            (f64::NEG_INFINITY, u0)
        };
        let mut v = u0 + (y_r - y0) / slope;
        let mut best = (f64::INFINITY, v);
        for _ in 0..MAX_ITERATIONS {
            // The model unmoved: no copy of it (nor of its memory) per trial.
            let (output, slope) = self.model.trial(v, self.max_du);
            let error = output - y_r;
            if error.abs() < best.0 {
                best = (error.abs(), v);
            }
            if error.abs() <= tolerance {
                return v;
            }
            if error > 0.0 {
                hi = hi.min(v);
            } else {
                lo = lo.max(v);
            }
            let newton = v - error / slope;
            v = if slope > 0.0 && newton > lo && newton < hi {
                newton
            } else if lo.is_finite() && hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                // Not bracketed yet: step on with the fallback slope.
                v - error / fallback
            };
        }
        best.1
    }

    /// Advances the state to the applied input `v` [V].
    pub fn commit(&mut self, v: f64) {
        self.model.advance_to(v, self.max_du);
    }

    pub fn reset(&mut self) {
        self.model.reset();
    }
}

/// A model at the rest of the loop to `rest_cycle` (0: virgin), with a
/// return-point memory where `memory` is set.
fn forward_model(params: BoucWenParams, rest_cycle: f64, memory: bool) -> AsymmetricBoucWen {
    let model = AsymmetricBoucWen::at_exercised_rest(params, rest_cycle);
    if memory {
        model.with_return_point_memory(rest_cycle)
    } else {
        model
    }
}

/// H_XY and H_YX run forward on the applied commands (module comment).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CouplingEstimator {
    x_from_y: AsymmetricBoucWen,
    y_from_x: AsymmetricBoucWen,
    max_du: f64,
}

/// Coupled displacements estimated from the commands applied so far [µm].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CouplingEstimate {
    /// H_XY[v_y]: x displacement caused by PZT1.
    pub x_from_y: f64,
    /// H_YX[v_x]: y displacement caused by the x pair.
    pub y_from_x: f64,
}

impl CouplingEstimator {
    pub fn new(models: &BoucWenModels, max_du: f64) -> Self {
        CouplingEstimator {
            x_from_y: forward_model(
                models.x_from_y,
                models.rest_cycle,
                models.return_point_memory,
            ),
            y_from_x: forward_model(
                models.y_from_x,
                models.rest_cycle,
                models.return_point_memory,
            ),
            max_du,
        }
    }

    /// Takes `from`'s model points ([`crate::restore`]).
    pub(crate) fn carry_points(&mut self, from: &Self) {
        self.x_from_y.carry_point(&from.x_from_y);
        self.y_from_x.carry_point(&from.y_from_x);
    }

    /// The models x from y and y from x.
    pub(crate) fn models(&self) -> [&AsymmetricBoucWen; 2] {
        [&self.x_from_y, &self.y_from_x]
    }

    pub fn estimate(&self) -> CouplingEstimate {
        CouplingEstimate {
            x_from_y: self.x_from_y.output(),
            y_from_x: self.y_from_x.output(),
        }
    }

    /// Advances both models with the applied channel commands [u1, u2, u3].
    pub fn commit(&mut self, applied: [f64; 3]) {
        self.x_from_y.advance_to(applied[0], self.max_du);
        self.y_from_x
            .advance_to(0.5 * (applied[1] + applied[2]), self.max_du);
    }

    pub fn reset(&mut self) {
        self.x_from_y.reset();
        self.y_from_x.reset();
    }
}

/// Seed 001's feedforward for the three channels: H_YY⁻¹ for PZT1, H_XX⁻¹
/// for each of PZT2 and PZT3 (own states).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoucWenFeedforward {
    /// PZT1, PZT2, PZT3.
    inverses: [InverseBoucWen; 3],
}

impl BoucWenFeedforward {
    pub fn new(models: &BoucWenModels, max_du: f64) -> Self {
        BoucWenFeedforward {
            inverses: [models.y, models.x, models.x].map(|p| {
                InverseBoucWen::new(p, models.rest_cycle, models.return_point_memory, max_du)
            }),
        }
    }

    /// Takes `from`'s model points ([`crate::restore`]).
    pub(crate) fn carry_points(&mut self, from: &Self) {
        for (inverse, own) in self.inverses.iter_mut().zip(&from.inverses) {
            inverse.carry_point(own);
        }
    }

    /// The forward models of PZT1, PZT2, PZT3 the inverses solve.
    pub(crate) fn models(&self) -> [&AsymmetricBoucWen; 3] {
        self.inverses.each_ref().map(|inverse| &inverse.model)
    }

    /// Commands [V] for the channel references [y_r, x_r2, x_r3] [µm].
    pub fn commands(&self, references: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|c| self.inverses[c].solve(references[c]))
    }

    /// Advances every channel's state to its applied command.
    pub fn commit(&mut self, applied: [f64; 3]) {
        for (inverse, v) in self.inverses.iter_mut().zip(applied) {
            inverse.commit(v);
        }
    }

    pub fn reset(&mut self) {
        for inverse in &mut self.inverses {
            inverse.reset();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bouc_wen::SIMULATE_MAX_DU;

    fn piezo() -> BoucWenParams {
        // FlexureStage's PZT1 in command volts (gain 10 folded in).
        BoucWenParams {
            p: 1.30951,
            q: -0.873006,
            a: 0.245,
            beta: 0.5,
            gamma: 0.05,
            n: 1.0,
            delta: 0.04,
        }
    }

    /// Eq. (6) composed with eq. (3)-(4) is the identity: a forward model
    /// driven by the inverse's commands outputs the demanded trajectory,
    /// reversals and minor loops included, to 1e-9 µm.
    #[test]
    fn inverse_then_forward_is_the_identity() {
        for params in [
            piezo(),
            BoucWenParams {
                n: 1.7,
                gamma: -0.1,
                delta: -0.02,
                ..piezo()
            },
        ] {
            let mut inverse = InverseBoucWen::new(params, 0.0, false, SIMULATE_MAX_DU);
            let mut forward = AsymmetricBoucWen::new(params);
            for i in 0..20_000 {
                let t = i as f64 * 1e-4;
                let y_r = 6.0
                    + 5.0 * (2.0 * std::f64::consts::PI * t).sin()
                    + 0.8 * (2.0 * std::f64::consts::PI * 7.0 * t).sin();
                follow(&mut inverse, &mut forward, y_r, t);
            }
        }
    }

    /// One sample of eq. (6): the inverse's command for `y_r`, applied to
    /// both models, and the forward model's output at `y_r` to 1e-9 µm.
    fn follow(inverse: &mut InverseBoucWen, forward: &mut AsymmetricBoucWen, y_r: f64, t: f64) {
        let v = inverse.solve(y_r);
        inverse.commit(v);
        forward.advance_to(v, SIMULATE_MAX_DU);
        assert!(
            (forward.output() - y_r).abs() < 1e-9,
            "t = {t}: {} vs {y_r}",
            forward.output()
        );
    }

    /// The same with the return-point memory on both sides, from the
    /// exercised rest: a demand whose minor loops close and are wiped out
    /// (nested excursions, then one past them all). The inverse's trials
    /// leave its memory alone: it holds the forward model's reversals.
    #[test]
    fn inverse_then_forward_is_the_identity_with_the_memory() {
        let rest_cycle = 10.0;
        let mut inverse = InverseBoucWen::new(piezo(), rest_cycle, true, SIMULATE_MAX_DU);
        let mut forward = AsymmetricBoucWen::at_exercised_rest(piezo(), rest_cycle)
            .with_return_point_memory(rest_cycle);
        let mut deepest = 0;
        for i in 0..30_000 {
            let t = i as f64 * 1e-4;
            let y_r = 6.0 * (1.0 - (std::f64::consts::PI * t / 3.0).cos()).min(1.5)
                + 1.5
                    * (2.0 * std::f64::consts::PI * t).sin()
                    * (std::f64::consts::PI * t / 3.0).sin();
            follow(&mut inverse, &mut forward, y_r, t);
            let reversals = forward.return_point_memory().unwrap().reversals();
            assert_eq!(
                inverse.model.return_point_memory().unwrap().reversals(),
                reversals
            );
            deepest = deepest.max(reversals.len());
        }
        assert!(deepest >= 4, "nested loops: {deepest} reversals at most");
    }

    /// `trial` is `advance_to` on a copy, bit for bit (the output; the slope
    /// too without the memory), on inputs that turn, wipe out and run past
    /// the rest cycle.
    #[test]
    fn a_trial_is_an_advance_on_a_copy() {
        let rest_cycle = 10.0;
        let plain = AsymmetricBoucWen::at_exercised_rest(piezo(), rest_cycle);
        let remembering = plain.clone().with_return_point_memory(rest_cycle);
        for mut model in [plain, remembering] {
            for (k, u) in [3.0, 1.0, 2.5, 1.5, 2.0, 4.0, 11.0, -1.0, 0.5, 0.5]
                .into_iter()
                .enumerate()
            {
                for probe in [u - 0.7, u + 0.3, u, 12.0, -2.0] {
                    let mut copy = model.clone();
                    copy.advance_to(probe, SIMULATE_MAX_DU);
                    let (output, slope) = model.trial(probe, SIMULATE_MAX_DU);
                    assert_eq!(output.to_bits(), copy.output().to_bits(), "{k}: {probe} V");
                    let direction = probe - model.input();
                    if direction != 0.0 {
                        // With a tilt, the copy's slope recovers the untilted
                        // state from h (a rounding apart).
                        let expected = copy.output_slope(direction);
                        if model.return_point_memory().is_none() {
                            assert_eq!(slope.to_bits(), expected.to_bits());
                        } else {
                            assert!((slope - expected).abs() <= 1e-12 * expected.abs());
                        }
                    }
                }
                model.advance_to(u, SIMULATE_MAX_DU);
            }
        }
    }

    #[test]
    fn solve_does_not_move_the_state_and_a_held_demand_holds_the_command() {
        let mut inverse = InverseBoucWen::new(piezo(), 0.0, false, SIMULATE_MAX_DU);
        let v = inverse.solve(4.0);
        assert_eq!(inverse.output(), 0.0);
        inverse.commit(v);
        assert_eq!(inverse.solve(4.0), v);
        assert!(inverse.solve(f64::NAN).is_nan());
    }

    #[test]
    fn the_estimator_follows_the_forward_coupling_models() {
        let models = BoucWenModels {
            x: piezo(),
            y: piezo(),
            x_from_y: BoucWenParams {
                p: 0.3,
                q: -1.0,
                ..piezo()
            },
            y_from_x: BoucWenParams {
                p: 0.2,
                q: -0.5,
                ..piezo()
            },
            rest_cycle: 0.0,
            return_point_memory: false,
        };
        let mut estimator = CouplingEstimator::new(&models, SIMULATE_MAX_DU);
        estimator.commit([4.0, 2.0, 6.0]);
        let mut x_from_y = AsymmetricBoucWen::new(models.x_from_y);
        x_from_y.advance_to(4.0, SIMULATE_MAX_DU);
        let mut y_from_x = AsymmetricBoucWen::new(models.y_from_x);
        y_from_x.advance_to(4.0, SIMULATE_MAX_DU);
        assert_eq!(
            estimator.estimate(),
            CouplingEstimate {
                x_from_y: x_from_y.output(),
                y_from_x: y_from_x.output()
            }
        );
    }
}
