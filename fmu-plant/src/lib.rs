//! FlexureStage FMU: seed 000's 3-DOF piezo flexure stage (x, y, θz; three
//! PZTs; first mode 790 Hz in θz), each actuator an asymmetric Bouc-Wen model
//! with seed 001's coupled hysteresis, as an FMI 2.0 co-simulation slave and
//! model-exchange model (one binary, one modelDescription).
//!
//! This crate is the thin join of `fmi2-cosim` (which knows nothing of piezos)
//! and `piezo-models` (which knows nothing of FMI): a variable table, units, and
//! `CoSimModel` and `ModelExchange` implementations that forward to
//! [`FlexureStage`] (its step, and its ODE form `piezo_models::flexure_stage::ode`).

use fmi2_cosim::model_description::format_real;
use fmi2_cosim::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, EventUpdate, FmiState, Interface, ModelError,
    ModelExchange, ModelExchangeInfo, ModelInfo, Status, StepOutcome, UnitDefinition, Variability,
    Variable, units,
};
use piezo_models::flexure_stage::ode::{self, NUMBER_OF_STATES};
use piezo_models::{
    ActuatorParams, AmplifierParams, FlexureStage, FlexureStageParams, ModeParams, Range,
    SensorNoiseParams, SolverParams,
};
use serde::{Deserialize, Serialize};

/// The FMU's model: the parameters the importer sets, the held input
/// commands, and the stage built from the parameters at initialization.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FlexureStageFmu {
    params: FlexureStageParams,
    commands: [f64; 3],
    stage: FlexureStage,
    /// Whether clipping of each amplifier channel was already reported: the
    /// warning is logged once per channel, not at every step.
    clip_reported: [bool; 3],
}

impl FlexureStageFmu {
    /// A model holding `params` as its parameter values (as if an importer
    /// had set each of them), at rest.
    pub fn with_params(params: FlexureStageParams) -> Result<Self, piezo_models::ParamError> {
        let stage = FlexureStage::new(params.clone())?;
        Ok(FlexureStageFmu {
            params,
            commands: [0.0; 3],
            stage,
            clip_reported: [false; 3],
        })
    }
    pub fn params(&self) -> &FlexureStageParams {
        &self.params
    }

    pub fn stage(&self) -> &FlexureStage {
        &self.stage
    }

    /// The state derivatives at the current state and commands, in
    /// `piezo_models::flexure_stage::ode::STATES` order.
    fn derivatives(&self) -> [f64; NUMBER_OF_STATES] {
        self.stage.derivatives(self.commands)
    }

    /// Logs, once per channel, a command that the amplifier limits clip.
    fn report_clipping(&mut self, ctx: &Context<'_>, time: f64, clipped: [bool; 3]) -> Status {
        let mut status = Status::Ok;
        for (channel, clipped) in clipped.iter().enumerate() {
            if *clipped && !self.clip_reported[channel] {
                self.clip_reported[channel] = true;
                let amp = &self.params.amplifier;
                ctx.warning(format_args!(
                    "t = {time}: PZT{} command u{} = {} V asks the amplifier for {} V, \
                     outside its input range {}..{} V or output range {}..{} V; the output is \
                     clipped (reported once per channel)",
                    channel + 1,
                    channel + 1,
                    // 1e308 in 6 characters, not 309 digits.
                    format_real(self.commands[channel]),
                    format_real(amp.gain * self.commands[channel]),
                    amp.input_min,
                    amp.input_max,
                    amp.v_min,
                    amp.v_max
                ));
                status = Status::Warning;
            }
        }
        status
    }

    /// Model Exchange, after an accepted integrator step or at an event: a
    /// state that left the physical domain ends the simulation; clipping is
    /// reported as in a co-simulation step.
    fn supervise(&mut self, ctx: &Context<'_>, time: f64) -> Result<Status, ModelError> {
        if let Some(fault) = self.stage.check_state() {
            return Err(ModelError(format!(
                "the stage diverged: {}",
                self.divergence(fault, Interface::ModelExchange)
            )));
        }
        let amplifier = self.params.amplifier;
        let clipped = self.commands.map(|u| amplifier.target(u).1);
        Ok(self.report_clipping(ctx, time, clipped))
    }
}

