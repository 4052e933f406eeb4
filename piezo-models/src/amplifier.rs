//! The piezo amplifier: three identical channels, each a gain with output
//! limits followed by a first-order lag.
//!
//! Seed 000 §3.2: the command is "amplified by a piezoelectric amplifier with a
//! gain of 10"; its amplifier is a PI E-505. A first-order lag is what a
//! current-limited linear amplifier driving a capacitive stack looks like in the
//! small-signal range: V̇ = 2π·f_a·(V_t − V), with V_t = clamp(G·u, v_min, v_max).
//! The lower limit is 0 V because the stacks cannot retract (seed 000 §3.2).

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
    /// Lowest output voltage [V].
    pub v_min: f64,
    /// Highest output voltage [V].
    pub v_max: f64,
}

impl AmplifierParams {
    /// τ = 1/(2π f_a) [s].
    pub fn time_constant(&self) -> f64 {
        1.0 / (TAU * self.bandwidth_hz)
    }

    /// The target voltage V_t = clamp(G·u, v_min, v_max) of one channel and
    /// whether the limits cut it. A NaN command gives a NaN target (not clipped):
    /// nothing is rejected here, the stage reports a non-finite state instead.
    pub fn target(&self, command: f64) -> (f64, bool) {
        let wanted = self.gain * command;
        let target = wanted.clamp(self.v_min, self.v_max);
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
            v_min: 0.0,
            v_max: 100.0,
        }
    }

    #[test]
    fn targets_are_clamped_and_reported() {
        let amp = Amplifier::new(params());
        let (t, c) = amp.targets([-1.0, 5.0, 12.0]);
        assert_eq!(t, [0.0, 50.0, 100.0]);
        assert_eq!(c, [true, false, true]);
        let (t, c) = amp.targets([0.0, 10.0, f64::INFINITY]);
        assert_eq!(t, [0.0, 100.0, 100.0]);
        assert_eq!(c, [false, false, true]);
        let (t, c) = amp.targets([f64::NAN, 1.0, 1.0]);
        assert!(t[0].is_nan());
        assert!(!c[0]);
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
