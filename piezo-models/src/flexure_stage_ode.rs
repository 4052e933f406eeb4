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
//! with 19 states in [`STATES`] order. With `return_point_memory = true`,
//! dh/du is that of the model's current branch: eq. (3) at the branch's
//! untilted state h − c·(V − V_b), plus its tilt c (MODEL.md §6), where the
//! memory (its reversals and the direction of the last motion) is discrete
//! state. What matters to an integrator:
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
//! - **ḣ is not smooth where eq. (3)'s state crosses 0**: |h|ⁿ and |h|ⁿ⁻¹·h
//!   switch branch there. For n = 1 (seed 000's actuators) the slope of ḣ
//!   in h jumps by 2γ·V̇, in the middle of a slew where V̇ is large; for
//!   n > 1 a higher derivative jumps. The stage starts at its exercised rest
//!   (h < 0), so every step of the voltage from rest drives each h through
//!   0. A BDF solver at tight tolerance spends hundreds of steps on such a
//!   kink (CVode at relative tolerance 1e-11 exceeded its 500 steps per
//!   output interval on the three actuator kinks of one 0→50/30/70 V step).
//!   So the 7 branch states are the first 7
//!   [`switching_functions`](FlexureStage::switching_functions): a solver
//!   with root finding stops there and restarts. Nothing changes at such an
//!   event.
//! - **The return-point memory changes at two kinds of event** per Bouc-Wen
//!   model, its other 14 switching functions: where the voltage turns (V_t − V
//!   changes sign against the last motion: the turn is remembered, and the
//!   branch that leaves it gets its tilt) and where it reaches the reversal
//!   the branch closes onto (both are forgotten and the older branch goes on:
//!   a wipe-out, which sets h onto that branch, so the importer must read the
//!   states again). The event update [`FlexureStage::settle_memories`] does
//!   what [`FlexureStage::step`] does at the same points; without the memory
//!   these functions are −1 and never fire.

//! Sensor noise is a sample drawn per communication step, which a
//! continuous-time model does not have; the sensors here read the pose.

use super::{
    ACTUATOR_STATES, AMPLIFIER_STATES, COUPLING_DRIVER, COUPLING_STATES, CREEP_STATES,
    FlexureStage, FlexureStageParams, MODE_POSITIONS, MODE_VELOCITIES, StateFault,
};
use crate::bouc_wen::{AsymmetricBoucWen, BoucWenParams};
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

/// Number of Bouc-Wen models: 3 actuators and 4 couplings.
const HYSTERESIS_MODELS: usize = 7;