const UNITS: &[UnitDefinition] = &[
    units::VOLT,
    units::MICROMETRE,
    units::MILLIMETRE,
    units::RADIAN,
    units::HERTZ,
    units::SECOND,
    piezo_fmu_tables::MICROMETRE_PER_VOLT,
    // Rates of the continuous states (Model Exchange).
    UnitDefinition {
        name: "V/s",
        base: BaseUnit {
            kg: 1,
            m: 2,
            s: -4,
            a: -1,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
    UnitDefinition {
        name: "um/s",
        base: BaseUnit {
            m: 1,
            s: -1,
            factor: 1e-6,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
    UnitDefinition {
        name: "um/s2",
        base: BaseUnit {
            m: 1,
            s: -2,
            factor: 1e-6,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
    UnitDefinition {
        name: "rad/s",
        base: BaseUnit {
            s: -1,
            rad: 1,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
    UnitDefinition {
        name: "rad/s2",
        base: BaseUnit {
            s: -2,
            rad: 1,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
    piezo_fmu_tables::MICROMETRE_PER_VOLT_SQUARED,
];

/// Ports first (the names users wire), then diagnostics.
const PORTS: &[Variable<FlexureStageFmu>] = &[
    Variable::real_input(
        "u1",
        "Command voltage of the PZT1 amplifier channel (drives y), 0..10 V for 0..100 V (-3..13 V accepted)",
        "V",
        |m| m.commands[0],
        |m, v| m.commands[0] = v,
    ),
    Variable::real_input(
        "u2",
        "Command voltage of the PZT2 amplifier channel (x pair), 0..10 V for 0..100 V (-3..13 V accepted)",
        "V",
        |m| m.commands[1],
        |m, v| m.commands[1] = v,
    ),
    Variable::real_input(
        "u3",
        "Command voltage of the PZT3 amplifier channel (x pair), 0..10 V for 0..100 V (-3..13 V accepted)",
        "V",
        |m| m.commands[2],
        |m, v| m.commands[2] = v,
    ),
    // No direct feedthrough from u1..u3; in Model Exchange the sensors are
    // computed from the pose states (x, y, theta_z are states themselves).
    Variable::real_output(
        "s1",
        "Laser sensor s1: y displacement",
        "um",
        |m: &FlexureStageFmu| m.stage.sensors()[0],
    )
    .depends_on(&["y"]),
    Variable::real_output(
        "s2",
        "Laser sensor s2: x + theta_z·L/2",
        "um",
        |m: &FlexureStageFmu| m.stage.sensors()[1],
    )
    .depends_on(&["x", "theta_z"]),
    Variable::real_output(
        "s3",
        "Laser sensor s3: x − theta_z·L/2",
        "um",
        |m: &FlexureStageFmu| m.stage.sensors()[2],
    )
    .depends_on(&["x", "theta_z"]),
    // The pose outputs are the pose states: each depends on itself.
    Variable::real_output(
        "x",
        "True platform x (no sensor noise)",
        "um",
        |m: &FlexureStageFmu| m.stage.pose().x_um,
    )
    .depends_on(&["x"]),
    Variable::real_output(
        "y",
        "True platform y (no sensor noise)",
        "um",
        |m: &FlexureStageFmu| m.stage.pose().y_um,
    )
    .depends_on(&["y"]),
    Variable::<FlexureStageFmu>::real_output(
        "theta_z",
        "True platform rotation about z (no sensor noise)",
        "rad",
        |m| m.stage.pose().theta_rad,
    )
    .display_unit("deg")
    .depends_on(&["theta_z"]),
    Variable::real_local(
        "amplifier.voltage[1]",
        "PZT1 amplifier output voltage",
        "V",
        |m| m.stage.amplifier_voltages()[0],
    ),
    Variable::real_local(
        "amplifier.voltage[2]",
        "PZT2 amplifier output voltage",
        "V",
        |m| m.stage.amplifier_voltages()[1],
    ),
    Variable::real_local(
        "amplifier.voltage[3]",
        "PZT3 amplifier output voltage",
        "V",
        |m| m.stage.amplifier_voltages()[2],
    ),
];

const AMPLIFIER: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.gain",
        "Amplifier voltage gain, > 0 (Guo et al. §3.2: 10)",
        "",
        AmplifierParams::GAIN,
        amplifier.gain
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.bandwidth",
        "Amplifier first-order bandwidth, > 0",
        "Hz",
        AmplifierParams::BANDWIDTH_HZ,
        amplifier.bandwidth_hz
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.v_min",
        "Lowest amplifier output voltage (PI E-505: -30 V)",
        "V",
        Range::FINITE,
        amplifier.v_min
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.v_max",
        "Highest amplifier output voltage (PI E-505: 130 V)",
        "V",
        Range::FINITE,
        amplifier.v_max
    ),
];

const PZT1_CREEP: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[1].creep_gain",
        "PZT1 creep: steady drift per volt",
        "um/V",
        ActuatorParams::CREEP_GAIN,
        actuators[0].creep_gain
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[1].creep_time",
        "PZT1 creep time constant, > 0 and more than 10 amplifier time constants",
        "s",
        ActuatorParams::CREEP_TIME,
        actuators[0].creep_time
    ),
];

const PZT2_CREEP: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[2].creep_gain",
        "PZT2 creep: steady drift per volt",
        "um/V",
        ActuatorParams::CREEP_GAIN,
        actuators[1].creep_gain
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[2].creep_time",
        "PZT2 creep time constant, > 0 and more than 10 amplifier time constants",
        "s",
        ActuatorParams::CREEP_TIME,
        actuators[1].creep_time
    ),
];

const PZT3_CREEP: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[3].creep_gain",
        "PZT3 creep: steady drift per volt",
        "um/V",
        ActuatorParams::CREEP_GAIN,
        actuators[2].creep_gain
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "pzt[3].creep_time",
        "PZT3 creep time constant, > 0 and more than 10 amplifier time constants",
        "s",
        ActuatorParams::CREEP_TIME,
        actuators[2].creep_time
    ),
];

// The actuators' hysteresis and the coupled hysteresis (seed 001 eq. 3-4,
// 7-8); their value references follow BLOCKS' order, not this one.
piezo_fmu_tables::bouc_wen_blocks! {
    FlexureStageFmu;
    PZT1_HYSTERESIS = ("pzt[1]", "PZT1 hysteresis", actuators[0].hysteresis);
    PZT2_HYSTERESIS = ("pzt[2]", "PZT2 hysteresis", actuators[1].hysteresis);
    PZT3_HYSTERESIS = ("pzt[3]", "PZT3 hysteresis", actuators[2].hysteresis);
    COUPLING_X_FROM_PZT1_HYSTERESIS = ("coupling.x_from_pzt1", "Coupling PZT1 voltage -> x", coupling.x_from_pzt1);
    COUPLING_ROT_FROM_PZT1_HYSTERESIS = ("coupling.rot_from_pzt1", "Coupling PZT1 voltage -> s2 − s3 (rotation)", coupling.rot_from_pzt1);
    COUPLING_Y_FROM_PZT2_HYSTERESIS = ("coupling.y_from_pzt2", "Coupling PZT2 voltage -> y", coupling.y_from_pzt2);
    COUPLING_Y_FROM_PZT3_HYSTERESIS = ("coupling.y_from_pzt3", "Coupling PZT3 voltage -> y", coupling.y_from_pzt3);
}

const STRUCTURE_SENSORS_SOLVER: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.x.frequency",
        "Natural frequency of the x mode, > 0",
        "Hz",
        ModeParams::FREQUENCY_HZ,
        modes.x.frequency_hz
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.x.damping",
        "Damping ratio of the x mode, 0 < zeta < 1",
        "",
        ModeParams::DAMPING_RATIO,
        modes.x.damping_ratio
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.y.frequency",
        "Natural frequency of the y mode, > 0",
        "Hz",
        ModeParams::FREQUENCY_HZ,
        modes.y.frequency_hz
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.y.damping",
        "Damping ratio of the y mode, 0 < zeta < 1",
        "",
        ModeParams::DAMPING_RATIO,
        modes.y.damping_ratio
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.theta.frequency",
        "Natural frequency of the theta_z mode, the first mode, > 0 (Guo et al. §2: 790 Hz)",
        "Hz",
        ModeParams::FREQUENCY_HZ,
        modes.theta.frequency_hz
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "mode.theta.damping",
        "Damping ratio of the theta_z mode, 0 < zeta < 1",
        "",
        ModeParams::DAMPING_RATIO,
        modes.theta.damping_ratio
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "L",
        "Distance between the x sensors s2 and s3: theta_z = (s2 − s3)/L, > 0",
        "mm",
        FlexureStageParams::SENSOR_SPACING_MM,
        sensor_spacing_mm
    ),
    Variable::<FlexureStageFmu>::boolean_parameter(
        "noise.enabled",
        "Add seeded Gaussian noise to the sensor readings",
        Variability::Fixed,
        |m| m.params.noise.enabled,
        |m, v| m.params.noise.enabled = v,
    )
    .model_path("noise.enabled"),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "noise.rms",
        "Sensor noise RMS per reading (Keyence LK-H050: repeatability 0.025 um as a 99 % band)",
        "um",
        SensorNoiseParams::RMS_UM,
        noise.rms_um
    ),
    Variable::<FlexureStageFmu>::integer_parameter(
        "noise.seed",
        "Seed of the sensor noise: the same seed gives the same noise",
        Variability::Fixed,
        |m| m.params.noise.seed as i32,
        |m, v| m.params.noise.seed = v as u32,
    )
    .integer_range(Some(0), None)
    .model_path("noise.seed"),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "solver.max_voltage_step",
        "Largest amplifier-voltage change per integration piece (bounds the hysteresis chord error)",
        "V",
        SolverParams::MAX_VOLTAGE_STEP,
        solver.max_voltage_step
    ),
];

