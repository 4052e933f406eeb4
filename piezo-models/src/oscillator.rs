//! Lightly damped structural modes, propagated exactly.
//!
//! Each degree of freedom of the stage is one second-order mode
//! q̈ + 2ζω·q̇ + ω²·q = ω²·f(s), driven by its quasi-static pose f. The stage
//! feeds it forcings made of a constant plus decaying exponentials, whose
//! particular solutions are known in closed form ([`exponential_gain`]); the
//! remaining free response is an exact damped oscillation. Nothing is
//! discretised, so the result does not depend on the interval length.

use crate::parameter::{Bound, Range};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// One structural mode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModeParams {
    /// Undamped natural frequency f = ω/2π [Hz].
    pub frequency_hz: f64,
    /// Damping ratio ζ, 0 < ζ < 1 [1].
    pub damping_ratio: f64,
}

impl ModeParams {
    pub const FREQUENCY_HZ: Range = Range::POSITIVE;
    /// Underdamped, 0 < ζ < 1: the closed-form free response is the damped
    /// oscillation (ζ = 0 never settles, ζ = 1 has no damped frequency).
    pub const DAMPING_RATIO: Range = Range {
        min: Bound::Open(0.0),
        max: Bound::Open(1.0),
    };
}

/// The three in-plane modes of the stage.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModeSet {
    pub x: ModeParams,
    pub y: ModeParams,
    pub theta: ModeParams,
}

/// Position and velocity of a mode (or of a particular solution) at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModalPoint {
    pub position: f64,
    pub velocity: f64,
}

/// [`Oscillator`]'s cached interval length before any interval.
const NO_CACHED_DT: f64 = -1.0;

/// A damped second-order mode with its state and a cache of the free-response
/// transition for the last interval length.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Oscillator {
    /// ω [rad/s].
    omega: f64,
    zeta: f64,
    /// Damped frequency ω_d = ω·sqrt(1 − ζ²) [rad/s].
    omega_d: f64,
    state: ModalPoint,
    /// Interval length the cached transition belongs to; negative: none yet.
    cached_dt: f64,
    /// Free-response transition matrix over `cached_dt`, row-major.
    transition: [f64; 4],
}

impl Oscillator {
    /// A mode at rest. The parameters must satisfy 0 < ζ < 1 and f > 0
    /// (checked by the stage's parameter validation).
    pub fn new(params: &ModeParams) -> Self {
        let omega = TAU * params.frequency_hz;
        let zeta = params.damping_ratio;
        Self {
            omega,
            zeta,
            omega_d: omega * (1.0 - zeta * zeta).sqrt(),
            state: ModalPoint::default(),
            cached_dt: NO_CACHED_DT,
            transition: [1.0, 0.0, 0.0, 1.0],
        }
    }

    pub fn state(&self) -> ModalPoint {
        self.state
    }

    pub fn position(&self) -> f64 {
        self.state.position
    }

    /// ω [rad/s].
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// ζ [1].
    pub fn damping_ratio(&self) -> f64 {
        self.zeta
    }

    /// Sets position and velocity (a continuous-state integrator owns them).
    pub fn set_state(&mut self, state: ModalPoint) {
        self.state = state;
    }

    /// Takes `from`'s state, keeping this mode's parameters; its cache is
    /// recomputed for the interval length `from` cached, so that the mode is
    /// the same value as `from` would be with this mode's parameters
    /// ([`crate::restore`]).
    pub(crate) fn carry_state(&mut self, from: &Self) {
        self.state = from.state;
        if from.cached_dt != NO_CACHED_DT {
            self.transition = self.free_transition(from.cached_dt);
            self.cached_dt = from.cached_dt;
        }
    }

    /// (q̇, q̈) of q̈ + 2ζω q̇ + ω² q = ω² f at the current state for the
    /// forcing `f`: the right-hand side a time-domain integrator needs.
    pub fn rate(&self, forcing: f64) -> ModalPoint {
        let ModalPoint { position, velocity } = self.state;
        ModalPoint {
            position: velocity,
            velocity: self.omega * (self.omega * (forcing - position) - 2.0 * self.zeta * velocity),
        }
    }

    /// The particular-solution gain for the forcing term a·e^{−λs}: the mode
    /// follows K·e^{−λs} with K = g·a, g = ω²/(λ² − 2ζωλ + ω²). The denominator
    /// is (λ − ζω)² + ω²(1 − ζ²) > 0, so g is finite for every λ when ζ < 1.
    pub fn exponential_gain(&self, rate: f64) -> f64 {
        let w2 = self.omega * self.omega;
        w2 / (rate * rate - 2.0 * self.zeta * self.omega * rate + w2)
    }

