//! The measurement procedures behind the calibration of [`FlexureStage`] to the
//! stage of seed 000 (§2 figures, Table 3 coupling spans), and the figures
//! they must reproduce ([`TARGETS`], the one place they are written).
//!
//! Each procedure drives a fresh stage from rest the way an FMI master would:
//! commands held over fixed steps of [`SAMPLE_PERIOD`] (seed 000's 10 kHz
//! controller), the command of step k being the demand evaluated at the end of
//! that step, t_k = k·SAMPLE_PERIOD, and readings taken from the sensors after
//! each step (x = (s2 + s3)/2, y = s1, θ = (s2 − s3)/L). Every procedure is
//! spelled out in its doc comment and is generic over the [`StageSource`]
//! that makes the stages: the model itself ([`FlexureStageParams`], for the
//! calibration example `examples/calibrate.rs` and this crate's tests), or a
//! FlexureStage FMU loaded by an importer (`piezo-cosim fingerprint`, which
//! the Python tests run), so the same code measures both and this crate
//! stays free of FMI.

use serde::Serialize;

use crate::flexure_stage::{FlexureStage, FlexureStageParams};

/// One stage instance as the procedures drive it: three commands in, three
/// sensor readings out, one fixed step at a time.
pub trait Stage {
    /// What [`Stage::snapshot`] saves: a probe runs from it and comes back.
    type Snapshot;
    /// Holds `commands` [V] over one step of `period` [s].
    fn step(&mut self, commands: [f64; 3], period: f64);
    /// s1, s2, s3 [µm] after the last step.
    fn sensors(&self) -> [f64; 3];
    fn snapshot(&self) -> Self::Snapshot;
    fn restore(&mut self, snapshot: &Self::Snapshot);
}

/// What makes fresh stages at rest (zero commands) to measure.
pub trait StageSource {
    type Stage: Stage;
    fn fresh(&self) -> Self::Stage;
    /// L, the distance between the x sensors s2 and s3 [µm].
    fn sensor_spacing_um(&self) -> f64;
}

impl Stage for FlexureStage {
    type Snapshot = FlexureStage;

    fn step(&mut self, commands: [f64; 3], period: f64) {
        FlexureStage::step(self, commands, period);
    }

    fn sensors(&self) -> [f64; 3] {
        FlexureStage::sensors(self)
    }

    fn snapshot(&self) -> FlexureStage {
        self.clone()
    }

    fn restore(&mut self, snapshot: &FlexureStage) {
        self.clone_from(snapshot);
    }
}

impl StageSource for FlexureStageParams {
    type Stage = FlexureStage;

    fn fresh(&self) -> FlexureStage {
        FlexureStage::new(self.clone()).expect("valid stage parameters")
    }

    fn sensor_spacing_um(&self) -> f64 {
        self.sensor_spacing_mm * 1e3
    }
}

/// Communication step of every procedure except the resonance record [s].
pub const SAMPLE_PERIOD: f64 = 1e-4;
/// Duration of every quasi-static ramp between two command sets [s].
pub const RAMP_TIME: f64 = 1.0;
/// Command of full stroke [V] (100 V after the amplifier gain of 10).
pub const FULL_COMMAND: f64 = 10.0;
/// Seed 000 §2 / Table 3: the driven axis spans 10 µm in the coupling sweeps.
pub const SWEEP_SPAN_UM: f64 = 10.0;
/// Seed 000 §3.2 / eq. (16): rotation sweep amplitude ±9.2e-3°.
pub const ROTATION_SWEEP_AMPLITUDE_DEG: f64 = 9.2e-3;

/// Axis driven in a stroke or loop measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// u2 = u3 driven, x = (s2 + s3)/2 read.
    X,
    /// u1 driven, y = s1 read.
    Y,
}

/// One sample after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Time since the start of the recorded segment (end of the step) [s].
    pub t: f64,
    /// Commands held during the step [V].
    pub commands: [f64; 3],
    /// s1, s2, s3 after the step [µm].
    pub sensors: [f64; 3],
}

/// A stage with its current commands, stepped at a fixed period.
#[derive(Clone)]
pub struct Rig<S: Stage = FlexureStage> {
    stage: S,
    commands: [f64; 3],
    spacing_um: f64,
}

impl<S: Stage> Rig<S> {
    /// A fresh stage of `source` at rest with zero commands.
    pub fn new<P: StageSource<Stage = S>>(source: &P) -> Self {
        Self {
            spacing_um: source.sensor_spacing_um(),
            stage: source.fresh(),
            commands: [0.0; 3],
        }
    }

    pub fn stage(&self) -> &S {
        &self.stage
    }

    /// x = (s2 + s3)/2 [µm].
    pub fn x(&self) -> f64 {
        let s = self.stage.sensors();
        0.5 * (s[1] + s[2])
    }

    /// y = s1 [µm].
    pub fn y(&self) -> f64 {
        self.stage.sensors()[0]
    }

    /// θ = (s2 − s3)/L [rad].
    pub fn theta(&self) -> f64 {
        let s = self.stage.sensors();
        (s[1] - s[2]) / self.spacing_um
    }

    /// θ = (s2 − s3)/L in degrees.
    pub fn theta_deg(&self) -> f64 {
        self.theta().to_degrees()
    }

    /// Runs `duration` seconds in steps of `period`, the commands of step k being
    /// `demand(k·period)`, and records every step.
    pub fn run(
        &mut self,
        duration: f64,
        period: f64,
        demand: impl Fn(f64) -> [f64; 3],
    ) -> Vec<Sample> {
        let steps = (duration / period).round() as usize;
        let mut samples = Vec::with_capacity(steps);
        for k in 1..=steps {
            let t = k as f64 * period;
            self.commands = demand(t);
            self.stage.step(self.commands, period);
            samples.push(Sample {
                t,
                commands: self.commands,
                sensors: self.stage.sensors(),
            });
        }
        samples
    }

    /// Linear ramp from the current commands to `target` over [`RAMP_TIME`] at
    /// [`SAMPLE_PERIOD`] (the last step holds exactly `target`).
    pub fn ramp_to(&mut self, target: [f64; 3]) {
        let start = self.commands;
        self.run(RAMP_TIME, SAMPLE_PERIOD, |t| {
            let f = t / RAMP_TIME;
            [0, 1, 2].map(|i| start[i] + (target[i] - start[i]) * f)
        });
        self.commands = target;
    }