/// The amplifier's input range and the actuators' rest, added after the
/// first release: appended so that the value references of everything above
/// stay as they were.
const APPENDED: &[Variable<FlexureStageFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.input_min",
        "Lowest control input the amplifier follows (PI E-505: -3 V)",
        "V",
        Range::FINITE,
        amplifier.input_min
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "amplifier.input_max",
        "Highest control input the amplifier follows (PI E-505: 13 V)",
        "V",
        Range::FINITE,
        amplifier.input_max
    ),
    piezo_fmu_tables::fixed_parameter!(
        FlexureStageFmu,
        "rest_cycle_voltage",
        "Working loop of the stacks that sets the rest the stage starts from: each hysteresis \
         model starts at the 0 V end of its loop to this voltage, readings zeroed there (0: virgin \
         state)",
        "V",
        FlexureStageParams::REST_CYCLE_VOLTAGE,
        rest_cycle_voltage
    ),
];

/// The continuous states that are not ports, amplifier voltages or velocities
/// (Model Exchange integrates them; Co-Simulation shows them as diagnostics).
///
/// The hysteretic states start at the rest their parameters settle them into
/// (`rest_cycle_voltage`, A, beta, ...): they initially depend on every known.
const STATES: &[Variable<FlexureStageFmu>] = &[
    Variable::real_local(
        "pzt[1].h",
        "PZT1 hysteretic state h (ABW-XY eq. 3)",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[3],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "pzt[2].h",
        "PZT2 hysteretic state h (ABW-XY eq. 3)",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[4],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "pzt[3].h",
        "PZT3 hysteretic state h (ABW-XY eq. 3)",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[5],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "coupling.x_from_pzt1.h",
        "Hysteretic state of the coupling PZT1 voltage -> x",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[6],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "coupling.rot_from_pzt1.h",
        "Hysteretic state of the coupling PZT1 voltage -> s2 − s3",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[7],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "coupling.y_from_pzt2.h",
        "Hysteretic state of the coupling PZT2 voltage -> y",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[8],
    )
    .initially_depends_on_every_known(),
    Variable::real_local(
        "coupling.y_from_pzt3.h",
        "Hysteretic state of the coupling PZT3 voltage -> y",
        "um",
        |m: &FlexureStageFmu| m.stage.continuous_states()[9],
    )
    .initially_depends_on_every_known(),
    Variable::real_local("pzt[1].creep", "PZT1 creep displacement", "um", |m| {
        m.stage.continuous_states()[10]
    }),
    Variable::real_local("pzt[2].creep", "PZT2 creep displacement", "um", |m| {
        m.stage.continuous_states()[11]
    }),
    Variable::real_local("pzt[3].creep", "PZT3 creep displacement", "um", |m| {
        m.stage.continuous_states()[12]
    }),
];

