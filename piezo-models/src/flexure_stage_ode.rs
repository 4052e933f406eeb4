//! The stage of [`FlexureStage`] as a system of ordinary differential
//! equations in time, x' = f(x, u), for an integrator that is not
//! [`FlexureStage::step`]: a model-exchange importer's variable-step solver.
//!
//! The equations are those of MODEL.md §2, each written as a rate:
//!
//! ```text
//! V̇_i = (V_t,i − V_i)/τ,        V_t,i = clamp(G·u_i, v_min, v_max)
//! ḣ   = (dh/du)(V, h, sgn V̇)·V̇  for each Bouc-Wen model (seed 001 eq. 3), u its voltage
//! ċ_i = (κ_i·V_i − c_i)/T_i
//! q̇   = v,   v̇ = ω²(q_qs − q) − 2ζω·v   for q ∈ {x, y, θ}, q_qs from seed 000 §2
//! ```
//!
//! with 19 states in [`STATES`] order. Two properties matter to an integrator:
//!
//! - **The right-hand side is continuous** in the states and the inputs. The
//!   amplifier's clipping acts on the target V_t, a function of the input u
//!   alone, continuous in it (a clamp) and constant while u is: no state
//!   crosses a switching surface, so no state event is needed. When an
//!   importer changes u by a jump, that is its own (input) event.
//! - **The hysteresis is rate independent**: every term of ḣ is proportional
//!   to V̇, so sgn V̇ switches the slope only where the product is 0. The rate
//!   is continuous (Lipschitz) across a voltage reversal; only its derivative
//!   jumps there, and by little, since V̇ itself is 0 at the reversal. A
//!   variable-step solver meets it with a smaller step. With inputs held
//!   between samples, V approaches its target exponentially and never
//!   reverses within a sample.
//! - **ḣ is not smooth where h crosses 0**: |h|ⁿ and |h|ⁿ⁻¹·h switch branch
//!   there. For n = 1 (seed 000's actuators) the slope of ḣ in h jumps by
//!   2γ·V̇, in the middle of a slew where V̇ is large; for n > 1 a higher
//!   derivative jumps. The
//!   stage starts at its exercised rest (h < 0), so every step of the
//!   voltage from rest drives each h through 0. A BDF solver at tight
//!   tolerance spends hundreds of steps on such a kink (CVode at relative
//!   tolerance 1e-11 exceeded its 500 steps per output interval on the
//!   three actuator kinks of one 0→50/30/70 V step). So the 7 hysteretic
//!   states are the [`switching_functions`](FlexureStage::switching_functions):
//!   a solver with root finding stops at h = 0 and restarts there. Nothing
//!   changes at the event; the model has no discrete state.
//!
//! Sensor noise is a sample drawn per communication step, which a
//! continuous-time model does not have; the sensors here read the pose.

use super::{
    ACTUATOR_STATES, AMPLIFIER_STATES, COUPLING_DRIVER, COUPLING_STATES, CREEP_STATES,
    FlexureStage, FlexureStageParams, MODE_POSITIONS, MODE_VELOCITIES, StateFault,
};
use crate::bouc_wen::BoucWenParams;
use crate::oscillator::ModalPoint;

/// Number of continuous states.
pub const NUMBER_OF_STATES: usize = 19;

/// What each entry of the state vector is, in order: amplifier voltages V1..V3
/// [V]; hysteretic states of PZT1..PZT3 and of the couplings x←1, rot←1, y←2,
/// y←3 [µm]; creep c1..c3 [µm]; positions x [µm], y [µm], θ [rad]; their
/// velocities [µm/s, µm/s, rad/s].
pub const STATES: [&str; NUMBER_OF_STATES] = [
    AMPLIFIER_STATES[0],
    AMPLIFIER_STATES[1],
    AMPLIFIER_STATES[2],
    ACTUATOR_STATES[0],
    ACTUATOR_STATES[1],
    ACTUATOR_STATES[2],
    COUPLING_STATES[0],
    COUPLING_STATES[1],
    COUPLING_STATES[2],
    COUPLING_STATES[3],
    CREEP_STATES[0],
    CREEP_STATES[1],
    CREEP_STATES[2],
    MODE_POSITIONS[0],
    MODE_POSITIONS[1],
    MODE_POSITIONS[2],
    MODE_VELOCITIES[0],
    MODE_VELOCITIES[1],
    MODE_VELOCITIES[2],
];