    /// Holds the current commands for `duration` seconds at [`SAMPLE_PERIOD`].
    pub fn hold(&mut self, duration: f64) {
        let held = self.commands;
        self.run(duration, SAMPLE_PERIOD, |_| held);
    }
}

/// Quasi-static stroke of an axis at the full command (seed 000 §2: x 12.74 µm,
/// y 12.22 µm): from rest, the driven command(s) ramp linearly 0 → 10 V over
/// 1 s (10 000 steps of 100 µs) with the other commands at 0; the stroke is the
/// axis reading after the last step.
pub fn stroke<P: StageSource>(plant: &P, axis: Axis) -> f64 {
    let mut rig = Rig::new(plant);
    match axis {
        Axis::X => {
            rig.ramp_to([0.0, FULL_COMMAND, FULL_COMMAND]);
            rig.x()
        }
        Axis::Y => {
            rig.ramp_to([FULL_COMMAND, 0.0, 0.0]);
            rig.y()
        }
    }
}

/// x after ramping u2 = u3 from rest to `u` over 1 s (u1 = 0).
fn x_after_ramp<P: StageSource>(plant: &P, u: f64) -> f64 {
    let mut rig = Rig::new(plant);
    rig.ramp_to([0.0, u, u]);
    rig.x()
}

/// The x home command u_home (seed 000 §3.2: home at half of the x stroke):
/// the u2 = u3 command whose 1 s ramp from rest ends at x = stroke(X)/2,
/// solved to |x − stroke/2| ≤ 1e-9 µm.
pub fn x_home_command<P: StageSource>(plant: &P) -> f64 {
    let half = 0.5 * stroke(plant, Axis::X);
    solve_increasing(|u| x_after_ramp(plant, u) - half, 0.0, FULL_COMMAND, 1e-9)
}

/// A rig at the x home: from rest, u2 = u3 ramped 0 → `u_home` over 1 s, u1 = 0.
pub fn rig_at_x_home<P: StageSource>(plant: &P, u_home: f64) -> Rig<P::Stage> {
    let mut rig = Rig::new(plant);
    rig.ramp_to([0.0, u_home, u_home]);
    rig
}

/// Rotation range (seed 000 §2: 0.0103° anticlockwise, 0.0088° clockwise),
/// returned as (anticlockwise, clockwise) in degrees, both positive.
///
/// From rest: ramp to the x home (0, u_home, u_home); ramp to (0, 10, 0) and
/// read θ⁺; ramp back to (0, u_home, u_home); ramp to (0, 0, 10) and read θ⁻.
/// Every ramp is linear over 1 s; θ = (s2 − s3)/L is measured from the
/// orientation at rest (θ = 0). Anticlockwise = θ⁺, clockwise = −θ⁻.
pub fn rotation_range_deg<P: StageSource>(plant: &P, u_home: f64) -> (f64, f64) {
    let mut rig = rig_at_x_home(plant, u_home);
    rig.ramp_to([0.0, FULL_COMMAND, 0.0]);
    let anticlockwise = rig.theta_deg();
    rig.ramp_to([0.0, u_home, u_home]);
    rig.ramp_to([0.0, 0.0, FULL_COMMAND]);
    (anticlockwise, -rig.theta_deg())
}

/// Step of the differential command in the resonance test [V].
pub const RESONANCE_STEP_COMMAND: f64 = 0.1;
/// Sample period of the resonance record [s].
pub const RESONANCE_SAMPLE_PERIOD: f64 = 1e-5;
/// Length of the resonance record [s].
pub const RESONANCE_RECORD_TIME: f64 = 0.25;

/// θ record of a small rotation step from the x home: rig at the x home, hold
/// 0.5 s (the modes settle), then commands (0, u_home + 0.1, u_home − 0.1)
/// held while θ = (s2 − s3)/L is sampled every 10 µs for 0.25 s (25 000
/// samples, steps of 10 µs).
pub fn rotation_step_record<P: StageSource>(plant: &P, u_home: f64) -> Vec<f64> {
    let mut rig = rig_at_x_home(plant, u_home);
    rig.hold(0.5);
    let held = [
        0.0,
        u_home + RESONANCE_STEP_COMMAND,
        u_home - RESONANCE_STEP_COMMAND,
    ];
    let spacing = rig.spacing_um;
    rig.run(RESONANCE_RECORD_TIME, RESONANCE_SAMPLE_PERIOD, |_| held)
        .iter()
        .map(|s| (s.sensors[1] - s.sensors[2]) / spacing)
        .collect()
}

/// Frequency of the largest peak of |DFT(θ − mean θ)| of `record` (sampled at
/// `period`), scanned from 300 Hz to 2000 Hz every 0.5 Hz (a direct DFT, so
/// the resolution is not limited to 1/record length).
pub fn spectral_peak_hz(record: &[f64], period: f64) -> f64 {
    let mean = record.iter().sum::<f64>() / record.len() as f64;
    let mut best = (0.0, f64::NEG_INFINITY);
    let mut f = 300.0;
    while f <= 2000.0 {
        // Rotating phasor: e^{−j2πf·k·period} by repeated multiplication.
        let (step_im, step_re) = (-std::f64::consts::TAU * f * period).sin_cos();
        let (mut re, mut im) = (1.0, 0.0);
        let (mut sum_re, mut sum_im) = (0.0, 0.0);
        for &v in record {
            sum_re += (v - mean) * re;
            sum_im += (v - mean) * im;
            (re, im) = (re * step_re - im * step_im, re * step_im + im * step_re);
        }
        let magnitude = sum_re * sum_re + sum_im * sum_im;
        if magnitude > best.1 {
            best = (f, magnitude);
        }
        f += 0.5;
    }
    best.0
}

/// θ resonance (seed 000 §2: 790 Hz): [`spectral_peak_hz`] of
/// [`rotation_step_record`].
pub fn theta_resonance_hz<P: StageSource>(plant: &P, u_home: f64) -> f64 {
    spectral_peak_hz(
        &rotation_step_record(plant, u_home),
        RESONANCE_SAMPLE_PERIOD,
    )
}

/// Shape of a hysteresis loop over one cycle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LoopShape {
    /// max − min of the output over the cycle [µm].
    pub span_um: f64,
    /// Largest |w(u)|, w = descending − ascending branch at the same input [µm].
    pub max_width_um: f64,
    /// max_width / span.
    pub width_ratio: f64,
    /// max over d of |w(c + d) − w(c − d)| / max|w|, c the mid input
    /// (0 for a loop point-symmetric about its centre).
    pub asymmetry: f64,
}