/// A state derivative of Model Exchange: the `$k`-th entry of the stage's
/// right-hand side.
macro_rules! derivative {
    ($state:literal, $unit:literal, $k:literal, [$($dependency:literal),* $(,)?]) => {
        Variable::real_local(
            concat!("der(", $state, ")"),
            concat!("Time derivative of ", $state),
            $unit,
            |m: &FlexureStageFmu| m.derivatives()[$k],
        )
        .derivative_of($state, &[$($dependency),*])
    };
}

/// The state derivatives, in the order of the state vector
/// (`piezo_models::flexure_stage::ode::STATES`): the table order of the
/// derivatives is the order of Model Exchange's state vector. The velocities
/// are states and the derivatives of x, y, theta_z (which start at rest, as
/// every state does). Dependencies: what each rate is computed from
/// (MODEL.md §2), checked numerically by the ABI tests.
const DERIVATIVES: &[Variable<FlexureStageFmu>] = &[
    derivative!(
        "amplifier.voltage[1]",
        "V/s",
        0,
        ["u1", "amplifier.voltage[1]"]
    ),
    derivative!(
        "amplifier.voltage[2]",
        "V/s",
        1,
        ["u2", "amplifier.voltage[2]"]
    ),
    derivative!(
        "amplifier.voltage[3]",
        "V/s",
        2,
        ["u3", "amplifier.voltage[3]"]
    ),
    derivative!(
        "pzt[1].h",
        "um/s",
        3,
        ["u1", "amplifier.voltage[1]", "pzt[1].h"]
    ),
    derivative!(
        "pzt[2].h",
        "um/s",
        4,
        ["u2", "amplifier.voltage[2]", "pzt[2].h"]
    ),
    derivative!(
        "pzt[3].h",
        "um/s",
        5,
        ["u3", "amplifier.voltage[3]", "pzt[3].h"]
    ),
    derivative!(
        "coupling.x_from_pzt1.h",
        "um/s",
        6,
        ["u1", "amplifier.voltage[1]", "coupling.x_from_pzt1.h"]
    ),
    derivative!(
        "coupling.rot_from_pzt1.h",
        "um/s",
        7,
        ["u1", "amplifier.voltage[1]", "coupling.rot_from_pzt1.h"]
    ),
    derivative!(
        "coupling.y_from_pzt2.h",
        "um/s",
        8,
        ["u2", "amplifier.voltage[2]", "coupling.y_from_pzt2.h"]
    ),
    derivative!(
        "coupling.y_from_pzt3.h",
        "um/s",
        9,
        ["u3", "amplifier.voltage[3]", "coupling.y_from_pzt3.h"]
    ),
    derivative!(
        "pzt[1].creep",
        "um/s",
        10,
        ["amplifier.voltage[1]", "pzt[1].creep"]
    ),
    derivative!(
        "pzt[2].creep",
        "um/s",
        11,
        ["amplifier.voltage[2]", "pzt[2].creep"]
    ),
    derivative!(
        "pzt[3].creep",
        "um/s",
        12,
        ["amplifier.voltage[3]", "pzt[3].creep"]
    ),
    Variable::real_local(
        "velocity.x",
        "Platform x velocity: der(x)",
        "um/s",
        |m: &FlexureStageFmu| m.stage.continuous_states()[16],
    )
    .derivative_of("x", &["velocity.x"])
    .initially_depends_on(&[]),
    Variable::real_local(
        "velocity.y",
        "Platform y velocity: der(y)",
        "um/s",
        |m: &FlexureStageFmu| m.stage.continuous_states()[17],
    )
    .derivative_of("y", &["velocity.y"])
    .initially_depends_on(&[]),
    Variable::real_local(
        "velocity.theta_z",
        "Platform rotation rate: der(theta_z)",
        "rad/s",
        |m: &FlexureStageFmu| m.stage.continuous_states()[18],
    )
    .derivative_of("theta_z", &["velocity.theta_z"])
    .initially_depends_on(&[]),
    // x_qs = (e2 + e3)/2 + d_x1 (seed 000 §2).
    derivative!(
        "velocity.x",
        "um/s2",
        16,
        [
            "x",
            "velocity.x",
            "amplifier.voltage[1]",
            "amplifier.voltage[2]",
            "amplifier.voltage[3]",
            "pzt[2].h",
            "pzt[3].h",
            "pzt[2].creep",
            "pzt[3].creep",
            "coupling.x_from_pzt1.h",
        ]
    ),
    // y_qs = e1 + d_y2 + d_y3.
    derivative!(
        "velocity.y",
        "um/s2",
        17,
        [
            "y",
            "velocity.y",
            "amplifier.voltage[1]",
            "amplifier.voltage[2]",
            "amplifier.voltage[3]",
            "pzt[1].h",
            "pzt[1].creep",
            "coupling.y_from_pzt2.h",
            "coupling.y_from_pzt3.h",
        ]
    ),
    // theta_qs = (e2 − e3 + d_rot1)/L.
    derivative!(
        "velocity.theta_z",
        "rad/s2",
        18,
        [
            "theta_z",
            "velocity.theta_z",
            "amplifier.voltage[1]",
            "amplifier.voltage[2]",
            "amplifier.voltage[3]",
            "pzt[2].h",
            "pzt[3].h",
            "pzt[2].creep",
            "pzt[3].creep",
            "coupling.rot_from_pzt1.h",
        ]
    ),
];

