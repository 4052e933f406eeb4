//! Drivers of the speed benchmarks (`benches/fmu_step.rs`): the FMUs driven
//! through their C ABI as an importer drives them, the same models called
//! directly in Rust, and the input signals both get.
//!
//! Both sides of every comparison run the same signal generator, the same
//! parameters and the same sequence of calls, so that the difference of their
//! timings is the FMI layer and nothing else; `tests/same_work.rs` checks that
//! they produce bit-identical outputs.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use fmi_sys::fmi2::fmi2Status;
use fmi2_import::{Fmu, Instance, OK, WARNING};
use piezo_models::{ControllerParams, FlexureStage, FlexureStageParams, PiezoController};

/// Communication step of every benchmark: seed 000's 10 kHz sample rate.
pub const STEP: f64 = 1e-4;

/// Frequency of every benchmark signal (seed 000 tracks 1 Hz sines).
pub const SIGNAL_HZ: f64 = 1.0;

/// Constant x demand in µm, mid-stroke (12.74 µm at 100 V), so that no
/// channel sits at a command limit.
pub const X_REF_UM: f64 = 6.0;
/// The y demand is Y_MEAN_UM + Y_AMPLITUDE_UM·sin(2π·1 Hz·t) in µm, 1..11 µm of
/// the 12.22 µm stroke.
pub const Y_MEAN_UM: f64 = 6.0;
pub const Y_AMPLITUDE_UM: f64 = 5.0;

/// A unit phasor advanced by one rotation per sample: sin and cos of
/// 2π·f·t_k for a few flops, so that the signal costs next to nothing beside
/// the 100 ns the controller's step is expected to take (a call of `sin`
/// costs about 15 ns).
#[derive(Clone, Copy, Debug)]
pub struct Phasor {
    sin: f64,
    cos: f64,
    rotation_sin: f64,
    rotation_cos: f64,
}

impl Phasor {
    /// Starts at phase 0 and turns by 2π·frequency·h per sample.
    pub fn new(frequency_hz: f64, h: f64) -> Self {
        let angle = TAU * frequency_hz * h;
        Phasor {
            sin: 0.0,
            cos: 1.0,
            rotation_sin: angle.sin(),
            rotation_cos: angle.cos(),
        }
    }

    /// (sin, cos) of the current sample's phase, then moves to the next sample.
    /// Rounding changes the magnitude by about 1e-16 per sample, which stays
    /// far below anything that matters over the benchmarks' 10⁸ samples.
    #[inline]
    pub fn sample(&mut self) -> (f64, f64) {
        let current = (self.sin, self.cos);
        let sin = self.sin * self.rotation_cos + self.cos * self.rotation_sin;
        let cos = self.cos * self.rotation_cos - self.sin * self.rotation_sin;
        self.sin = sin;
        self.cos = cos;
        current
    }
}

/// The references [x_ref, y_ref, theta_ref] of a sample with phasor values
/// (sin, cos): a 1 Hz sine on y, x held mid-stroke, no rotation.
#[inline]
pub fn references(sin: f64) -> [f64; 3] {
    [X_REF_UM, Y_MEAN_UM + Y_AMPLITUDE_UM * sin, 0.0]
}

/// The controller's six inputs of one sample in the order of
/// [`CONTROLLER_INPUTS`]: the references and sensor readings near them, as a
/// stage that tracks with a lag would give (a 50 nm error at the steepest part
/// of the sine, 20 nm of x-pair difference), so that the PI laws and the
/// inverse models see changing, realistic errors and rates.
#[derive(Clone, Copy, Debug)]
pub struct ControllerSignal {
    phasor: Phasor,
}

impl ControllerSignal {
    pub fn new(h: f64) -> Self {
        ControllerSignal {
            phasor: Phasor::new(SIGNAL_HZ, h),
        }
    }

    #[inline]
    pub fn sample(&mut self) -> [f64; 6] {
        let (sin, cos) = self.phasor.sample();
        let [x_ref, y_ref, theta_ref] = references(sin);
        [
            x_ref,
            y_ref,
            theta_ref,
            y_ref - 0.05 * cos,
            x_ref + 0.02 * sin,
            x_ref - 0.02 * sin,
        ]
    }
}