/// Loop width w(u) = y_desc(u) − y_asc(u) of one cycle that runs from a minimum
/// of `input` through its maximum back to a minimum, evaluated by linear
/// interpolation on each branch at the 19 inputs u_min + j·(u_max − u_min)/20,
/// j = 1..19. Returns (u, w) pairs.
pub fn loop_widths(input: &[f64], output: &[f64]) -> Vec<(f64, f64)> {
    let (ascending, descending) = branches(input, output);
    let lo = input.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = input.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (1..20)
        .map(|j| {
            let u = lo + (hi - lo) * j as f64 / 20.0;
            (u, interpolate(&descending, u) - interpolate(&ascending, u))
        })
        .collect()
}

/// One branch of a loop: (input, output) points sorted by increasing input.
pub type Branch = Vec<(f64, f64)>;

/// The two branches of one min → max → min cycle, (ascending, descending),
/// split at the maximum of `input`.
pub fn branches(input: &[f64], output: &[f64]) -> (Branch, Branch) {
    let top = argmax(input);
    let ascending = (0..=top).map(|k| (input[k], output[k])).collect();
    let descending = (top..input.len())
        .rev()
        .map(|k| (input[k], output[k]))
        .collect();
    (ascending, descending)
}

/// Loop shape of (input, output) over one min → max → min cycle.
pub fn loop_shape(input: &[f64], output: &[f64]) -> LoopShape {
    let widths = loop_widths(input, output);
    let span = span(output);
    let max_width = widths.iter().map(|w| w.1.abs()).fold(0.0, f64::max);
    let n = widths.len();
    let asymmetry = (0..n / 2)
        .map(|j| (widths[j].1 - widths[n - 1 - j].1).abs())
        .fold(0.0, f64::max)
        / max_width;
    LoopShape {
        span_um: span,
        max_width_um: max_width,
        width_ratio: max_width / span,
        asymmetry,
    }
}

/// Open-loop major loop of an axis (u1 → y, or u2 = u3 → x), 0 → 10 → 0 V at
/// 1 Hz after one preconditioning cycle: from rest, the driven command(s)
/// follow u(t) = 5·(1 − cos 2πt) V for t ∈ (0, 2] s (others 0); the loop is
/// the axis reading versus the command over the second cycle, t ∈ [1, 2] s.
pub fn major_loop<P: StageSource>(plant: &P, axis: Axis) -> LoopShape {
    let mut rig = Rig::new(plant);
    let wave = |t: f64| 0.5 * FULL_COMMAND * (1.0 - (std::f64::consts::TAU * t).cos());
    let samples = rig.run(2.0, SAMPLE_PERIOD, |t| match axis {
        Axis::X => [0.0, wave(t), wave(t)],
        Axis::Y => [wave(t), 0.0, 0.0],
    });
    let cycle = window(&samples, 1.0, 2.0);
    let channel = if axis == Axis::X { 1 } else { 0 };
    let input: Vec<f64> = cycle.iter().map(|s| s.commands[channel]).collect();
    let output: Vec<f64> = cycle
        .iter()
        .map(|s| match axis {
            Axis::X => 0.5 * (s.sensors[1] + s.sensors[2]),
            Axis::Y => s.sensors[0],
        })
        .collect();
    loop_shape(&input, &output)
}

/// A coupled displacement recorded in one of the coupling sweeps.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Coupling {
    /// Span (max − min) of the coupled displacement over the measured cycle [µm].
    pub span_um: f64,
    /// Largest loop width of the coupled displacement versus the driving
    /// command, divided by its span.
    pub width_ratio: f64,
}

/// The four couplings of seed 000 Table 3 (without decoupling).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CouplingSweeps {
    /// Command amplitude a of the y sweep u1 = a(1 − cos 2πt)/2 [V].
    pub y_sweep_amplitude: f64,
    /// Command amplitude a of the x sweep u2 = u3 = a(1 − cos 2πt)/2 [V].
    pub x_sweep_amplitude: f64,
    /// Differential amplitude D of the rotation sweep [V].
    pub rotation_sweep_amplitude: f64,
    /// s2 during the y sweep (target span 2.2065 µm).
    pub s2_from_y: Coupling,
    /// s3 during the y sweep (target span 2.7435 µm).
    pub s3_from_y: Coupling,
    /// y during the x sweep (target span 1.2482 µm).
    pub y_from_x: Coupling,
    /// y during the rotation sweep (target span 1.6784 µm).
    pub y_from_rotation: Coupling,
}

/// y sweep: from rest, ramp to the x home; then u1 = a·(1 − cos 2πt)/2 for
/// t ∈ (0, 2] s with u2 = u3 = u_home; measured cycle t ∈ [1, 2] s.
fn y_sweep<P: StageSource>(plant: &P, u_home: f64, a: f64) -> Vec<Sample> {
    let mut rig = rig_at_x_home(plant, u_home);
    let samples = rig.run(2.0, SAMPLE_PERIOD, |t| {
        [
            0.5 * a * (1.0 - (std::f64::consts::TAU * t).cos()),
            u_home,
            u_home,
        ]
    });
    window(&samples, 1.0, 2.0)
}

/// x sweep: from rest, u2 = u3 = a·(1 − cos 2πt)/2 for t ∈ (0, 2] s with
/// u1 = 0 (the y home); measured cycle t ∈ [1, 2] s.
fn x_sweep<P: StageSource>(plant: &P, a: f64) -> Vec<Sample> {
    let mut rig = Rig::new(plant);
    let samples = rig.run(2.0, SAMPLE_PERIOD, |t| {
        let u = 0.5 * a * (1.0 - (std::f64::consts::TAU * t).cos());
        [0.0, u, u]
    });
    window(&samples, 1.0, 2.0)
}

/// Rotation sweep: from rest, ramp to the x home; then u2 = u_home + D sin 2πt,
/// u3 = u_home − D sin 2πt for t ∈ (0, 2.75] s with u1 = 0; measured cycle
/// t ∈ [1.75, 2.75] s (minimum to minimum of the differential command).
fn rotation_sweep<P: StageSource>(plant: &P, u_home: f64, d: f64) -> Vec<Sample> {
    let mut rig = rig_at_x_home(plant, u_home);
    let samples = rig.run(2.75, SAMPLE_PERIOD, |t| {
        let s = d * (std::f64::consts::TAU * t).sin();
        [0.0, u_home + s, u_home - s]
    });
    window(&samples, 1.75, 2.75)
}