/// The blocks of the table, in value-reference order.
///
/// APPEND ONLY. A variable's value reference is its position in this table,
/// and importers keep value references (saved models, SSP parameter sets,
/// compiled wiring): a new variable goes at the end (a new block after the
/// last), never between existing ones, and no variable is removed or moved.
/// `valueReferences.txt` beside this crate records every name's reference
/// and a test fails when an existing one changes.
const BLOCKS: &[&[Variable<FlexureStageFmu>]] = &[
    PORTS,
    AMPLIFIER,
    PZT1_HYSTERESIS,
    PZT1_CREEP,
    PZT2_HYSTERESIS,
    PZT2_CREEP,
    PZT3_HYSTERESIS,
    PZT3_CREEP,
    COUPLING_X_FROM_PZT1_HYSTERESIS,
    COUPLING_ROT_FROM_PZT1_HYSTERESIS,
    COUPLING_Y_FROM_PZT2_HYSTERESIS,
    COUPLING_Y_FROM_PZT3_HYSTERESIS,
    STRUCTURE_SENSORS_SOLVER,
    APPENDED,
    STATES,
    DERIVATIVES,
    MINOR_LOOPS,
];

/// Whether the stacks' minor loops close, added after the states and their
/// derivatives: last, so that every earlier value reference stays.
const MINOR_LOOPS: &[Variable<FlexureStageFmu>] =
    &[Variable::<FlexureStageFmu>::boolean_parameter(
        "return_point_memory",
        "Close the stacks' minor loops, as a real stack's close: each branch is the Bouc-Wen \
         branch (ABW-XY eq. 3) tilted to end at the reversal it returns to, and an excursion past \
         a reversal wipes its loop out (false: eq. 3 as integrated; its minor loops drift and \
         dither ratchets it). In Model Exchange the memory is discrete state, updated at the \
         turn and wipe-out event indicators",
        Variability::Fixed,
        |m| m.params.return_point_memory,
        |m, v| m.params.return_point_memory = v,
    )
    .model_path("return_point_memory")];