/// Number of switching functions (module comment): three per Bouc-Wen model,
/// its branch's state and the return-point memory's two events.
pub const NUMBER_OF_SWITCHING_FUNCTIONS: usize = 3 * HYSTERESIS_MODELS;

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
        let voltages = self.amplifier.voltages();
        let voltage_rates = self.approach(commands).map(|gap| gap / self.tau);
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

    /// V_t − V per channel [V]: what each amplifier voltage still has to go
    /// to its target under `commands`, of the sign of V̇. Through the
    /// amplifier's own target, so that its limits are the ones the step uses.
    fn approach(&self, commands: [f64; 3]) -> [f64; 3] {
        let amplifier = &self.params.amplifier;
        let voltages = self.amplifier.voltages();
        std::array::from_fn(|i| amplifier.target(commands[i]).0 - voltages[i])
    }

    /// The 7 Bouc-Wen models, PZT1..PZT3 then the couplings x←1, rot←1,
    /// y←2, y←3, each with the channel that drives it.
    fn hysteresis_models(&self) -> impl Iterator<Item = (&AsymmetricBoucWen, usize)> {
        let channels = [0, 1, 2].into_iter().chain(COUPLING_DRIVER);
        self.actuators.iter().chain(&self.couplings).zip(channels)
    }

    /// The switching functions (module comment) under `commands`, for the 7
    /// Bouc-Wen models in the order of [`STATES`] (PZT1..PZT3, then the
    /// couplings x←1, rot←1, y←2, y←3):
    ///
    /// - `[0..7]`: each model's eq. (3) state on its branch [µm] (the
    ///   hysteretic state, less the branch's tilt with a return-point memory):
    ///   where one changes sign, ḣ changes form;
    /// - `[7..14]`: where each model's input turns, and `[14..21]`: where it
    ///   reaches the reversal its branch closes onto [V] (the return-point
    ///   memory's events, [`AsymmetricBoucWen::memory_event_functions`];
    ///   −1 throughout with `return_point_memory = false`).
    ///
    /// At a crossing of the last two kinds an event update
    /// ([`FlexureStage::settle_memories`]) changes the memory.
    pub fn switching_functions(&self, commands: [f64; 3]) -> [f64; NUMBER_OF_SWITCHING_FUNCTIONS] {
        let mut g = [0.0; NUMBER_OF_SWITCHING_FUNCTIONS];
        let approach = self.approach(commands);
        for (k, (model, channel)) in self.hysteresis_models().enumerate() {
            let [turn, wipe_out] = model.memory_event_functions(approach[channel]);
            g[k] = model.branch_state();
            g[HYSTERESIS_MODELS + k] = turn;
            g[2 * HYSTERESIS_MODELS + k] = wipe_out;
        }
        g
    }

    /// The event update of Model Exchange under `commands`: every Bouc-Wen
    /// model's return-point memory settled at the current point
    /// ([`AsymmetricBoucWen::settle_memory`]; nothing with
    /// `return_point_memory = false`). Returns whether a continuous state
    /// changed (a wipe-out puts a hysteretic state on the branch it
    /// continues). Allocates nothing.
    pub fn settle_memories(&mut self, commands: [f64; 3]) -> bool {
        let approach = self.approach(commands);
        let max_du = self.max_du;
        let mut changed = false;
        for (model, channel) in self.actuators.iter_mut().zip([0, 1, 2]) {
            changed |= model.settle_memory(approach[channel], max_du);
        }
        for (model, channel) in self.couplings.iter_mut().zip(COUPLING_DRIVER) {
            changed |= model.settle_memory(approach[channel], max_du);
        }
        changed
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
    /// With `memory_events`, the return-point memory is settled at the
    /// commands' jump and at every located crossing, as an importer's event
    /// updates do; returns the number of updates that moved a state (the
    /// wipe-outs).
    fn integrate(
        stage: &mut FlexureStage,
        commands: [f64; 3],
        h: f64,
        steps: usize,
        memory_events: bool,
    ) -> usize {
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
            probe.switching_functions(commands)
        };
        // FMI 2.0's reading of a crossing: a change between z > 0 and z <= 0.
        let crosses =
            |g0: &[f64], g1: &[f64]| g0.iter().zip(g1).any(|(a, b)| (*a > 0.0) != (*b > 0.0));
        let mut wipe_outs = 0;
        let mut settle = |stage: &mut FlexureStage| {
            if memory_events && stage.settle_memories(commands) {
                wipe_outs += 1;
            }
        };
        // An importer's event at the commands' jump (an input event).
        settle(stage);
        for _ in 0..steps {
            let mut left = h;
            while left > 0.0 {
                let x0 = stage.continuous_states();
                let g0 = stage.switching_functions(commands);
                let mut x1 = rk4(stage, &x0, left);
                let mut taken = left;
                let crossed = crosses(&g0, &switching(stage, &x1));
                if crossed {
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
                if crossed {
                    // The event update at the located crossing (also one
                    // located at the step's end).
                    settle(stage);
                }
                left -= taken;
            }
        }
        wipe_outs
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
        // Without the memory the continuous states are the whole state (with
        // it, the memory is discrete state the states do not carry).
        let params = FlexureStageParams::without_memory();
        let stage = moving(&params);
        let x = stage.continuous_states();
        assert!(x.iter().all(|v| *v != 0.0), "every state moves: {x:?}");
        let mut copy = FlexureStage::new(params).unwrap();
        copy.set_continuous_states(&x);
        assert_eq!(copy.continuous_states(), x);
        assert_eq!(copy.pose(), stage.pose());
        assert_eq!(copy.sensors(), stage.sensors());
        assert_eq!(copy.actuator_extensions(), stage.actuator_extensions());
        assert_eq!(copy.derivatives([3.0; 3]), stage.derivatives([3.0; 3]));
        let g = copy.switching_functions([3.0; 3]);
        assert_eq!(g[..3], x[ACTUATORS..ACTUATORS + 3]);
        assert_eq!(g[3..7], x[COUPLINGS..COUPLINGS + 4]);
        assert_eq!(g[7..], [-1.0; 14], "no memory, no memory events");
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
        integrate(&mut by_ode, commands, 2e-7, 5000, true);
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

    /// With the return-point memory, the ODE with its event updates (turns
    /// remembered, wipe-outs taken where the located crossings are) and
    /// `FlexureStage::step` trace the same minor loops: 12 ms of commands held
    /// 1 ms each, from rest, that turn every channel 11 times and carry it
    /// past earlier reversals (wipe-outs inside a hold), on the tracking
    /// parameter set. Tolerance as in the memory-free test above: the memory
    /// adds no approximation of its own to either (the step takes a wipe-out
    /// at the exact voltage inside its chord, the ODE at the located zero).
    #[test]
    fn the_ode_with_its_events_and_the_step_trace_the_same_minor_loops() {
        let params = FlexureStageParams {
            solver: SolverParams {
                max_voltage_step: 1e-3,
            },
            ..FlexureStageParams::default()
        };
        assert!(params.return_point_memory);
        let holds: [[f64; 3]; 12] = [
            [5.0, 3.0, 7.0],
            [2.0, 1.0, 4.0],
            [4.0, 2.5, 6.0],
            [1.0, 0.5, 3.0],
            [6.0, 4.0, 8.0],
            [3.0, 2.0, 5.0],
            [3.5, 2.2, 5.5],
            [-0.2, -0.1, 1.0],
            [0.5, 0.4, 2.0],
            [0.0, 0.0, 0.0],
            [9.0, 7.0, 10.0],
            [4.0, 3.0, 6.0],
        ];
        let mut by_step = FlexureStage::new(params.clone()).unwrap();
        let mut by_ode = by_step.clone();
        let mut without_events = by_step.clone();
        let mut wipe_outs = 0;
        for commands in holds {
            for _ in 0..10 {
                by_step.step(commands, 1e-4);
            }
            wipe_outs += integrate(&mut by_ode, commands, 2e-7, 5000, true);
            integrate(&mut without_events, commands, 2e-7, 5000, false);
        }
        assert!(
            wipe_outs >= 10,
            "the holds carry the models past their reversals: {wipe_outs} wipe-outs"
        );
        let nominal = state_nominals(&params);
        let worst = |other: &FlexureStage| {
            let (a, b) = (by_step.continuous_states(), other.continuous_states());
            (0..NUMBER_OF_STATES)
                .map(|k| ((a[k] - b[k]).abs() / nominal[k], STATES[k], a[k], b[k]))
                .fold((0.0, "", 0.0, 0.0), |m, e| if e.0 > m.0 { e } else { m })
        };
        let (error, state, a, b) = worst(&by_ode);
        assert!(
            error <= 1e-9,
            "{state}: step {a} vs ode {b}, {error:e} of its nominal"
        );
        // Without the event updates the ODE runs every branch from the rest
        // loop's memory: the check above would fail by orders of magnitude.
        let (error, state, ..) = worst(&without_events);
        assert!(error > 1e-4, "{state}: {error:e} of its nominal");
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