fn coupling(input: &[f64], output: &[f64]) -> Coupling {
    let shape = loop_shape(input, output);
    Coupling {
        span_um: shape.span_um,
        width_ratio: shape.width_ratio,
    }
}

/// The coupling spans of seed 000 Table 3, open loop. Each sweep drives one
/// axis with a 1 Hz wave whose amplitude is solved (span to 1e-7 µm, θ span
/// to 1e-9°) so
/// that the driven axis spans 10 µm (x, y) or 2 × 9.2e-3° (θ) over the
/// measured cycle, while the other actuators hold their home commands (y home
/// u1 = 0, x home u2 = u3 = u_home); see `y_sweep`, `x_sweep` and
/// `rotation_sweep` in this module for the exact demands. Coupled readings:
/// s2 and s3 versus u1 (y sweep), y versus u2 (x sweep), y versus
/// D sin 2πt (rotation sweep).
pub fn coupling_sweeps<P: StageSource>(plant: &P, u_home: f64) -> CouplingSweeps {
    let spacing = plant.sensor_spacing_um();
    let y_of = |s: &Sample| s.sensors[0];
    let x_of = |s: &Sample| 0.5 * (s.sensors[1] + s.sensors[2]);
    let theta_deg_of = |s: &Sample| ((s.sensors[1] - s.sensors[2]) / spacing).to_degrees();

    let a_y = solve_increasing(
        |a| span_of(&y_sweep(plant, u_home, a), y_of) - SWEEP_SPAN_UM,
        0.0,
        FULL_COMMAND,
        1e-7,
    );
    let ys = y_sweep(plant, u_home, a_y);
    let u1: Vec<f64> = ys.iter().map(|s| s.commands[0]).collect();
    let s2: Vec<f64> = ys.iter().map(|s| s.sensors[1]).collect();
    let s3: Vec<f64> = ys.iter().map(|s| s.sensors[2]).collect();

    let a_x = solve_increasing(
        |a| span_of(&x_sweep(plant, a), x_of) - SWEEP_SPAN_UM,
        0.0,
        FULL_COMMAND,
        1e-7,
    );
    let xs = x_sweep(plant, a_x);
    let u2: Vec<f64> = xs.iter().map(|s| s.commands[1]).collect();
    let y_x: Vec<f64> = xs.iter().map(y_of).collect();

    let d_max = u_home.min(FULL_COMMAND - u_home);
    let d = solve_increasing(
        |d| {
            span_of(&rotation_sweep(plant, u_home, d), theta_deg_of)
                - 2.0 * ROTATION_SWEEP_AMPLITUDE_DEG
        },
        0.0,
        d_max,
        1e-9,
    );
    let rs = rotation_sweep(plant, u_home, d);
    let differential: Vec<f64> = rs
        .iter()
        .map(|s| 0.5 * (s.commands[1] - s.commands[2]))
        .collect();
    let y_r: Vec<f64> = rs.iter().map(y_of).collect();

    CouplingSweeps {
        y_sweep_amplitude: a_y,
        x_sweep_amplitude: a_x,
        rotation_sweep_amplitude: d,
        s2_from_y: coupling(&u1, &s2),
        s3_from_y: coupling(&u1, &s3),
        y_from_x: coupling(&u2, &y_x),
        y_from_rotation: coupling(&differential, &y_r),
    }
}

/// Axis of a feedback-loop test, read and driven as seed 000's controller
/// reads and drives it (§3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoopAxis {
    /// Reads x = (s2 + s3)/2, drives u2 and u3 equally.
    X,
    /// Reads y = s1, drives u1.
    Y,
    /// Reads θ·L/2 = (s2 − s3)/2 [µm], drives u2 up and u3 down.
    Theta,
}

impl LoopAxis {
    pub const ALL: [LoopAxis; 3] = [LoopAxis::X, LoopAxis::Y, LoopAxis::Theta];

    fn directions(self) -> [f64; 3] {
        match self {
            LoopAxis::X => [0.0, 1.0, 1.0],
            LoopAxis::Y => [1.0, 0.0, 0.0],
            LoopAxis::Theta => [0.0, 1.0, -1.0],
        }
    }

    fn reading<S: Stage>(self, rig: &Rig<S>) -> f64 {
        let s = rig.stage.sensors();
        match self {
            LoopAxis::X => 0.5 * (s[1] + s[2]),
            LoopAxis::Y => s[0],
            LoopAxis::Theta => 0.5 * (s[1] - s[2]),
        }
    }
}

/// u1 at the operating point of the loop tests (y at mid stroke) [V].
pub const LOOP_Y_COMMAND: f64 = 5.0;
/// Reference step that starts the loop's oscillation [µm].
pub const LOOP_STEP_UM: f64 = 0.05;
/// Length of one proportional-loop probe [s].
pub const LOOP_PROBE_TIME: f64 = 0.12;
/// The two windows whose oscillation amplitudes give the growth rate [s].
const LOOP_WINDOWS: [(f64, f64); 2] = [(0.02, 0.06), (0.08, 0.12)];

/// The Ziegler-Nichols ultimate gain of one axis: the proportional gain at
/// which the sampled loop oscillates without growing or decaying, and the
/// period of that oscillation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct UltimateGain {
    /// K_u [V/µm].
    pub gain: f64,
    /// T_u [s].
    pub period: f64,
}

impl UltimateGain {
    /// Ziegler-Nichols PI tuning: kp = 0.45·K_u, ki = kp/(T_u/1.2).
    pub fn ziegler_nichols_pi(&self) -> (f64, f64) {
        let kp = 0.45 * self.gain;
        (kp, kp * 1.2 / self.period)
    }
}

/// A proportional loop on `axis` from the settled rig `start`: the reference
/// steps by [`LOOP_STEP_UM`] and the command of channel c over [t_k, t_k+1] is
/// the operating command + directions_c·kp·(r − reading(t_k−1)): one sample
/// of compute delay, as a controller FMU in the
/// project's co-simulation has. Returns the growth rate of the oscillation
/// [1/s] (ln of the ratio of the RMS of the error about its mean in the two
/// [`LOOP_WINDOWS`], over their distance) and its period [s] from the zero
/// crossings in the last window. A probe whose command leaves 0..10 V is
/// unstable: growth +∞.
pub fn proportional_loop_growth<S: Stage>(rig: &mut Rig<S>, axis: LoopAxis, kp: f64) -> (f64, f64) {
    let saved = rig.stage.snapshot();
    let saved_commands = rig.commands;
    let (growth, period) = loop_probe(rig, axis, kp);
    rig.stage.restore(&saved);
    rig.commands = saved_commands;
    (growth, period)
}