/// Every variable, in value-reference order.
static VARIABLES: [Variable<FlexureStageFmu>; piezo_fmu_tables::total_len(BLOCKS)] =
    fmi2_cosim::variables::concat(BLOCKS);

impl CoSimModel for FlexureStageFmu {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "FlexureStage",
        model_name: "FlexureStage",
        description: "3-DOF piezo-driven flexure stage (x, y, theta_z; three PZTs with asymmetric \
                      Bouc-Wen hysteresis and coupled hysteresis; first mode 790 Hz in theta_z); \
                      Co-Simulation and Model Exchange (19 continuous states; 21 event indicators: per Bouc-Wen model, its branch state and the return-point memory's turn and wipe-out)",
        author: "piezo-fmu project",
        version: env!("CARGO_PKG_VERSION"),
        license: "MIT OR Apache-2.0",
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-4,
        },
    };
    const UNITS: &'static [UnitDefinition] = UNITS;
    const MODEL_EXCHANGE: Option<ModelExchangeInfo> = Some(ModelExchangeInfo {
        number_of_continuous_states: NUMBER_OF_STATES,
        // Per Bouc-Wen model: its branch state, where its rate changes form,
        // and the return-point memory's turn and wipe-out. No event for the
        // amplifier's clipping: it clips its target G·u, a function of the
        // inputs alone (piezo_models::flexure_stage::ode).
        number_of_event_indicators: ode::NUMBER_OF_SWITCHING_FUNCTIONS,
    });

    fn variables() -> &'static [Variable<Self>] {
        &VARIABLES
    }

    fn new() -> Self {
        Self::with_params(FlexureStageParams::default())
            .expect("the shipped preset validates (tested in piezo-models)")
    }

    fn exit_initialization_mode(
        &mut self,
        ctx: &mut Context<'_>,
        _start_time: f64,
    ) -> Result<(), ModelError> {
        if ctx.interface() == Interface::ModelExchange && self.params.noise.enabled {
            return Err(ModelError(
                "noise.enabled = true: the sensor noise is one sample per communication step, \
                 and Model Exchange has none; add the noise in the importer, or use \
                 Co-Simulation"
                    .to_owned(),
            ));
        }
        // The stage starts de-energized and at rest, whatever the inputs: the
        // actuators have no history before t0. The hysteresis models' rests
        // settled at instantiation are kept where their parameters did not
        // change (settling is most of fmi2Instantiate's cost).
        self.stage = self
            .stage
            .at_rest_with(self.params.clone())
            .map_err(refused_parameter)?;
        self.clip_reported = [false; 3];
        ctx.event(format_args!("stage built from the parameters, at rest"));
        Ok(())
    }

    // Inlined into the FMI entry point: one call less on every step.
    #[inline]
    fn do_step(
        &mut self,
        ctx: &mut Context<'_>,
        current_time: f64,
        step_size: f64,
    ) -> Result<StepOutcome, ModelError> {
        let report = self.stage.step(self.commands, step_size);
        if let Some(fault) = report.fault {
            // Never hand a diverged state on as outputs: the importer gets
            // fmi2Error and the instance stays unusable until reset.
            return Err(self.diverged(current_time, step_size, fault));
        }
        // Clipping is logged once per channel: most steps have nothing new
        // to report, and skip the call.
        let unreported: [bool; 3] =
            std::array::from_fn(|c| report.clipped[c] & !self.clip_reported[c]);
        if unreported == [false; 3] {
            return Ok(StepOutcome::Completed);
        }
        Ok(
            match self.report_clipping(ctx, current_time, report.clipped) {
                Status::Ok => StepOutcome::Completed,
                _ => StepOutcome::CompletedWithWarning,
            },
        )
    }

    /// Past initialization the stage was built from the FMU's parameters:
    /// it must hold the same ones, and is rebuilt from them and its dynamic
    /// state (`FlexureStage::rebuilt` validates both). Before it,
    /// `exit_initialization_mode` validates and builds everything.
    fn validate_restored(
        &mut self,
        _ctx: &mut Context<'_>,
        state: FmiState,
    ) -> Result<(), ModelError> {
        // Whatever the machine state, the stage the instance holds was built
        // from valid parameters (its constructor refuses others), so it can
        // be rebuilt; its dynamic state may be non-finite only in the error
        // state, which a diverged step leaves.
        self.stage = self.stage.rebuilt().map_err(refused_parameter)?;
        if state != FmiState::Error
            && let Some(unreachable) = self.stage.unreachable_state()
        {
            return Err(ModelError(unreachable.to_string()));
        }
        // Past initialization it was built from the FMU's parameters.
        if !state.initialized() {
            return Ok(());
        }
        if self.stage.params() != &self.params {
            return Err(ModelError(
                "the stage's parameters differ from the FMU's: the state was not taken from \
                 an instance of this FMU"
                    .to_owned(),
            ));
        }
        Ok(())
    }
}

