//! Creep of a piezo stack: a slow first-order drift towards κ·V.
//!
//! Seed 000 §3.2 names creep as an unmodelled error that the PI feedback has to
//! remove. The simplest model with the right signature is one slow first-order
//! element in series with the hysteresis: ċ = (κ·V − c)/T. Driven by the
//! amplifier's exponential V(s) = V_t + (V_0 − V_t)·e^{−s/τ}, it has the exact
//! solution c(s) = κ·V_t + K·e^{−s/τ} + B·e^{−s/T}, K = κ(V_0 − V_t)·τ/(τ − T),
//! B = c(0) − κ·V_t − K (T ≠ τ; the stage requires T > 10·τ).

use serde::{Deserialize, Serialize};

/// The solution c(s) = steady + amplifier_term·e^{−s/τ} + own_term·e^{−s/T} of
/// the creep element over a stretch of constant amplifier target.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CreepPath {
    /// κ·V_t [µm].
    pub steady: f64,
    /// K, the amplitude of e^{−s/τ} [µm].
    pub amplifier_term: f64,
    /// B, the amplitude of e^{−s/T} [µm].
    pub own_term: f64,
}

/// One creep element.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Creep {
    /// κ [µm/V].
    gain: f64,
    /// T [s].
    time_constant: f64,
    /// c [µm].
    value: f64,
}

impl Creep {
    /// At rest (c = 0).
    pub fn new(gain: f64, time_constant: f64) -> Self {
        Self {
            gain,
            time_constant,
            value: 0.0,
        }
    }

    /// c [µm].
    pub fn value(&self) -> f64 {
        self.value
    }

    /// T [s].
    pub fn time_constant(&self) -> f64 {
        self.time_constant
    }

    /// κ [µm/V].
    pub fn gain(&self) -> f64 {
        self.gain
    }

    /// Sets c (a continuous-state integrator owns it).
    pub fn set_value(&mut self, value: f64) {
        self.value = value;
    }

    /// ċ = (κ·V − c)/T at actuator voltage `voltage` [µm/s].
    pub fn rate(&self, voltage: f64) -> f64 {
        (self.gain * voltage - self.value) / self.time_constant
    }

    /// The exact path from the current value while the voltage relaxes from
    /// `v_start` towards `v_target` with time constant `tau`.
    pub fn path(&self, v_start: f64, v_target: f64, tau: f64) -> CreepPath {
        let steady = self.gain * v_target;
        let amplifier_term = self.gain * (v_start - v_target) * tau / (tau - self.time_constant);
        CreepPath {
            steady,
            amplifier_term,
            own_term: self.value - steady - amplifier_term,
        }
    }

    /// Moves to the end of `path` after a time s, given e^{−s/τ} and e^{−s/T}.
    pub fn follow(&mut self, path: &CreepPath, amplifier_decay: f64, own_decay: f64) {
        self.value =
            path.steady + path.amplifier_term * amplifier_decay + path.own_term * own_decay;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form against a fine RK4 integration of ċ = (κV − c)/T with the
    /// exponential voltage.
    #[test]
    fn exact_path_matches_numerical_integration() {
        let (kappa, t_creep, tau) = (1.2e-3, 1.5, 53e-6);
        let (v0, vt) = (20.0, 80.0);
        let mut creep = Creep::new(kappa, t_creep);
        creep.value = 0.01;
        let path = creep.path(v0, vt, tau);
        let s = 2e-3;
        let mut exact = creep.clone();
        exact.follow(&path, (-s / tau).exp(), (-s / t_creep).exp());

        let rhs = |t: f64, c: f64| (kappa * (vt + (v0 - vt) * (-t / tau).exp()) - c) / t_creep;
        let (mut c, steps) = (0.01, 20_000);
        let dt = s / steps as f64;
        for i in 0..steps {
            let t = i as f64 * dt;
            let k1 = rhs(t, c);
            let k2 = rhs(t + dt / 2.0, c + dt / 2.0 * k1);
            let k3 = rhs(t + dt / 2.0, c + dt / 2.0 * k2);
            let k4 = rhs(t + dt, c + dt * k3);
            c += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
        assert!(
            (exact.value() - c).abs() < 1e-14,
            "{} vs {c}",
            exact.value()
        );
        // Nothing moves instantly: the path starts where the element is.
        assert!((path.steady + path.amplifier_term + path.own_term - 0.01).abs() < 1e-17);
    }

    #[test]
    fn settles_to_gain_times_voltage() {
        let mut creep = Creep::new(1.2e-3, 1.5);
        let path = creep.path(0.0, 100.0, 53e-6);
        creep.follow(&path, 0.0, (-60.0f64 / 1.5).exp());
        assert!((creep.value() - 0.12).abs() < 1e-12);
    }
}