fn loop_probe<S: Stage>(rig: &mut Rig<S>, axis: LoopAxis, kp: f64) -> (f64, f64) {
    match loop_errors(rig, axis, kp, LOOP_STEP_UM, 0.0) {
        Some(errors) => growth_and_period(&errors, false),
        None => (f64::INFINITY, f64::NAN),
    }
}

/// The errors r − reading of a proportional loop on `axis` from the rig's
/// state, the reference stepped by `step_um` and the operating commands
/// ramped along the axis's directions at `command_rate` [V/s] (0: held);
/// None once a command leaves 0..10 V. A loop that is stable never leaves
/// the command range after a small step from mid-stroke; once limited, an
/// unstable loop's amplitude stops growing and would look marginal.
fn loop_errors<S: Stage>(
    rig: &mut Rig<S>,
    axis: LoopAxis,
    kp: f64,
    step_um: f64,
    command_rate: f64,
) -> Option<Vec<f64>> {
    let operating = rig.commands;
    let directions = axis.directions();
    let reference = axis.reading(rig) + step_um;
    let mut previous = axis.reading(rig);
    let mut current = previous;
    let steps = (LOOP_PROBE_TIME / SAMPLE_PERIOD).round() as usize;
    let mut errors = Vec::with_capacity(steps);
    for k in 0..steps {
        let v = kp * (reference - previous) + command_rate * (k as f64 * SAMPLE_PERIOD);
        let raw = [0, 1, 2].map(|c| operating[c] + directions[c] * v);
        if raw.iter().any(|u| !(0.0..=FULL_COMMAND).contains(u)) {
            return None;
        }
        rig.stage.step(raw, SAMPLE_PERIOD);
        previous = current;
        current = axis.reading(rig);
        errors.push(reference - current);
    }
    Some(errors)
}

/// The growth rate [1/s] and period [s] of the oscillation in a probe's
/// errors ([`proportional_loop_growth`] says how), each window's mean taken
/// out, and with `detrend` its straight line (a moving probe's slow drift).
fn growth_and_period(errors: &[f64], detrend: bool) -> (f64, f64) {
    let window = |(from, to): (f64, f64)| {
        let a = (from / SAMPLE_PERIOD).round() as usize;
        let b = ((to / SAMPLE_PERIOD).round() as usize).min(errors.len());
        let segment = &errors[a..b];
        let n = segment.len() as f64;
        let mean = segment.iter().sum::<f64>() / n;
        let middle = 0.5 * (n - 1.0);
        let trend = if detrend {
            let sxx: f64 = (0..segment.len())
                .map(|k| (k as f64 - middle).powi(2))
                .sum();
            segment
                .iter()
                .enumerate()
                .map(|(k, e)| (k as f64 - middle) * (e - mean))
                .sum::<f64>()
                / sxx
        } else {
            0.0
        };
        let centred: Vec<f64> = segment
            .iter()
            .enumerate()
            .map(|(k, e)| e - mean - trend * (k as f64 - middle))
            .collect();
        let rms = (centred.iter().map(|e| e * e).sum::<f64>() / centred.len() as f64).sqrt();
        (rms, centred)
    };
    let (first, _) = window(LOOP_WINDOWS[0]);
    let (last, centred) = window(LOOP_WINDOWS[1]);
    let distance = LOOP_WINDOWS[1].0 - LOOP_WINDOWS[0].0;
    let growth = (last.max(1e-300) / first.max(1e-300)).ln() / distance;
    // Zero crossings, interpolated between samples [in samples].
    let crossings: Vec<f64> = (1..centred.len())
        .filter(|&k| (centred[k - 1] < 0.0) != (centred[k] < 0.0))
        .map(|k| (k - 1) as f64 + centred[k - 1] / (centred[k - 1] - centred[k]))
        .collect();
    let period = if crossings.len() >= 3 {
        2.0 * (crossings[crossings.len() - 1] - crossings[0]) * SAMPLE_PERIOD
            / (crossings.len() - 1) as f64
    } else {
        f64::NAN
    };
    (growth, period)
}

/// A rig at the operating point of the loop tests: from rest, ramp to
/// ([`LOOP_Y_COMMAND`], u_home, u_home) over 1 s and hold 0.5 s so that the
/// modes settle.
pub fn rig_at_loop_operating_point<P: StageSource>(plant: &P, u_home: f64) -> Rig<P::Stage> {
    let mut rig = Rig::new(plant);
    rig.ramp_to([LOOP_Y_COMMAND, u_home, u_home]);
    rig.hold(0.5);
    rig
}

/// The ultimate gain of `axis` (Ziegler-Nichols, the method seed 000 §3.2
/// tuned its PI gains with): the gain at which
/// [`proportional_loop_growth`] changes sign, by bisection in log gain
/// between 0.001 and 10 V/µm to a relative width of 1e-4, at the operating
/// point of [`rig_at_loop_operating_point`]. (Bisection, because an unstable
/// probe reports an infinite growth that regula falsi cannot interpolate.)
pub fn ultimate_gain<P: StageSource>(plant: &P, u_home: f64, axis: LoopAxis) -> UltimateGain {
    let mut rig = rig_at_loop_operating_point(plant, u_home);
    bisected_ultimate_gain(&mut rig, (1e-3, 10.0), |rig, kp| {
        proportional_loop_growth(rig, axis, kp)
    })
}

/// The gain in (stable, unstable) at which `growth` changes sign, by
/// bisection in log gain to a relative width of 1e-4, with the period of the
/// oscillation just inside the stable side, where the probe does not leave
/// the command range.
fn bisected_ultimate_gain<S: Stage>(
    rig: &mut Rig<S>,
    (mut stable, mut unstable): (f64, f64),
    growth: impl Fn(&mut Rig<S>, f64) -> (f64, f64),
) -> UltimateGain {
    while unstable / stable > 1.0 + 1e-4 {
        let kp = (stable * unstable).sqrt();
        if growth(rig, kp).0 > 0.0 {
            unstable = kp;
        } else {
            stable = kp;
        }
    }
    let gain = (stable * unstable).sqrt();
    let (_, period) = growth(rig, stable);
    UltimateGain { gain, period }
}