/// The plant's three commands of one sample: full-range 1 Hz sines, 0..10 V
/// (0..100 V after the amplifier), a third of a period apart, so that every
/// channel, every hysteresis model and the rotation mode are driven.
#[derive(Clone, Copy, Debug)]
pub struct PlantSignal {
    phasor: Phasor,
    /// (sin, cos) of each channel's phase offset.
    offsets: [(f64, f64); 3],
}

impl PlantSignal {
    pub fn new(h: f64) -> Self {
        PlantSignal {
            phasor: Phasor::new(SIGNAL_HZ, h),
            offsets: [0.0, 1.0, 2.0].map(|k: f64| {
                let phase = k * TAU / 3.0;
                (phase.sin(), phase.cos())
            }),
        }
    }

    #[inline]
    pub fn sample(&mut self) -> [f64; 3] {
        let (sin, cos) = self.phasor.sample();
        // sin(ωt + φ) = sin ωt·cos φ + cos ωt·sin φ
        self.offsets
            .map(|(sin_phi, cos_phi)| 5.0 + 5.0 * (sin * cos_phi + cos * sin_phi))
    }
}

/// The controller parameters of both sides: the FMU's start values
/// (`ControllerParams::default()`) with every switch on. The FMU's start value
/// of `decoupling` is false; the benchmarks turn it on (through
/// `fmi2SetBoolean` before initialization on the ABI side) so that the
/// controller's whole law is timed.
pub fn controller_params() -> ControllerParams {
    ControllerParams {
        feedforward: true,
        decoupling: true,
        feedback_x: true,
        feedback_y: true,
        feedback_theta: true,
        ..ControllerParams::default()
    }
}

/// The Boolean switches set on the controller FMU before initialization, as
/// (name, value); they reproduce [`controller_params`].
pub const CONTROLLER_SWITCHES: [(&str, bool); 5] = [
    ("feedforward", true),
    ("decoupling", true),
    ("feedback_x", true),
    ("feedback_y", true),
    ("feedback_theta", true),
];

/// Controller inputs in the order [`ControllerSignal::sample`] produces them.
pub const CONTROLLER_INPUTS: [&str; 6] = ["x_ref", "y_ref", "theta_ref", "s1", "s2", "s3"];
/// The controller outputs a master wires to the plant.
pub const CONTROLLER_OUTPUTS: [&str; 3] = ["u1", "u2", "u3"];
pub const PLANT_INPUTS: [&str; 3] = ["u1", "u2", "u3"];
/// The plant outputs a master wires back to the controller.
pub const PLANT_OUTPUTS: [&str; 3] = ["s1", "s2", "s3"];

/// The workspace root (this crate's parent directory).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("fmu-bench lives inside the workspace")
        .to_owned()
}

/// `libfmu_controller.so` of the profile the running binary was built in
/// (`target/release` under `cargo bench`) with the committed description.
/// Panics when the binary is missing or older than its sources.
pub fn load_controller() -> Fmu {
    let library = fmi2_import::cdylib_path("fmu-controller");
    Fmu::load(
        &library,
        include_str!("../../modelDescription/PiezoController.xml"),
    )
}

/// `libfmu_plant.so`, as [`load_controller`].
pub fn load_plant() -> Fmu {
    let library = fmi2_import::cdylib_path("fmu-plant");
    Fmu::load(
        &library,
        include_str!("../../modelDescription/FlexureStage.xml"),
    )
}

/// One initialized FMU instance with the value references of the inputs and
/// outputs a master exchanges at every step, resolved once: the per-step
/// calls allocate nothing and look nothing up, as in a real master.
pub struct AbiSlave<'a, const I: usize, const O: usize> {
    instance: Instance<'a>,
    inputs: [u32; I],
    outputs: [u32; O],
}