/// A parameter piezo-models refuses, named as the importer knows it.
fn refused_parameter(e: piezo_models::ParamError) -> ModelError {
    piezo_fmu_tables::refused_parameter(&VARIABLES, &e)
}

impl FlexureStageFmu {
    #[cold]
    #[inline(never)]
    fn diverged(
        &self,
        current_time: f64,
        step_size: f64,
        fault: piezo_models::flexure_stage::StateFault,
    ) -> ModelError {
        ModelError(format!(
            "the stage diverged in the step from t = {current_time} to t = {}: {}",
            current_time + step_size,
            self.divergence(fault, Interface::CoSimulation)
        ))
    }

    /// What diverged, with the commands, and the likely cause: the modes are
    /// stable and the amplifier bounded, so a state leaves the physical
    /// domain only through a Bouc-Wen model that runs away on a path its
    /// build did not check, a sensor spacing too small for the platform's
    /// rotation, an absurd gain, or, in Model Exchange, an integrator step
    /// too long for the modes.
    fn divergence(
        &self,
        fault: piezo_models::flexure_stage::StateFault,
        interface: Interface,
    ) -> String {
        let modes = &self.params.modes;
        let fastest = [modes.x, modes.y, modes.theta]
            .into_iter()
            .max_by(|a, b| a.frequency_hz.total_cmp(&b.frequency_hz))
            .expect("three modes");
        let omega = 2.0 * std::f64::consts::PI * fastest.frequency_hz;
        let cause = if fault.variable.starts_with("hysteretic state") {
            "a Bouc-Wen model whose state runs away on this run's input path (the build checks \
             one cycle from the virgin state over the amplifier's range, within ±1 kV; beta + \
             gamma < 0 steepens the loading branch); check that model's parameters"
                .to_owned()
        } else if fault.variable.contains("theta_z") && interface == Interface::CoSimulation {
            format!(
                "a rotation beyond {} rad: theta_z is the stacks' differential motion over the \
                 sensor spacing L = {} mm, too small for it",
                piezo_models::flexure_stage::DIVERGED_ROTATION_RAD,
                self.params.sensor_spacing_mm
            )
        } else if interface == Interface::ModelExchange {
            format!(
                "an integrator step too long for the stage's modes: the fastest, {} Hz with \
                 damping ratio {}, keeps explicit Euler stable only below 2·zeta/omega = {:.3e} \
                 s; use a variable-step solver (CVode) or a shorter step",
                fastest.frequency_hz,
                fastest.damping_ratio,
                2.0 * fastest.damping_ratio / omega
            )
        } else {
            "a gain that drives the platform or a creep state beyond 1 m (a stack's p, a creep \
             gain, the amplifier gain); check them"
                .to_owned()
        };
        format!(
            "{} = {} (non-finite, or beyond {} um / {} rad) with commands u1..u3 = {:?} V; \
             likely cause: {cause}",
            fault.variable,
            fault.value,
            piezo_models::flexure_stage::DIVERGED_DISPLACEMENT_UM,
            piezo_models::flexure_stage::DIVERGED_ROTATION_RAD,
            self.commands
        )
    }
}