/// Command rate of the moving loop probe [V/s]: the x stroke (12.74 µm per
/// 10 V, seed 000 §2) at the mid-stroke speed of seed 000's Fig. 7 sine, a
/// 10 µm span at 1 Hz (π·10 µm·1 Hz = 31.4 µm/s).
pub const MOVING_LOOP_COMMAND_RATE: f64 = 25.0;
/// Reference step of the moving loop probe [µm]: its oscillation's command,
/// kp·step at 818 Hz, moves at about 1 V/s at the ultimate gain, far below
/// the ramp, so the stacks never reverse and the loop sees the branch's own
/// slope (a held probe's stacks reverse at every half period).
pub const MOVING_LOOP_STEP_UM: f64 = 0.002;

/// [`proportional_loop_growth`] with the operating commands ramping along
/// the axis at [`MOVING_LOOP_COMMAND_RATE`] from the rig's state: the loop
/// as a tracking stage has it, on a branch rather than on a held point's
/// small loops. The oscillation is the difference between the probe with a
/// [`MOVING_LOOP_STEP_UM`] step and the same probe without one, which takes
/// the ramp's own trajectory out.
pub fn proportional_loop_growth_while_moving<S: Stage>(
    rig: &mut Rig<S>,
    axis: LoopAxis,
    kp: f64,
) -> (f64, f64) {
    let saved = rig.stage.snapshot();
    let saved_commands = rig.commands;
    let mut run = |step_um: f64| {
        let errors = loop_errors(rig, axis, kp, step_um, MOVING_LOOP_COMMAND_RATE);
        rig.stage.restore(&saved);
        rig.commands = saved_commands;
        errors
    };
    match (run(MOVING_LOOP_STEP_UM), run(0.0)) {
        (Some(stepped), Some(unstepped)) => {
            let difference: Vec<f64> = stepped.iter().zip(&unstepped).map(|(a, b)| a - b).collect();
            growth_and_period(&difference, true)
        }
        _ => (f64::INFINITY, f64::NAN),
    }
}

/// [`ultimate_gain`] of the loop while the stage moves
/// ([`proportional_loop_growth_while_moving`]) from the same operating point:
/// the gain raised from 0.01 V/µm in steps of 5 % until the oscillation
/// grows, as the Ziegler-Nichols procedure raises it, then bisected within
/// that step. (Not bisected over the whole range: well above K_u the
/// oscillation soon outruns the ramp, the stacks reverse, their flatter small
/// loops hold its amplitude, and the growth between the two windows reads
/// about 0.)
pub fn ultimate_gain_while_moving<P: StageSource>(
    plant: &P,
    u_home: f64,
    axis: LoopAxis,
) -> UltimateGain {
    let mut rig = rig_at_loop_operating_point(plant, u_home);
    let growth = |rig: &mut Rig<P::Stage>, kp| proportional_loop_growth_while_moving(rig, axis, kp);
    // Raised no further than the held test's bracket, whose top it returns
    // for a loop stable at every gain.
    let mut stable: f64 = 0.01;
    while 1.05 * stable < 10.0 && growth(&mut rig, 1.05 * stable).0 <= 0.0 {
        stable *= 1.05;
    }
    bisected_ultimate_gain(&mut rig, (stable, (1.05 * stable).min(10.0)), growth)
}

/// Where the Ziegler-Nichols test's loop runs. Seed 000 §3.2 tuned the PI
/// gains of a tracking stage by Ziegler-Nichols without saying at which
/// operating point; a held stack answers the probe on its small minor loops,
/// a moving one on the branch it runs along, and with the return-point
/// memory the two differ by 44 % (MODEL.md §5-6).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ZieglerNicholsReading {
    /// [`ultimate_gain_while_moving`]: the loop on a stage ramping at seed
    /// 000's Fig. 7 speed, the reading the default preset is calibrated to.
    WhileMoving,
    /// [`ultimate_gain`]: the loop at a held point, the reading the
    /// `3dof_memory` and `3dof_no_memory` presets are calibrated to.
    Held,
}

impl ZieglerNicholsReading {
    /// The ultimate gain of `axis` as this reading takes it.
    pub fn ultimate_gain<P: StageSource>(
        self,
        plant: &P,
        u_home: f64,
        axis: LoopAxis,
    ) -> UltimateGain {
        match self {
            ZieglerNicholsReading::WhileMoving => ultimate_gain_while_moving(plant, u_home, axis),
            ZieglerNicholsReading::Held => ultimate_gain(plant, u_home, axis),
        }
    }
}

/// Every fingerprint of the calibrated stage.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Fingerprints {
    pub stroke_x_um: f64,
    pub stroke_y_um: f64,
    pub x_home_command: f64,
    /// (anticlockwise, clockwise) [deg].
    pub rotation_range_deg: (f64, f64),
    pub theta_resonance_hz: f64,
    pub loop_x: LoopShape,
    pub loop_y: LoopShape,
    pub couplings: CouplingSweeps,
    /// How [`Fingerprints::ultimate_gains`] were read.
    pub ziegler_nichols: ZieglerNicholsReading,
    /// Ziegler-Nichols ultimate gains of x, y and θ (in [`LoopAxis::ALL`] order).
    pub ultimate_gains: [UltimateGain; 3],
}

/// Runs every procedure of this module, the Ziegler-Nichols figures read on
/// the moving stage ([`ZieglerNicholsReading::WhileMoving`]).
pub fn measure<P: StageSource>(plant: &P) -> Fingerprints {
    measure_with(plant, ZieglerNicholsReading::WhileMoving)
}

/// [`measure`] with the Ziegler-Nichols figures read as `reading` says.
pub fn measure_with<P: StageSource>(plant: &P, reading: ZieglerNicholsReading) -> Fingerprints {
    let u_home = x_home_command(plant);
    Fingerprints {
        stroke_x_um: stroke(plant, Axis::X),
        stroke_y_um: stroke(plant, Axis::Y),
        x_home_command: u_home,
        rotation_range_deg: rotation_range_deg(plant, u_home),
        theta_resonance_hz: theta_resonance_hz(plant, u_home),
        loop_x: major_loop(plant, Axis::X),
        loop_y: major_loop(plant, Axis::Y),
        couplings: coupling_sweeps(plant, u_home),
        ziegler_nichols: reading,
        ultimate_gains: LoopAxis::ALL.map(|axis| reading.ultimate_gain(plant, u_home, axis)),
    }
}