/// Number of switching functions (the hysteretic states, module comment):
/// 3 actuators and 4 couplings.
pub const NUMBER_OF_SWITCHING_FUNCTIONS: usize = 7;

/// Index of the first amplifier voltage, hysteretic state, creep, position and
/// velocity in the state vector.
const VOLTAGES: usize = 0;
const ACTUATORS: usize = 3;
const COUPLINGS: usize = 6;
const CREEP: usize = 10;
const POSITIONS: usize = 13;
const VELOCITIES: usize = 16;

impl FlexureStage {
    /// The continuous states, in [`STATES`] order.
    pub fn continuous_states(&self) -> [f64; NUMBER_OF_STATES] {
        let mut x = [0.0; NUMBER_OF_STATES];
        x[VOLTAGES..VOLTAGES + 3].copy_from_slice(&self.amplifier.voltages());
        for i in 0..3 {
            x[ACTUATORS + i] = self.actuators[i].hysteretic_state();
            x[CREEP + i] = self.creep[i].value();
            let mode = self.modes[i].state();
            x[POSITIONS + i] = mode.position;
            x[VELOCITIES + i] = mode.velocity;
        }
        for k in 0..4 {
            x[COUPLINGS + k] = self.couplings[k].hysteretic_state();
        }
        x
    }

    /// Makes `x` (in [`STATES`] order) the stage's state: every Bouc-Wen
    /// model's input becomes the voltage that drives it. Outputs, sensors and
    /// [`FlexureStage::derivatives`] then describe this state.
    pub fn set_continuous_states(&mut self, x: &[f64; NUMBER_OF_STATES]) {
        let voltages = [x[VOLTAGES], x[VOLTAGES + 1], x[VOLTAGES + 2]];
        self.amplifier.set_voltages(voltages);
        for i in 0..3 {
            self.actuators[i].set_point(voltages[i], x[ACTUATORS + i]);
            self.creep[i].set_value(x[CREEP + i]);
            self.modes[i].set_state(ModalPoint {
                position: x[POSITIONS + i],
                velocity: x[VELOCITIES + i],
            });
        }
        for k in 0..4 {
            self.couplings[k].set_point(voltages[COUPLING_DRIVER[k]], x[COUPLINGS + k]);
        }
    }

    /// The time derivatives of the states (in [`STATES`] order) with the
    /// amplifier commands `commands` (volts before the amplifier). Allocates
    /// nothing.
    pub fn derivatives(&self, commands: [f64; 3]) -> [f64; NUMBER_OF_STATES] {
        let mut dx = [0.0; NUMBER_OF_STATES];
        let amplifier = &self.params.amplifier;
        let voltages = self.amplifier.voltages();
        let mut voltage_rates = [0.0; 3];
        for i in 0..3 {
            // Through the amplifier's own target, so that its limits are the
            // ones the step uses.
            let (target, _) = amplifier.target(commands[i]);
            voltage_rates[i] = (target - voltages[i]) / self.tau;
        }
        dx[VOLTAGES..VOLTAGES + 3].copy_from_slice(&voltage_rates);
        let mut extension = [0.0; 3];
        for i in 0..3 {
            let actuator = &self.actuators[i];
            dx[ACTUATORS + i] = actuator.state_rate(voltage_rates[i]);
            dx[CREEP + i] = self.creep[i].rate(voltages[i]);
            extension[i] = actuator.output() + self.creep[i].value();
        }
        let mut coupled = [0.0; 4];
        for (k, model) in self.couplings.iter().enumerate() {
            dx[COUPLINGS + k] = model.state_rate(voltage_rates[COUPLING_DRIVER[k]]);
            coupled[k] = model.output();
        }
        let [x_from_1, rot_from_1, y_from_2, y_from_3] = coupled;
        // Quasi-static pose, seed 000 §2 (as in `FlexureStage::step`).
        let forcing = [
            0.5 * (extension[1] + extension[2]) + x_from_1,
            extension[0] + y_from_2 + y_from_3,
            (extension[1] - extension[2] + rot_from_1) / self.spacing_um,
        ];
        for m in 0..3 {
            let rate = self.modes[m].rate(forcing[m]);
            dx[POSITIONS + m] = rate.position;
            dx[VELOCITIES + m] = rate.velocity;
        }
        dx
    }