impl<'a, const I: usize, const O: usize> AbiSlave<'a, I, O> {
    /// Instantiates (logging off, as importers run by default), sets the
    /// Boolean parameters `switches`, initializes at t = 0.
    pub fn new(
        fmu: &'a Fmu,
        name: &str,
        inputs: [&str; I],
        outputs: [&str; O],
        switches: &[(&str, bool)],
    ) -> Self {
        let vr = |name: &str| fmu.variable(name).vr;
        let mut instance = fmu.instantiate(name, false);
        for (switch, on) in switches {
            // SAFETY: `instance.c` is live (the instance owns it); one value
            // reference and one value, both temporaries alive for the call.
            let status = unsafe {
                fmu.binding
                    .fmi2SetBoolean(instance.c, &vr(switch), 1, &i32::from(*on))
            };
            assert_eq!(
                status,
                OK,
                "fmi2SetBoolean({switch}): {:#?}",
                instance.take_log()
            );
        }
        instance.initialize();
        AbiSlave {
            instance,
            inputs: inputs.map(vr),
            outputs: outputs.map(vr),
        }
    }

    /// fmi2SetReal of every input.
    #[inline]
    pub fn set_inputs(&self, values: &[f64; I]) {
        // SAFETY: `self.instance.c` is live (the instance owns it); both
        // arrays have `I` elements, as passed.
        let status = unsafe {
            self.instance.fmu.binding.fmi2SetReal(
                self.instance.c,
                self.inputs.as_ptr(),
                I,
                values.as_ptr(),
            )
        };
        self.check("fmi2SetReal", status);
    }

    /// fmi2DoStep from the instance's current time.
    #[inline]
    pub fn do_step(&mut self, h: f64) {
        let status = self.instance.do_step(h);
        self.check("fmi2DoStep", status);
    }

    /// fmi2GetReal of every output.
    #[inline]
    pub fn get_outputs(&self) -> [f64; O] {
        let mut values = [0.0; O];
        // SAFETY: `self.instance.c` is live (the instance owns it); both
        // arrays have `O` elements, as passed, and `values` is writable.
        let status = unsafe {
            self.instance.fmu.binding.fmi2GetReal(
                self.instance.c,
                self.outputs.as_ptr(),
                O,
                values.as_mut_ptr(),
            )
        };
        self.check("fmi2GetReal", status);
        values
    }

    /// A master checks every status; a warning (a clipped command, logged
    /// once) is fine, anything worse stops the benchmark.
    #[inline]
    fn check(&self, function: &str, status: fmi2Status) {
        if status > WARNING {
            self.fail(function, status);
        }
    }

    #[cold]
    #[inline(never)]
    fn fail(&self, function: &str, status: fmi2Status) -> ! {
        panic!(
            "{function} returned {status}: {:#?}",
            self.instance.take_log()
        )
    }
}

pub type AbiController<'a> = AbiSlave<'a, 6, 3>;
pub type AbiPlant<'a> = AbiSlave<'a, 3, 3>;

/// The controller FMU with [`controller_params`], initialized.
pub fn abi_controller(fmu: &Fmu) -> AbiController<'_> {
    AbiSlave::new(
        fmu,
        "controller",
        CONTROLLER_INPUTS,
        CONTROLLER_OUTPUTS,
        &CONTROLLER_SWITCHES,
    )
}

/// The plant FMU with its start values (= `FlexureStageParams::default()`),
/// initialized.
pub fn abi_plant(fmu: &Fmu) -> AbiPlant<'_> {
    AbiSlave::new(fmu, "plant", PLANT_INPUTS, PLANT_OUTPUTS, &[])
}

/// The controller called directly, with the FMU's parameters.
pub fn direct_controller() -> PiezoController {
    PiezoController::new(controller_params()).expect("the FMU's parameters validate")
}

/// The stage called directly, with the FMU's start values.
pub fn direct_plant() -> FlexureStage {
    FlexureStage::new(FlexureStageParams::default()).expect("the shipped preset validates")
}

/// One direct controller sample with the inputs of [`ControllerSignal::sample`];
/// returns the commands u1..u3.
#[inline]
pub fn controller_step(controller: &mut PiezoController, inputs: &[f64; 6], h: f64) -> [f64; 3] {
    let [x_ref, y_ref, theta_ref, s1, s2, s3] = *inputs;
    controller.step(x_ref, y_ref, theta_ref, [s1, s2, s3], h).u
}