impl ModelExchange for FlexureStageFmu {
    fn continuous_states(&self, states: &mut [f64]) {
        states.copy_from_slice(&self.stage.continuous_states());
    }

    fn set_continuous_states(&mut self, states: &[f64]) {
        let states: &[f64; NUMBER_OF_STATES] =
            states.try_into().expect("the layer checks the length");
        self.stage.set_continuous_states(states);
    }

    fn derivatives(&self, _time: f64, derivatives: &mut [f64]) {
        derivatives.copy_from_slice(&self.derivatives());
    }

    fn nominals(&self, nominals: &mut [f64]) {
        nominals.copy_from_slice(&ode::state_nominals(&self.params));
    }

    fn event_indicators(&self, _time: f64, indicators: &mut [f64]) {
        indicators.copy_from_slice(&self.stage.switching_functions(self.commands));
    }

    fn update_discrete_states(
        &mut self,
        ctx: &mut Context<'_>,
        time: f64,
    ) -> Result<EventUpdate, ModelError> {
        // The return-point memory is the discrete state: a turn of a
        // voltage is remembered, a wipe-out moves a hysteretic state onto
        // the branch it continues (the integrator reads the states again).
        let values_changed = self.stage.settle_memories(self.commands);
        self.supervise(ctx, time)?;
        Ok(EventUpdate {
            values_changed,
            ..EventUpdate::default()
        })
    }

    fn completed_integrator_step(
        &mut self,
        ctx: &mut Context<'_>,
        time: f64,
    ) -> Result<Status, ModelError> {
        self.supervise(ctx, time)
    }
}

fmi2_cosim::export_fmi2!(FlexureStageFmu, model_exchange);