    /// The switching functions (module comment): the hysteretic states of
    /// PZT1..PZT3 and of the couplings x←1, rot←1, y←2, y←3 [µm], in
    /// [`STATES`] order. Where one changes sign, ḣ changes branch.
    pub fn switching_functions(&self) -> [f64; NUMBER_OF_SWITCHING_FUNCTIONS] {
        let mut g = [0.0; NUMBER_OF_SWITCHING_FUNCTIONS];
        let models = self.actuators.iter().chain(&self.couplings);
        for (value, model) in g.iter_mut().zip(models) {
            *value = model.hysteretic_state();
        }
        g
    }

    /// The first state that is non-finite or beyond the divergence bounds
    /// (see [`StepReport::fault`](super::StepReport::fault)), `None` for a
    /// sound state.
    pub fn check_state(&self) -> Option<StateFault> {
        self.state_fault()
    }
}

/// Nominal magnitude of each state (in [`STATES`] order) for the parameters:
/// the scale an integrator's absolute tolerance should be relative to. Each is
/// a bound on what the state reaches over the actuator voltage range, from
/// the parameters alone: voltages max(|v_min|, |v_max|); a hysteretic state
/// the smaller of its growth over the range and its saturation level
/// ((|A| + |δ|·V)/(β + γ))^(1/n); creep κ·V; positions from the quasi-static
/// pose of those magnitudes; velocities ω times their position. A magnitude
/// that comes out zero or non-finite (a creep gain of 0, parameters not yet
/// validated) is 1.
pub fn state_nominals(params: &FlexureStageParams) -> [f64; NUMBER_OF_STATES] {
    let amplifier = &params.amplifier;
    let v_max = amplifier.v_min.abs().max(amplifier.v_max.abs());
    let travel = (amplifier.v_max - amplifier.v_min).abs();
    let hysteretic = |p: &BoucWenParams| {
        let growth = (p.a.abs() + p.delta.abs() * v_max) * travel;
        let shape = p.beta + p.gamma;
        let saturation = if shape > 0.0 && p.n >= 1.0 {
            ((p.a.abs() + p.delta.abs() * v_max) / shape).powf(1.0 / p.n)
        } else {
            f64::INFINITY
        };
        growth.min(saturation)
    };
    let output = |p: &BoucWenParams| p.p.abs() * v_max + p.q.abs() * hysteretic(p);
    let mut n = [0.0; NUMBER_OF_STATES];
    let mut extension = [0.0; 3];
    for (i, actuator) in params.actuators.iter().enumerate() {
        n[VOLTAGES + i] = v_max;
        n[ACTUATORS + i] = hysteretic(&actuator.hysteresis);
        n[CREEP + i] = actuator.creep_gain.abs() * v_max;
        extension[i] = output(&actuator.hysteresis) + n[CREEP + i];
    }
    let c = &params.coupling;
    let coupling = [c.x_from_pzt1, c.rot_from_pzt1, c.y_from_pzt2, c.y_from_pzt3];
    for (k, model) in coupling.iter().enumerate() {
        n[COUPLINGS + k] = hysteretic(model);
    }
    let spacing_um = params.sensor_spacing_mm * 1e3;
    n[POSITIONS] = 0.5 * (extension[1] + extension[2]) + output(&c.x_from_pzt1);
    n[POSITIONS + 1] = extension[0] + output(&c.y_from_pzt2) + output(&c.y_from_pzt3);
    n[POSITIONS + 2] = (extension[1] + extension[2] + output(&c.rot_from_pzt1)) / spacing_um;
    let modes = [&params.modes.x, &params.modes.y, &params.modes.theta];
    for (m, mode) in modes.iter().enumerate() {
        n[VELOCITIES + m] = std::f64::consts::TAU * mode.frequency_hz * n[POSITIONS + m];
    }
    for value in &mut n {
        if !(value.is_finite() && *value > 0.0) {
            *value = 1.0;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flexure_stage::SolverParams;

    /// Classical RK4 in time on the ODE, `steps` equal steps of `h` with the
    /// commands held. A step across a switching function's zero is split
    /// there, as a solver with root finding does (module comment): the kink
    /// of an n = 1 rate at h = 0 would otherwise cost RK4 its order.
    fn integrate(stage: &mut FlexureStage, commands: [f64; 3], h: f64, steps: usize) {
        let at = |stage: &FlexureStage, x: &[f64; NUMBER_OF_STATES]| {
            let mut probe = stage.clone();
            probe.set_continuous_states(x);
            probe.derivatives(commands)
        };
        let rk4 = |stage: &FlexureStage, x0: &[f64; NUMBER_OF_STATES], h: f64| {
            let add = |a: &[f64; NUMBER_OF_STATES], k: &[f64; NUMBER_OF_STATES], f: f64| {
                let mut out = *a;
                for (o, d) in out.iter_mut().zip(k) {
                    *o += f * d;
                }
                out
            };
            let k1 = at(stage, x0);
            let k2 = at(stage, &add(x0, &k1, 0.5 * h));
            let k3 = at(stage, &add(x0, &k2, 0.5 * h));
            let k4 = at(stage, &add(x0, &k3, h));
            let mut x1 = *x0;
            for i in 0..NUMBER_OF_STATES {
                x1[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            x1
        };
        let switching = |stage: &FlexureStage, x: &[f64; NUMBER_OF_STATES]| {
            let mut probe = stage.clone();
            probe.set_continuous_states(x);
            probe.switching_functions()
        };
        let crosses = |g0: &[f64], g1: &[f64]| g0.iter().zip(g1).any(|(a, b)| a * b < 0.0);
        for _ in 0..steps {
            let mut left = h;
            while left > 0.0 {
                let x0 = stage.continuous_states();
                let g0 = stage.switching_functions();
                let mut x1 = rk4(stage, &x0, left);
                let mut taken = left;
                if crosses(&g0, &switching(stage, &x1)) {
                    // Bisection to the first zero, to a few ulps of the step.
                    let (mut lo, mut hi) = (0.0, left);
                    for _ in 0..60 {
                        let mid = 0.5 * (lo + hi);
                        if crosses(&g0, &switching(stage, &rk4(stage, &x0, mid))) {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    taken = hi;
                    x1 = rk4(stage, &x0, taken);
                }
                stage.set_continuous_states(&x1);
                left -= taken;
            }
        }
    }

    /// A stage moving in every state: 30 ms of a three-phase ramp from rest.
    fn moving(params: &FlexureStageParams) -> FlexureStage {
        let mut stage = FlexureStage::new(params.clone()).unwrap();
        for k in 0..300 {
            let t = k as f64 * 1e-4;
            stage.step(
                [0, 1, 2].map(|i| 2.0 + 100.0 * t + 1.5 * (300.0 * t + i as f64).sin()),
                1e-4,
            );
        }
        stage
    }

    #[test]
    fn states_round_trip_and_set_the_outputs() {
        let stage = moving(&FlexureStageParams::default());
        let x = stage.continuous_states();
        assert!(x.iter().all(|v| *v != 0.0), "every state moves: {x:?}");
        let mut copy = FlexureStage::new(FlexureStageParams::default()).unwrap();
        copy.set_continuous_states(&x);
        assert_eq!(copy.continuous_states(), x);
        assert_eq!(copy.pose(), stage.pose());
        assert_eq!(copy.sensors(), stage.sensors());
        assert_eq!(copy.actuator_extensions(), stage.actuator_extensions());
        assert_eq!(copy.derivatives([3.0; 3]), stage.derivatives([3.0; 3]));
        let g = copy.switching_functions();
        assert_eq!(g[..3], x[ACTUATORS..ACTUATORS + 3]);
        assert_eq!(g[3..], x[COUPLINGS..COUPLINGS + 4]);
    }

    #[test]
    fn a_stage_at_rest_with_zero_commands_stays_at_rest() {
        let stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
        assert_eq!(stage.derivatives([0.0; 3]), [0.0; NUMBER_OF_STATES]);
    }

    /// The ODE integrated in time (RK4, 0.2 µs steps) and `FlexureStage::step`
    /// (exact linear parts, hysteresis chords of 1 mV) agree on 1 ms after a
    /// command jump from a moving state, through the amplifier's transient
    /// and the modes' ringing. Both approximate the same solution: RK4's error
    /// at this step is ~1e-12 µm, the chord's (1e-3 V)²·|y''|/8 ~ 1e-10 µm.
    #[test]
    fn the_ode_and_the_step_describe_the_same_stage() {
        let params = FlexureStageParams {
            solver: SolverParams {
                max_voltage_step: 1e-3,
            },
            ..FlexureStageParams::default()
        };
        let start = moving(&params);
        let commands = [7.5, 1.0, 11.0]; // the last one clipped
        let mut by_step = start.clone();
        for _ in 0..10 {
            by_step.step(commands, 1e-4);
        }
        let mut by_ode = start.clone();
        integrate(&mut by_ode, commands, 2e-7, 5000);
        let (a, b) = (by_step.continuous_states(), by_ode.continuous_states());
        let nominal = state_nominals(&params);
        for k in 0..NUMBER_OF_STATES {
            assert!(
                (a[k] - b[k]).abs() <= 1e-9 * nominal[k],
                "{}: step {} vs ode {} (nominal {})",
                STATES[k],
                a[k],
                b[k],
                nominal[k]
            );
        }
        let (sa, sb) = (by_step.sensors(), by_ode.sensors());
        for i in 0..3 {
            assert!(
                (sa[i] - sb[i]).abs() < 1e-8,
                "s{}: {} vs {}",
                i + 1,
                sa[i],
                sb[i]
            );
        }
    }

    /// A held input holds every hysteretic state: the rates vanish with V̇
    /// whatever the direction of the last motion.
    #[test]
    fn hysteresis_rates_vanish_with_the_voltage_rate() {
        let stage = moving(&FlexureStageParams::default());
        let mut settled = stage.clone();
        let mut x = settled.continuous_states();
        // Targets equal to the voltages: V̇ = 0.
        let gain = settled.params().amplifier.gain;
        let commands = [x[0] / gain, x[1] / gain, x[2] / gain];
        x[CREEP..CREEP + 3].copy_from_slice(&[0.0; 3]);
        settled.set_continuous_states(&x);
        let dx = settled.derivatives(commands);
        for k in 0..3 {
            assert!(dx[VOLTAGES + k].abs() < 1e-9, "{}", dx[VOLTAGES + k]);
        }
        for k in ACTUATORS..CREEP {
            assert!(dx[k].abs() < 1e-12, "{}: {}", STATES[k], dx[k]);
        }
    }

    #[test]
    fn nominals_are_positive_and_of_the_right_size() {
        for params in [FlexureStageParams::default(), FlexureStageParams::xy200s()] {
            let n = state_nominals(&params);
            assert!(n.iter().all(|v| v.is_finite() && *v > 0.0), "{n:?}");
            assert_eq!(
                n[VOLTAGES],
                params
                    .amplifier
                    .v_max
                    .abs()
                    .max(params.amplifier.v_min.abs())
            );
            // The positions bound the strokes the calibration measures (seed
            // 000: 12.7 µm; XY200S: 150 µm) within a factor of a few.
            let stroke = if params == FlexureStageParams::default() {
                12.7
            } else {
                150.0
            };
            for m in 0..2 {
                let ratio = n[POSITIONS + m] / stroke;
                assert!(
                    (0.5..6.0).contains(&ratio),
                    "{}: {}",
                    STATES[POSITIONS + m],
                    n[POSITIONS + m]
                );
            }
        }
        let mut broken = FlexureStageParams::default();
        broken.actuators[0].creep_gain = 0.0;
        broken.coupling.y_from_pzt2.n = f64::NAN;
        let n = state_nominals(&broken);
        assert!(n.iter().all(|v| v.is_finite() && *v > 0.0), "{n:?}");
    }
}