/// A figure of seed 000 and the relative tolerance the plant must meet.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Target {
    /// The [`Fingerprints::value`] key.
    pub key: &'static str,
    pub name: &'static str,
    pub paper: f64,
    pub relative_tolerance: f64,
    pub unit: &'static str,
    pub source: &'static str,
}

/// Seed 000 §3.2's PI gains (translation kp 0.05, ki 50; rotation kp 0.06),
/// tuned by Ziegler-Nichols: kp = 0.45·K_u, ki = 1.2·kp/T_u.
const TRANSLATION_KP: f64 = 0.05;
const TRANSLATION_KI: f64 = 50.0;
const ROTATION_KP: f64 = 0.06;
const ZIEGLER_NICHOLS_KP: f64 = 0.45;

/// Every figure the calibrated stage reproduces (the calibration example
/// solves for them; the tests and `piezo-cosim fingerprint` check them).
pub const TARGETS: [Target; 14] = [
    Target {
        key: "stroke_x",
        name: "stroke x at 10 V",
        paper: 12.74,
        relative_tolerance: 0.05,
        unit: "um",
        source: "seed 000 §2",
    },
    Target {
        key: "stroke_y",
        name: "stroke y at 10 V",
        paper: 12.22,
        relative_tolerance: 0.05,
        unit: "um",
        source: "seed 000 §2",
    },
    Target {
        key: "rotation_anticlockwise",
        name: "rotation range anticlockwise",
        paper: 0.0103,
        relative_tolerance: 0.10,
        unit: "deg",
        source: "seed 000 §2",
    },
    Target {
        key: "rotation_clockwise",
        name: "rotation range clockwise",
        paper: 0.0088,
        relative_tolerance: 0.10,
        unit: "deg",
        source: "seed 000 §2",
    },
    Target {
        key: "theta_resonance",
        name: "theta_z resonance",
        paper: 790.0,
        relative_tolerance: 0.02,
        unit: "Hz",
        source: "seed 000 §2",
    },
    Target {
        key: "s2_from_y",
        name: "coupling span s2 (x2) from y",
        paper: 2.2065,
        relative_tolerance: 0.15,
        unit: "um",
        source: "seed 000 Table 3",
    },
    Target {
        key: "s3_from_y",
        name: "coupling span s3 (x3) from y",
        paper: 2.7435,
        relative_tolerance: 0.15,
        unit: "um",
        source: "seed 000 Table 3",
    },
    Target {
        key: "y_from_x",
        name: "coupling span y from x",
        paper: 1.2482,
        relative_tolerance: 0.15,
        unit: "um",
        source: "seed 000 Table 3",
    },
    Target {
        key: "y_from_rotation",
        name: "coupling span y from rotation",
        paper: 1.6784,
        relative_tolerance: 0.15,
        unit: "um",
        source: "seed 000 Table 3",
    },
    Target {
        key: "ultimate_gain_x",
        name: "Ziegler-Nichols ultimate gain x",
        paper: TRANSLATION_KP / ZIEGLER_NICHOLS_KP,
        relative_tolerance: 0.10,
        unit: "V/um",
        source: "seed 000 §3.2 kp / 0.45",
    },
    Target {
        key: "ultimate_gain_y",
        name: "Ziegler-Nichols ultimate gain y",
        paper: TRANSLATION_KP / ZIEGLER_NICHOLS_KP,
        relative_tolerance: 0.10,
        unit: "V/um",
        source: "seed 000 §3.2 kp / 0.45",
    },
    Target {
        key: "ultimate_gain_theta",
        name: "Ziegler-Nichols ultimate gain theta_z",
        paper: ROTATION_KP / ZIEGLER_NICHOLS_KP,
        relative_tolerance: 0.10,
        unit: "V/um",
        source: "seed 000 §3.2 kp / 0.45",
    },
    Target {
        key: "ultimate_period_x",
        name: "Ziegler-Nichols ultimate period x",
        paper: 1.2 * TRANSLATION_KP / TRANSLATION_KI,
        relative_tolerance: 0.10,
        unit: "s",
        source: "seed 000 §3.2 1.2 kp / ki",
    },
    Target {
        key: "ultimate_period_y",
        name: "Ziegler-Nichols ultimate period y",
        paper: 1.2 * TRANSLATION_KP / TRANSLATION_KI,
        relative_tolerance: 0.10,
        unit: "s",
        source: "seed 000 §3.2 1.2 kp / ki",
    },
];

/// The target of `key` (one of [`TARGETS`]).
pub fn target(key: &str) -> &'static Target {
    TARGETS
        .iter()
        .find(|t| t.key == key)
        .unwrap_or_else(|| panic!("no fingerprint target {key}"))
}

/// Major-loop width as a share of the loop's span (8-15 %).
pub const LOOP_WIDTH_RANGE: (f64, f64) = (0.08, 0.15);
/// A loop is asymmetric when max_d |w(c+d) − w(c−d)| / max|w| exceeds this.
pub const LOOP_ASYMMETRY_MIN: f64 = 0.10;
/// A coupling is a hysteresis loop when its width is at least this share of
/// its span.
pub const COUPLING_LOOP_WIDTH_MIN: f64 = 0.05;

/// One checked row of the fingerprint table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Check {
    pub key: String,
    pub name: String,
    /// The paper's figure (target rows).
    pub paper: Option<f64>,
    /// What the measured value must meet: the tolerance about the paper's
    /// figure, or the rule of a shape check.
    pub rule: String,
    pub measured: f64,
    pub unit: &'static str,
    /// measured / paper − 1 (target rows only).
    pub relative_error: Option<f64>,
    pub relative_tolerance: Option<f64>,
    pub within: bool,
    pub source: &'static str,
}

impl Fingerprints {
    /// The measured figure of a [`TARGETS`] key.
    pub fn value(&self, key: &str) -> Option<f64> {
        let c = &self.couplings;
        let [x, y, theta] = self.ultimate_gains;
        Some(match key {
            "stroke_x" => self.stroke_x_um,
            "stroke_y" => self.stroke_y_um,
            "rotation_anticlockwise" => self.rotation_range_deg.0,
            "rotation_clockwise" => self.rotation_range_deg.1,
            "theta_resonance" => self.theta_resonance_hz,
            "s2_from_y" => c.s2_from_y.span_um,
            "s3_from_y" => c.s3_from_y.span_um,
            "y_from_x" => c.y_from_x.span_um,
            "y_from_rotation" => c.y_from_rotation.span_um,
            "ultimate_gain_x" => x.gain,
            "ultimate_gain_y" => y.gain,
            "ultimate_gain_theta" => theta.gain,
            "ultimate_period_x" => x.period,
            "ultimate_period_y" => y.period,
            "ultimate_period_theta" => theta.period,
            _ => return None,
        })
    }

