//! The piezo amplifier: three identical channels, each a gain between an
//! input and an output limit, followed by a first-order lag.
//!
//! Seed 000 §3.2: the command is "amplified by a piezoelectric amplifier with a
//! gain of 10"; its amplifier is a PI E-505.00 (§2). A first-order lag is what
//! a current-limited linear amplifier driving a capacitive stack looks like in
//! the small-signal range: V̇ = 2π·f_a·(V_t − V), with
//! V_t = clamp(G·clamp(u, u_min, u_max), v_min, v_max).
//!
//! The limits are the hardware's, and bipolar: PI's LVPZT amplifiers take a
//! control input of −2..12 V (−3..13 V at most) and the E-505 drives its
//! output from −30 to 130 V. The stacks can be driven below their 0 V rest,
//! which seed 000's own numbers need (MODEL.md §4 gives the sources).

use crate::parameter::Range;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Amplifier parameters, shared by the three channels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AmplifierParams {
    /// Voltage gain G from command to actuator [V/V] (seed 000 §3.2: 10).
    pub gain: f64,
    /// First-order bandwidth f_a [Hz].
    pub bandwidth_hz: f64,
    /// Lowest control input the amplifier follows [V]; below it the input
    /// stage saturates.
    pub input_min: f64,
    /// Highest control input the amplifier follows [V].
    pub input_max: f64,
    /// Lowest output voltage [V].
    pub v_min: f64,
    /// Highest output voltage [V].
    pub v_max: f64,
}

impl AmplifierParams {
    pub const GAIN: Range = Range::POSITIVE;
    pub const BANDWIDTH_HZ: Range = Range::POSITIVE;

    /// τ = 1/(2π f_a) [s].
    pub fn time_constant(&self) -> f64 {
        1.0 / (TAU * self.bandwidth_hz)
    }

    /// The target voltage V_t = clamp(G·clamp(u, u_min, u_max), v_min, v_max)
    /// of one channel and whether a limit cut it. A NaN command gives a NaN
    /// target (not clipped): nothing is rejected here, the stage reports a
    /// non-finite state instead.
    #[inline]
    pub fn target(&self, command: f64) -> (f64, bool) {
        let wanted = self.gain * command;
        let target = (self.gain * command.clamp(self.input_min, self.input_max))
            .clamp(self.v_min, self.v_max);
        (target, target != wanted && !wanted.is_nan())
    }
}

/// Three amplifier channels (PZT1, PZT2, PZT3) and their output voltages.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Amplifier {
    params: AmplifierParams,
    voltages: [f64; 3],
}

impl Amplifier {
    /// All outputs at 0 V.
    pub fn new(params: AmplifierParams) -> Self {
        Self {
            params,
            voltages: [0.0; 3],
        }
    }

    pub fn params(&self) -> &AmplifierParams {
        &self.params
    }

    /// Output voltages [V].
    pub fn voltages(&self) -> [f64; 3] {
        self.voltages
    }

    /// Targets of the three channels for held commands, and which were clipped.
    pub fn targets(&self, commands: [f64; 3]) -> ([f64; 3], [bool; 3]) {
        let mut targets = [0.0; 3];
        let mut clipped = [false; 3];
        for i in 0..3 {
            (targets[i], clipped[i]) = self.params.target(commands[i]);
        }
        (targets, clipped)
    }

    /// Moves every channel along its exact exponential towards `targets` by the
    /// factor `decay` = e^{−s/τ} of the elapsed time s:
    /// V(s) = V_t + (V_0 − V_t)·e^{−s/τ}.
    pub fn relax(&mut self, targets: [f64; 3], decay: f64) {
        for (v, t) in self.voltages.iter_mut().zip(targets) {
            *v = t + (*v - t) * decay;
        }
    }

    /// Sets the three outputs (used when a state is assembled piece by piece).
    pub fn set_voltages(&mut self, voltages: [f64; 3]) {
        self.voltages = voltages;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> AmplifierParams {
        AmplifierParams {
            gain: 10.0,
            bandwidth_hz: 3000.0,
            input_min: -3.0,
            input_max: 13.0,
            v_min: -30.0,
            v_max: 130.0,
        }
    }

    #[test]
    fn targets_are_clamped_and_reported() {
        let amp = Amplifier::new(params());
        let (t, c) = amp.targets([-4.0, 5.0, 14.0]);
        assert_eq!(t, [-30.0, 50.0, 130.0]);
        assert_eq!(c, [true, false, true]);
        let (t, c) = amp.targets([-3.0, 13.0, f64::INFINITY]);
        assert_eq!(t, [-30.0, 130.0, 130.0]);
        assert_eq!(c, [false, false, true]);
        let (t, c) = amp.targets([-1.5, 0.0, 12.0]);
        assert_eq!(t, [-15.0, 0.0, 120.0]);
        assert_eq!(c, [false; 3]);
        let (t, c) = amp.targets([f64::NAN, 1.0, 1.0]);
        assert!(t[0].is_nan());
        assert!(!c[0]);
    }

    /// Whichever limit is the narrower one cuts: the input stage when the
    /// gain is low, the output rails when it is high.
    #[test]
    fn the_narrower_of_input_and_output_limits_cuts() {
        let low_gain = AmplifierParams {
            gain: 5.0,
            ..params()
        };
        assert_eq!(low_gain.target(20.0), (65.0, true));
        assert_eq!(low_gain.target(-20.0), (-15.0, true));
        let high_gain = AmplifierParams {
            gain: 15.0,
            ..params()
        };
        assert_eq!(high_gain.target(12.0), (130.0, true));
        assert_eq!(high_gain.target(-2.5), (-30.0, true));
        assert_eq!(high_gain.target(-1.0), (-15.0, false));
    }

    /// Relaxing by e^{−s1/τ} then e^{−s2/τ} equals relaxing by e^{−(s1+s2)/τ}:
    /// the exponential is exact, so the split does not matter.
    #[test]
    fn relaxation_composes_exactly() {
        let tau = params().time_constant();
        let mut a = Amplifier::new(params());
        let mut b = Amplifier::new(params());
        a.relax([10.0, 50.0, 100.0], (-3e-5 / tau).exp());
        a.relax([10.0, 50.0, 100.0], (-7e-5 / tau).exp());
        b.relax([10.0, 50.0, 100.0], (-1e-4 / tau).exp());
        for (x, y) in a.voltages().iter().zip(b.voltages()) {
            assert!((x - y).abs() < 1e-12);
        }
        assert!(
            (params().time_constant() - 1.0 / (2.0 * std::f64::consts::PI * 3000.0)).abs() < 1e-18
        );
    }
}