    /// Advances the mode over an interval of length `dt` on which a particular
    /// solution of the forced equation is known at both ends (`start`, `end`).
    /// The deviation from it is a free damped oscillation, propagated exactly:
    /// e(s) = e^{−ζωs}[e₀ cos ω_d s + (ė₀ + ζω e₀)/ω_d · sin ω_d s].
    pub fn propagate(&mut self, dt: f64, start: ModalPoint, end: ModalPoint) {
        if dt != self.cached_dt {
            self.transition = self.free_transition(dt);
            self.cached_dt = dt;
        }
        let [p11, p12, p21, p22] = self.transition;
        let e0 = self.state.position - start.position;
        let v0 = self.state.velocity - start.velocity;
        self.state = ModalPoint {
            position: end.position + p11 * e0 + p12 * v0,
            velocity: end.velocity + p21 * e0 + p22 * v0,
        };
    }

    fn free_transition(&self, dt: f64) -> [f64; 4] {
        let decay = (-self.zeta * self.omega * dt).exp();
        let (sin, cos) = (self.omega_d * dt).sin_cos();
        let zw_over_wd = self.zeta * self.omega / self.omega_d;
        [
            decay * (cos + zw_over_wd * sin),
            decay * sin / self.omega_d,
            -decay * self.omega * self.omega / self.omega_d * sin,
            decay * (cos - zw_over_wd * sin),
        ]
    }
}

/// The particular solution at the start and the end of an interval of length s
/// for the forcing f(σ) = c + Σ_k a_k·e^{−λ_k σ}: q_p = c + Σ_k g_k a_k e^{−λ_k σ}
/// (g_k from [`Oscillator::exponential_gain`]); `decays[k]` = e^{−λ_k s}.
pub fn exponential_particular<const K: usize>(
    constant: f64,
    amplitudes: &[f64; K],
    gains: &[f64; K],
    rates: &[f64; K],
    decays: &[f64; K],
) -> (ModalPoint, ModalPoint) {
    let mut start = ModalPoint {
        position: constant,
        velocity: 0.0,
    };
    let mut end = start;
    for k in 0..K {
        let amplitude = gains[k] * amplitudes[k];
        start.position += amplitude;
        start.velocity -= rates[k] * amplitude;
        end.position += amplitude * decays[k];
        end.velocity -= rates[k] * amplitude * decays[k];
    }
    (start, end)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode() -> Oscillator {
        Oscillator::new(&ModeParams {
            frequency_hz: 790.0,
            damping_ratio: 0.02,
        })
    }

    /// Unit step forcing from rest: q(t) = 1 − e^{−ζωt}(cos ω_d t + ζω/ω_d sin ω_d t).
    #[test]
    fn step_response_matches_closed_form() {
        let mut m = mode();
        let fixed = ModalPoint {
            position: 1.0,
            velocity: 0.0,
        };
        let (w, z) = (m.omega, m.zeta);
        let wd = w * (1.0 - z * z).sqrt();
        for k in 1..=2000 {
            m.propagate(1e-5, fixed, fixed);
            let t = k as f64 * 1e-5;
            let exact = 1.0 - (-z * w * t).exp() * ((wd * t).cos() + z * w / wd * (wd * t).sin());
            // Repeated multiplication by a cached 2×2 matrix: roundoff grows ~k·ε.
            assert!((m.position() - exact).abs() < 1e-12, "t = {t}");
        }
    }

    /// Exponential forcing e^{−λs}: the closed-form particular solution plus the
    /// exact free response must not depend on how the interval is split.
    #[test]
    fn exponential_forcing_is_split_independent() {
        let rate = 1.0 / 53e-6;
        let run = |pieces: usize| {
            let mut m = mode();
            let gain = m.exponential_gain(rate);
            let total = 1e-3;
            let dt = total / pieces as f64;
            for i in 0..pieces {
                // The forcing seen from the start of piece i is 2·e^{−λ(s + i·dt)}.
                let amplitude = 2.0 * (-rate * dt * i as f64).exp();
                let (start, end) = exponential_particular(
                    0.5,
                    &[amplitude],
                    &[gain],
                    &[rate],
                    &[(-rate * dt).exp()],
                );
                m.propagate(dt, start, end);
            }
            m.state()
        };
        let one = run(1);
        let many = run(37);
        assert!((one.position - many.position).abs() < 1e-12);
        assert!((one.velocity - many.velocity).abs() < 1e-12 * mode().omega);
    }

    #[test]
    fn particular_gain_is_one_for_slow_forcing_and_peaks_near_resonance() {
        let m = mode();
        assert!((m.exponential_gain(0.0) - 1.0).abs() < 1e-15);
        // Slow forcing: g = 1 + 2ζλ/ω + O((λ/ω)²), here (λ/ω)² ≈ 4e-8.
        let slow = m.exponential_gain(1.0) - 1.0;
        assert!((slow - 2.0 * m.zeta / m.omega).abs() < 1e-7);
        // λ = ζω maximises the gain at 1/(1 − ζ²).
        let peak = m.exponential_gain(m.zeta * m.omega);
        assert!((peak - 1.0 / (1.0 - m.zeta * m.zeta)).abs() < 1e-12);
    }
}