/// One direct stage step; returns the sensors s1..s3, what the FMU's outputs
/// s1..s3 read.
#[inline]
pub fn plant_step(stage: &mut FlexureStage, commands: [f64; 3], h: f64) -> [f64; 3] {
    let report = stage.step(commands, h);
    // The FMU fails the step on a non-finite state; the direct side checks it
    // too, so that both do the same work.
    assert!(report.fault.is_none(), "the stage state diverged");
    stage.sensors()
}

/// A co-simulation master's loop over the two FMUs (Jacobi coupling, as the
/// FMI 2.0 masters of Simulink, OMSimulator's weakly coupled systems and
/// libcosim do): each 100 µs sample sets both slaves' inputs from the outputs
/// of the previous sample, steps both, reads both.
pub struct AbiLoop<'a> {
    controller: AbiController<'a>,
    plant: AbiPlant<'a>,
    signal: ControllerSignal,
    commands: [f64; 3],
    sensors: [f64; 3],
}

impl<'a> AbiLoop<'a> {
    pub fn new(controller_fmu: &'a Fmu, plant_fmu: &'a Fmu, h: f64) -> Self {
        AbiLoop {
            controller: abi_controller(controller_fmu),
            plant: abi_plant(plant_fmu),
            signal: ControllerSignal::new(h),
            commands: [0.0; 3],
            sensors: [0.0; 3],
        }
    }

    /// One sample; returns the sensors read at its end.
    #[inline]
    pub fn step(&mut self, h: f64) -> [f64; 3] {
        // Only the references come from the signal; the sensors are the plant's.
        let [x_ref, y_ref, theta_ref, ..] = self.signal.sample();
        let [s1, s2, s3] = self.sensors;
        self.controller
            .set_inputs(&[x_ref, y_ref, theta_ref, s1, s2, s3]);
        self.plant.set_inputs(&self.commands);
        self.controller.do_step(h);
        self.plant.do_step(h);
        self.commands = self.controller.get_outputs();
        self.sensors = self.plant.get_outputs();
        self.sensors
    }
}

/// [`AbiLoop`] with the models called directly: the same data flow, no FMI.
pub struct DirectLoop {
    controller: PiezoController,
    plant: FlexureStage,
    signal: ControllerSignal,
    commands: [f64; 3],
    sensors: [f64; 3],
}

impl DirectLoop {
    pub fn new(h: f64) -> Self {
        DirectLoop {
            controller: direct_controller(),
            plant: direct_plant(),
            signal: ControllerSignal::new(h),
            commands: [0.0; 3],
            sensors: [0.0; 3],
        }
    }