    /// Every target and shape rule, measured and judged.
    pub fn checks(&self) -> Vec<Check> {
        let mut checks: Vec<Check> = TARGETS
            .iter()
            .map(|t| {
                let measured = self.value(t.key).expect("every target has a value");
                let error = measured / t.paper - 1.0;
                Check {
                    key: t.key.to_owned(),
                    name: t.name.to_owned(),
                    paper: Some(t.paper),
                    rule: format!("±{:.0} %", 100.0 * t.relative_tolerance),
                    measured,
                    unit: t.unit,
                    relative_error: Some(error),
                    relative_tolerance: Some(t.relative_tolerance),
                    within: error.abs() <= t.relative_tolerance,
                    source: t.source,
                }
            })
            .collect();
        for (axis, shape) in [("x", self.loop_x), ("y", self.loop_y)] {
            let (low, high) = LOOP_WIDTH_RANGE;
            checks.push(Check {
                key: format!("loop_{axis}_width_ratio"),
                name: format!("major loop {axis}: width / span"),
                paper: None,
                rule: format!("{:.0}-{:.0} %", 100.0 * low, 100.0 * high),
                measured: shape.width_ratio,
                unit: "",
                relative_error: None,
                relative_tolerance: None,
                within: (low..=high).contains(&shape.width_ratio),
                source: "hysteresis of PZT stacks",
            });
            checks.push(Check {
                key: format!("loop_{axis}_asymmetry"),
                name: format!("major loop {axis}: asymmetry"),
                paper: None,
                rule: format!("> {LOOP_ASYMMETRY_MIN}"),
                measured: shape.asymmetry,
                unit: "",
                relative_error: None,
                relative_tolerance: None,
                within: shape.asymmetry > LOOP_ASYMMETRY_MIN,
                source: "seed 001 (asymmetric loops)",
            });
        }
        let c = &self.couplings;
        for (key, coupling) in [
            ("s2_from_y", c.s2_from_y),
            ("s3_from_y", c.s3_from_y),
            ("y_from_x", c.y_from_x),
            ("y_from_rotation", c.y_from_rotation),
        ] {
            checks.push(Check {
                key: format!("{key}_width_ratio"),
                name: format!("{key}: loop width / span"),
                paper: None,
                rule: format!(">= {:.0} %", 100.0 * COUPLING_LOOP_WIDTH_MIN),
                measured: coupling.width_ratio,
                unit: "",
                relative_error: None,
                relative_tolerance: None,
                within: coupling.width_ratio >= COUPLING_LOOP_WIDTH_MIN,
                source: "seed 001 eq. 8",
            });
        }
        checks
    }
}

/// The samples with t in [from, to] (both ends included, 1 µs slack for rounding).
fn window(samples: &[Sample], from: f64, to: f64) -> Vec<Sample> {
    samples
        .iter()
        .filter(|s| s.t >= from - 1e-6 && s.t <= to + 1e-6)
        .copied()
        .collect()
}

fn span(values: &[f64]) -> f64 {
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    max - min
}

fn span_of(samples: &[Sample], reading: impl Fn(&Sample) -> f64) -> f64 {
    span(&samples.iter().map(reading).collect::<Vec<_>>())
}

fn argmax(values: &[f64]) -> usize {
    let mut best = 0;
    for (k, v) in values.iter().enumerate() {
        if *v > values[best] {
            best = k;
        }
    }
    best
}

/// Linear interpolation of y at x on points sorted by increasing x (a branch;
/// repeated x are tolerated), clamped at the ends.
pub fn interpolate(points: &[(f64, f64)], x: f64) -> f64 {
    let j = points.partition_point(|p| p.0 < x);
    if j == 0 {
        return points[0].1;
    }
    if j == points.len() {
        return points[j - 1].1;
    }
    let (x0, y0) = points[j - 1];
    let (x1, y1) = points[j];
    if x1 == x0 {
        y1
    } else {
        y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    }
}

/// Root of an increasing function on [lo, hi] by the Illinois variant of
/// regula falsi, to |f| ≤ tolerance (or a bracket narrower than 1e-12).
pub fn solve_increasing(f: impl Fn(f64) -> f64, lo: f64, hi: f64, tolerance: f64) -> f64 {
    let (mut a, mut b) = (lo, hi);
    let (mut fa, mut fb) = (f(a), f(b));
    if fa >= 0.0 {
        return a;
    }
    if fb <= 0.0 {
        return b;
    }
    let mut side = 0;
    for _ in 0..200 {
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = f(c);
        if fc.abs() <= tolerance || (b - a) < 1e-12 {
            return c;
        }
        if fc < 0.0 {
            a = c;
            fa = fc;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            b = c;
            fb = fc;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_and_loop_width_of_a_known_loop() {
        // An ellipse-like loop: ascending y = u − 0.1·sin(πu), descending
        // y = u + 0.1·sin(πu), u in [0, 1]: width 0.2·sin(πu), symmetric.
        let n = 1000;
        let mut input = Vec::new();
        let mut output = Vec::new();
        for k in 0..=n {
            let u = k as f64 / n as f64;
            input.push(u);
            output.push(u - 0.1 * (std::f64::consts::PI * u).sin());
        }
        for k in (0..n).rev() {
            let u = k as f64 / n as f64;
            input.push(u);
            output.push(u + 0.1 * (std::f64::consts::PI * u).sin());
        }
        let shape = loop_shape(&input, &output);
        assert!((shape.max_width_um - 0.2).abs() < 1e-6);
        assert!((shape.span_um - 1.0).abs() < 1e-12);
        assert!(shape.asymmetry < 1e-6);
    }

    #[test]
    fn spectral_peak_finds_a_damped_sine() {
        let period = 1e-5;
        let record: Vec<f64> = (0..25_000)
            .map(|k| {
                let t = k as f64 * period;
                (-60.0 * t).exp() * (std::f64::consts::TAU * 812.3 * t).sin()
            })
            .collect();
        assert!((spectral_peak_hz(&record, period) - 812.3).abs() <= 0.5);
    }

    #[test]
    fn solver_finds_the_root() {
        let root = solve_increasing(|x| x * x * x - 2.0, 0.0, 3.0, 1e-12);
        assert!((root - 2f64.cbrt()).abs() < 1e-10);
    }
}
