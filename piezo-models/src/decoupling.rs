//! Seed 000's decoupling law, eq. (11) and Table 2: piecewise-linear
//! compensations added to the inputs of the inverse models of the non-driven
//! axes.
//!
//! ```text
//! x_r2 = x_d2 + D1(Δk1·y_d + Δb1)      x_r3 = x_d3 + D2(Δk2·y_d + Δb2)
//! y_rx = y_d + D3(Δk3·x_d + Δb3)       y_rθ = y_d + D4(Δk4·θ_zd + Δb4)
//! D_i(f) = clamp(f, q_i, p_i),  x_d = (x_d2 + x_d3)/2,  θ_zd = (x_d2 − x_d3)/L
//! ```
//!
//! Readings of the printed law:
//! - The y inverse model gets both y compensations: y_r = y_d + D3(…) + D4(…)
//!   = y_rx + y_rθ − y_d.
//! - Table 2 prints q_1 = 10 with p_1 = 2.05, a lower cutoff above the upper
//!   one; since "a value of ±10 means the cutoff is not used", q_1 is read as
//!   −10.
//! - θ_zd enters D4 in microradians. Table 2 does not say; the unit is read
//!   from the printed numbers. Over eq. (16)'s rotation (±9.2×10⁻³ deg =
//!   ±160.6 µrad) Δk4 = −0.75×10⁻² and Δb4 = 0.87 then give D4 from 2.07 µm
//!   down to its printed lower cutoff q4 = −0.18 µm (which holds 16 % of the
//!   cycle), a 2.25 µm span against Table 3's 1.68 µm y-from-rotation
//!   coupling, which the law cuts to 0.37 µm. In millidegrees, the unit of
//!   eq. (16) itself, D4 would span 0.14 µm and never reach q4, and no other
//!   term of the law moves with θ_zd: the printed law could not make Table 3's
//!   cut. The `stage` preset, fitted on this plant by the paper's procedure,
//!   agrees: Δk4 = −0.0048 µm/µrad, 0.63 times the printed value (the other
//!   three slopes are within 2.1 times Table 2's).

use serde::{Deserialize, Serialize};

/// Δk, Δb, p, q of the four compensations (Table 2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecouplingParams {
    pub dk: [f64; 4],
    pub db: [f64; 4],
    /// Upper cutoffs [µm].
    pub p: [f64; 4],
    /// Lower cutoffs [µm].
    pub q: [f64; 4],
}

impl DecouplingParams {
    /// Table 2 as printed, with q_1 read as −10 (see the module doc).
    pub fn paper() -> Self {
        DecouplingParams {
            dk: [0.38, 0.31, -0.20, -0.75e-2],
            db: [-0.38, -0.70, 1.50, 0.87],
            p: [2.05, 10.0, 0.27, 10.0],
            q: [-10.0, -10.0, -10.0, -0.18],
        }
    }
}

/// The references after compensation (eq. 11) [µm].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DecoupledReferences {
    pub x_r2: f64,
    pub x_r3: f64,
    pub y_rx: f64,
    pub y_rtheta: f64,
}

impl DecoupledReferences {
    /// What the y inverse model receives: both y compensations.
    pub fn y_r(&self, y_d: f64) -> f64 {
        self.y_rx + self.y_rtheta - y_d
    }
}

/// D_i(f) = clamp(f, q_i, p_i). Written with max/min rather than `clamp` so
/// that inconsistent cutoffs (q > p) saturate at p instead of panicking.
fn cutoff(f: f64, p: f64, q: f64) -> f64 {
    f.max(q).min(p)
}

/// The rotation demand θ_zd in the unit D4 takes (µrad), from radians.
pub fn rotation_demand(theta_zd_rad: f64) -> f64 {
    theta_zd_rad * 1e6
}

/// eq. (11): demanded displacements of the x actuators `x_d2`, `x_d3` and of y
/// `y_d` [µm], sensor spacing L [mm].
pub fn decouple(
    params: &DecouplingParams,
    x_d2: f64,
    x_d3: f64,
    y_d: f64,
    sensor_spacing_mm: f64,
) -> DecoupledReferences {
    let x_d = 0.5 * (x_d2 + x_d3);
    let theta_zd_rad = (x_d2 - x_d3) / (sensor_spacing_mm * 1e3);
    let theta_zd = rotation_demand(theta_zd_rad);
    let d = |i: usize, f: f64| cutoff(params.dk[i] * f + params.db[i], params.p[i], params.q[i]);
    DecoupledReferences {
        x_r2: x_d2 + d(0, y_d),
        x_r3: x_d3 + d(1, y_d),
        y_rx: y_d + d(2, x_d),
        y_rtheta: y_d + d(3, theta_zd),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const L_MM: f64 = 73.5;

    #[test]
    fn compensations_follow_eq_11_inside_the_cutoffs() {
        let p = DecouplingParams::paper();
        // y_d = 3 µm, x pair at 5 µm, no rotation: D1 = 0.38·3 − 0.38 = 0.76,
        // D2 = 0.31·3 − 0.70 = 0.23, D3 = −0.20·5 + 1.50 = 0.5 cut to p3 = 0.27,
        // D4 = 0.87 (inside [q4, p4] = [−0.18, 10]).
        let r = decouple(&p, 5.0, 5.0, 3.0, L_MM);
        assert!((r.x_r2 - 5.76).abs() < 1e-12, "{r:?}");
        assert!((r.x_r3 - 5.23).abs() < 1e-12, "{r:?}");
        assert!((r.y_rx - 3.27).abs() < 1e-12, "{r:?}");
        assert!((r.y_rtheta - 3.87).abs() < 1e-12, "{r:?}");
        assert!((r.y_r(3.0) - (3.0 + 0.27 + 0.87)).abs() < 1e-12);
    }

    #[test]
    fn every_compensation_saturates_at_its_cutoffs() {
        let p = DecouplingParams::paper();
        // Large y: D1 saturates at p1 = 2.05.
        let r = decouple(&p, 0.0, 0.0, 100.0, L_MM);
        assert!((r.x_r2 - 2.05).abs() < 1e-12);
        // Large x: D3 = −0.2·x + 1.5 falls to the lower cutoff q3 = −10.
        let r = decouple(&p, 100.0, 100.0, 0.0, L_MM);
        assert!((r.y_rx - (-10.0)).abs() < 1e-12);
        // Large positive rotation: D4 = −0.0075·θ + 0.87 falls to q4 = −0.18
        // from θ_zd = 140 µrad.
        let differential = 200e-6 * L_MM * 1e3; // θ_zd = 200 µrad
        let r = decouple(&p, differential / 2.0, -differential / 2.0, 0.0, L_MM);
        assert!((r.y_rtheta - (-0.18)).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn rotation_enters_in_microradians() {
        let p = DecouplingParams {
            dk: [0.0, 0.0, 0.0, 0.01],
            db: [0.0; 4],
            p: [10.0; 4],
            q: [-10.0; 4],
        };
        // 9.2e-3 deg (eq. 16's amplitude) = 160.57 µrad: D4 = 0.01 · 160.57.
        let differential = 9.2e-3_f64.to_radians() * L_MM * 1e3;
        let r = decouple(
            &p,
            6.0 + differential / 2.0,
            6.0 - differential / 2.0,
            0.0,
            L_MM,
        );
        let expected = 0.01 * 9.2e-3_f64.to_radians() * 1e6;
        assert!((expected - 1.6057).abs() < 1e-4);
        assert!((r.y_rtheta - expected).abs() < 1e-9, "{r:?}");
    }
}