    #[inline]
    pub fn step(&mut self, h: f64) -> [f64; 3] {
        let [x_ref, y_ref, theta_ref, ..] = self.signal.sample();
        let [s1, s2, s3] = self.sensors;
        let commands = controller_step(
            &mut self.controller,
            &[x_ref, y_ref, theta_ref, s1, s2, s3],
            h,
        );
        self.sensors = plant_step(&mut self.plant, self.commands, h);
        self.commands = commands;
        self.sensors
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phasor_is_a_one_hertz_sine() {
        let mut phasor = Phasor::new(SIGNAL_HZ, STEP);
        // A quarter period (2500 samples) later the phase is π/2; after a
        // million samples (100 periods) the sine is still exact to 1e-9.
        for k in 0..1_000_000u32 {
            let (sin, cos) = phasor.sample();
            if k % 2500 == 0 || k == 999_999 {
                let phase = TAU * SIGNAL_HZ * STEP * f64::from(k);
                assert!((sin - phase.sin()).abs() < 1e-9, "sample {k}: {sin}");
                assert!((cos - phase.cos()).abs() < 1e-9, "sample {k}: {cos}");
            }
        }
    }

    #[test]
    fn plant_commands_span_the_full_range() {
        let mut signal = PlantSignal::new(STEP);
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for _ in 0..10_000 {
            for (c, u) in signal.sample().into_iter().enumerate() {
                lo[c] = lo[c].min(u);
                hi[c] = hi[c].max(u);
            }
        }
        for c in 0..3 {
            assert!(lo[c] > -1e-9 && lo[c] < 1e-3, "channel {c}: min {}", lo[c]);
            assert!(hi[c] < 10.0 + 1e-9 && hi[c] > 10.0 - 1e-3, "max {}", hi[c]);
        }
    }

    #[test]
    fn controller_inputs_stay_near_the_references() {
        let mut signal = ControllerSignal::new(STEP);
        for _ in 0..10_000 {
            let [x_ref, y_ref, theta_ref, s1, s2, s3] = signal.sample();
            assert!((1.0..=11.0).contains(&y_ref));
            assert_eq!((x_ref, theta_ref), (X_REF_UM, 0.0));
            assert!((s1 - y_ref).abs() <= 0.05 + 1e-12);
            assert!((s2 - x_ref).abs() <= 0.02 + 1e-12 && (s3 - x_ref).abs() <= 0.02 + 1e-12);
        }
    }
}

/// Interleaved timing of workloads that are to be compared with each other.
///
/// On a shared machine (and a virtual one, whose host may run another guest
/// on the sibling hyperthread) the speed of a core drifts by tens of percent
/// within seconds, so two criterion benchmarks timed one after the other
/// can differ by more than the few percent an overhead ratio is about.
/// Here the workloads take turns in short blocks (well under a millisecond
/// each), every round gives one ratio from blocks that ran within a
/// millisecond of each other, and the median over many rounds is the ratio.
pub mod paired {
    use std::time::Instant;

    /// A workload that runs `n` samples when called.
    pub type Block<'a> = &'a mut dyn FnMut(usize);

    /// Runs every workload for `block` samples per round, `rounds` times,
    /// starting each round with the next workload in turn (so that none is
    /// always the first after another one's cache footprint). Returns the
    /// ns per sample of every workload in every round.
    pub fn interleave(workloads: &mut [Block<'_>], block: usize, rounds: usize) -> Vec<Vec<f64>> {
        let count = workloads.len();
        let mut times = vec![Vec::with_capacity(rounds); count];
        for round in 0..rounds {
            for k in 0..count {
                let w = (round + k) % count;
                let start = Instant::now();
                (workloads[w])(block);
                times[w].push(start.elapsed().as_nanos() as f64 / block as f64);
            }
        }
        times
    }

    /// Median and quartiles of `values` (sorted in place).
    pub fn quartiles(values: &mut [f64]) -> [f64; 3] {
        assert!(!values.is_empty(), "no values");
        values.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let position = q * (values.len() - 1) as f64;
            let (lo, hi) = (position.floor() as usize, position.ceil() as usize);
            values[lo] + (values[hi] - values[lo]) * (position - lo as f64)
        };
        [at(0.25), at(0.5), at(0.75)]
    }

    /// Per-round ratios `f(round's times) ` summarised by their quartiles.
    pub fn ratio_quartiles(times: &[Vec<f64>], f: impl Fn(&[f64]) -> f64) -> [f64; 3] {
        let rounds = times.first().map_or(0, Vec::len);
        let mut ratios: Vec<f64> = (0..rounds)
            .map(|r| f(&times.iter().map(|t| t[r]).collect::<Vec<_>>()))
            .collect();
        quartiles(&mut ratios)
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn quartiles_interpolate() {
            assert_eq!(quartiles(&mut [4.0, 1.0, 3.0, 2.0, 5.0]), [2.0, 3.0, 4.0]);
            assert_eq!(quartiles(&mut [1.0, 2.0]), [1.25, 1.5, 1.75]);
        }

        #[test]
        fn every_workload_runs_every_round() {
            let (mut a, mut b) = (0usize, 0usize);
            let mut run_a = |n: usize| a += n;
            let mut run_b = |n: usize| b += n;
            let times = interleave(&mut [&mut run_a, &mut run_b], 10, 7);
            assert_eq!(times.len(), 2);
            assert!(times.iter().all(|t| t.len() == 7));
            assert_eq!((a, b), (70, 70));
        }
    }
}
