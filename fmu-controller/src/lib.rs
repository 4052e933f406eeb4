//! PiezoController FMU: seed 000's controller for the 3-DOF flexure stage
//! (modified inverse Prandtl-Ishlinskii feedforward, PI feedback and the
//! decoupling law, eq. 3-5, 10-12) as an FMI 2.0 co-simulation slave.
//!
//! This crate is the thin join of `fmi2-cosim` (which knows nothing of piezos)
//! and `piezo-models` (which knows nothing of FMI): a variable table, units, and
//! a `CoSimModel` implementation that forwards to [`PiezoController`].
//!
//! Timing: the controller samples its inputs (references and sensors) at the
//! communication point t_k where `fmi2DoStep(t_k, h)` starts and its outputs,
//! computed from them, hold from the end of the step: one sample of compute
//! delay, as on a DSP that writes its outputs at the next sample. The outputs
//! are 0 V until the first step, so the stage starts de-energized.

use fmi2_cosim::variables::Value;
use fmi2_cosim::{
    BaseUnit, Causality, CoSimModel, Context, DefaultExperiment, FmiState, ModelError, ModelInfo,
    StepOutcome, UnitDefinition, Variability, Variable, units,
};
use piezo_models::{
    BoucWenModels, ControllerOutput, ControllerParams, DecouplingModel, HysteresisModel,
    InversePiParams, PiGains, PiezoController, Range,
};
use serde::{Deserialize, Serialize};

/// The FMU's model: the parameters the importer sets, the inputs it writes,
/// and the controller built from the parameters at initialization.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PiezoControllerFmu {
    params: ControllerParams,
    /// x_ref [µm], y_ref [µm], theta_ref [rad].
    references: [f64; 3],
    /// s1, s2, s3 [µm].
    sensors: [f64; 3],
    controller: PiezoController,
    /// Whether limiting of each command was already logged (once per channel,
    /// not at every step).
    saturation_reported: [bool; 3],
    /// The Integer codes of `hysteresis_model` and `decoupling_model` as the
    /// importer set them; checked and turned into the selectors at
    /// initialization (a wrong code is refused there, by name).
    selector_codes: [i32; 2],
}

/// The selector value of an Integer code, if it is one.
fn selected<T: Copy>(codes: &[(i32, T)], code: i32) -> Option<T> {
    codes.iter().find(|(c, _)| *c == code).map(|(_, v)| *v)
}

/// The Integer code of a selector value (`CODES` of piezo-models).
fn code_of<T: PartialEq + Copy>(codes: &[(i32, T)], value: T) -> i32 {
    codes
        .iter()
        .find(|(_, v)| *v == value)
        .map(|(c, _)| *c)
        .expect("every selector value has a code")
}

impl PiezoControllerFmu {
    /// A model holding `params` as its parameter values (as if an importer
    /// had set each of them), with an idle controller.
    pub fn with_params(params: ControllerParams) -> Result<Self, piezo_models::ParamError> {
        let controller = PiezoController::new(params.clone())?;
        let selector_codes = [
            code_of(&HysteresisModel::CODES, params.hysteresis_model),
            code_of(&DecouplingModel::CODES, params.decoupling_model),
        ];
        Ok(PiezoControllerFmu {
            params,
            references: [0.0; 3],
            sensors: [0.0; 3],
            selector_codes,
            controller,
            saturation_reported: [false; 3],
        })
    }
    pub fn params(&self) -> &ControllerParams {
        &self.params
    }

    pub fn controller(&self) -> &PiezoController {
        &self.controller
    }

    fn output(&self) -> &ControllerOutput {
        self.controller.output()
    }

    /// Writes a tunable parameter both where the importer reads it back and
    /// into the running controller.
    fn tune(&mut self, tuning: impl Fn(&mut ControllerParams)) {
        tuning(&mut self.params);
        self.controller.set_tuning(tuning);
    }
}

/// Unit of the y³ coefficient of G and similar: V per µm^k (and V·s/µm² for
/// the rate slopes of eq. 4). Volt = kg·m²·s⁻³·A⁻¹.
const fn volt_per(m: i8, s: i8, factor: f64) -> BaseUnit {
    BaseUnit {
        kg: 1,
        m: 2 - m,
        s: -3 - s,
        a: -1,
        factor,
        ..BaseUnit::NONE
    }
}

const UNITS: &[UnitDefinition] = &[
    units::VOLT,
    units::MICROMETRE,
    units::MILLIMETRE,
    units::RADIAN,
    UnitDefinition {
        name: "V/um",
        base: volt_per(1, 0, 1e6),
        display_units: &[],
    },
    UnitDefinition {
        name: "V/(um.s)",
        base: volt_per(1, 1, 1e6),
        display_units: &[],
    },
    UnitDefinition {
        name: "V.s/um2",
        base: volt_per(2, -1, 1e12),
        display_units: &[],
    },
    UnitDefinition {
        name: "V/um2",
        base: volt_per(2, 0, 1e12),
        display_units: &[],
    },
    UnitDefinition {
        name: "V/um3",
        base: volt_per(3, 0, 1e18),
        display_units: &[],
    },
    // The Bouc-Wen models in command volts: p and A in µm/V, δ in µm/V².
    piezo_fmu_tables::MICROMETRE_PER_VOLT,
    piezo_fmu_tables::MICROMETRE_PER_VOLT_SQUARED,
    // Δk4 turns a rotation demand in microradians into micrometres (the
    // reading of Table 2's numbers: piezo_models::decoupling).
    UnitDefinition {
        name: "um/urad",
        base: BaseUnit {
            m: 1,
            rad: -1,
            factor: 1.0,
            ..BaseUnit::NONE
        },
        display_units: &[],
    },
];

/// An output read from the controller's last sample.
macro_rules! output {
    ($name:literal, $description:literal, $unit:literal, $($path:tt)+) => {
        Variable::real_output($name, $description, $unit, |m: &PiezoControllerFmu| {
            m.output().$($path)+
        })
    };
}

/// A tunable Real parameter whose value lives at `params.<path>`, in the
/// range piezo-models declares for it (an open end is stated in the
/// description); a new value also reaches the running controller.
macro_rules! tunable_parameter {
    ($name:expr, $description:expr, $unit:expr, $range:expr, $($path:tt)+) => {
        piezo_fmu_tables::with_range(
            Variable::real_parameter(
                $name,
                $description,
                $unit,
                Variability::Tunable,
                |m: &PiezoControllerFmu| m.params.$($path)+,
                |m: &mut PiezoControllerFmu, v: f64| m.tune(|p| p.$($path)+ = v),
            ),
            $range,
        )
        .model_path(stringify!($($path)+))
    };
}

/// A tunable Boolean switch at `params.<field>`.
macro_rules! switch {
    ($name:literal, $description:literal, $field:ident) => {
        Variable::<PiezoControllerFmu>::boolean_parameter(
            $name,
            $description,
            Variability::Tunable,
            |m| m.params.$field,
            |m, v| m.tune(|p| p.$field = v),
        )
        .model_path(stringify!($field))
    };
}

/// Fixed parameters `<prefix>.<field>[i]` for the listed 1-based indices `i`
/// of the array `params.<path>.<field>` (0-based index `j`).
macro_rules! indexed {
    ($prefix:literal, $field:ident, $description:expr, $unit:expr, $path:ident;
     $($i:literal => $j:literal),+) => {
        [$(
            Variable::real_parameter(
                concat!($prefix, ".", stringify!($field), "[", $i, "]"),
                $description,
                $unit,
                Variability::Fixed,
                |m: &PiezoControllerFmu| m.params.$path.$field[$j],
                |m: &mut PiezoControllerFmu, v: f64| m.params.$path.$field[$j] = v,
            )
            // Spelled out: stringify! spaces tokens unpredictably.
            .model_path(concat!(stringify!($path), ".", stringify!($field), "[", $j, "]"))
        ),+]
    };
}

/// The parameters of one modified inverse P-I model (seed 000 eq. 3-5).
macro_rules! inverse_pi_parameters {
    ($prefix:literal, $who:literal, $model:ident) => {{
        const K: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, k,
            concat!($who, ": slope k_i of backlash weight i with the demanded rate, w_h = k·dy/dt + b (Guo et al. eq. 4)"),
            "V.s/um2", $model;
            1 => 0, 2 => 1, 3 => 2, 4 => 3, 5 => 4, 6 => 5, 7 => 6, 8 => 7, 9 => 8, 10 => 9);
        const B: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, b,
            concat!($who, ": intercept b_i of backlash weight i (Guo et al. eq. 4)"),
            "V/um", $model;
            1 => 0, 2 => 1, 3 => 2, 4 => 3, 5 => 4, 6 => 5, 7 => 6, 8 => 7, 9 => 8, 10 => 9);
        const WS: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, ws,
            concat!($who, ": weight w_s,j of dead-zone operator j (Guo et al. eq. 3)"),
            "", $model;
            1 => 0, 2 => 1, 3 => 2, 4 => 3, 5 => 4, 6 => 5);
        const A1: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, a,
            concat!($who, ": a1 of the cubic G(y) = a1·y³ + a2·y² + a3·y + a4 (Guo et al. eq. 3, 8-9)"),
            "V/um3", $model; 1 => 0);
        const A2: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, a,
            concat!($who, ": a2 of the cubic G(y)"), "V/um2", $model; 2 => 1);
        const A3: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, a,
            concat!($who, ": a3 of the cubic G(y)"), "V/um", $model; 3 => 2);
        const A4: &[Variable<PiezoControllerFmu>] = &indexed!($prefix, a,
            concat!($who, ": a4 of the cubic G(y)"), "V", $model; 4 => 3);
        const THRESHOLDS: &[Variable<PiezoControllerFmu>] = &[
            piezo_fmu_tables::fixed_parameter!(PiezoControllerFmu, concat!($prefix, ".c"),
                concat!($who, ": scale c of the dead-zone thresholds d = c·[0,1,3,5,7,9], > 0 (Guo et al. eq. 5)"),
                "um", InversePiParams::THRESHOLD_SCALE, $model.c),
            piezo_fmu_tables::fixed_parameter!(PiezoControllerFmu, concat!($prefix, ".u1max"),
                concat!($who, ": u1max, scale of the backlash thresholds r = [0,…,6.5]·u1max/10, > 0 (Guo et al. eq. 5)"),
                "um", InversePiParams::THRESHOLD_SCALE, $model.u1max),
        ];
        const BLOCKS: &[&[Variable<PiezoControllerFmu>]] = &[K, B, WS, THRESHOLDS, A1, A2, A3, A4];
        fmi2_cosim::variables::concat::<PiezoControllerFmu, { piezo_fmu_tables::total_len(BLOCKS) }>(BLOCKS)
    }};
}

/// Which feedforward model and which decoupling law the controller runs.
const MODEL_SELECTORS: &[Variable<PiezoControllerFmu>] = &[
    Variable::<PiezoControllerFmu>::integer_parameter(
        "hysteresis_model",
        "Feedforward model: 1 = modified inverse Prandtl-Ishlinskii (Guo et al. eq. 3-5), 2 = inverse asymmetric Bouc-Wen (ABW-XY eq. 6)",
        Variability::Fixed,
        |m| m.selector_codes[0],
        |m, v| m.selector_codes[0] = v,
    )
    .integer_range(Some(1), Some(2))
    .model_path("hysteresis_model"),
    Variable::<PiezoControllerFmu>::integer_parameter(
        "decoupling_model",
        "Decoupling law applied when decoupling is on: 1 = piecewise-linear compensations D1..D4 (Guo et al. eq. 11-12), 2 = model-based, from the coupling models H_XY, H_YX (ABW-XY eq. 7-16)",
        Variability::Fixed,
        |m| m.selector_codes[1],
        |m, v| m.selector_codes[1] = v,
    )
    .integer_range(Some(1), Some(2))
    .model_path("decoupling_model"),
];

// The four Bouc-Wen models of the inverse Bouc-Wen feedforward and the
// model-based decoupling (seed 001 eq. 3-16).
piezo_fmu_tables::bouc_wen_blocks! {
    PiezoControllerFmu;
    BOUC_WEN_X = ("bouc_wen.x", "H_XX, Bouc-Wen model of each x-pair channel (PZT2, PZT3) to x", bouc_wen.x);
    BOUC_WEN_Y = ("bouc_wen.y", "H_YY, Bouc-Wen model of PZT1's channel to y", bouc_wen.y);
    BOUC_WEN_X_FROM_Y = ("bouc_wen.x_from_y", "H_XY, coupling of PZT1's channel into x", bouc_wen.x_from_y);
    BOUC_WEN_Y_FROM_X = ("bouc_wen.y_from_x", "H_YX, coupling of the x pair's mean command into y", bouc_wen.y_from_x);
}

/// Inputs and outputs: the names users wire.
const PORTS: &[Variable<PiezoControllerFmu>] = &[
    Variable::real_input(
        "x_ref",
        "Demanded x of the platform",
        "um",
        |m| m.references[0],
        |m, v| m.references[0] = v,
    ),
    Variable::real_input(
        "y_ref",
        "Demanded y of the platform",
        "um",
        |m| m.references[1],
        |m, v| m.references[1] = v,
    ),
    Variable::<PiezoControllerFmu>::real_input(
        "theta_ref",
        "Demanded rotation of the platform about z (anticlockwise positive)",
        "rad",
        |m| m.references[2],
        |m, v| m.references[2] = v,
    )
    .display_unit("deg"),
    Variable::real_input(
        "s1",
        "Measured y: laser sensor s1 (wire from FlexureStage.s1)",
        "um",
        |m| m.sensors[0],
        |m, v| m.sensors[0] = v,
    ),
    Variable::real_input(
        "s2",
        "Measured x + theta_z·L/2: laser sensor s2 (wire from FlexureStage.s2)",
        "um",
        |m| m.sensors[1],
        |m, v| m.sensors[1] = v,
    ),
    Variable::real_input(
        "s3",
        "Measured x − theta_z·L/2: laser sensor s3 (wire from FlexureStage.s3)",
        "um",
        |m| m.sensors[2],
        |m, v| m.sensors[2] = v,
    ),
    output!(
        "u1",
        "Command of the PZT1 amplifier channel (y), within command_min..command_max (wire to FlexureStage.u1)",
        "V",
        u[0]
    )
    // Before the first step the command rests at 0 V clamped into the
    // command range (PiezoController's rest output).
    .initially_depends_on(&["command_min", "command_max"]),
    output!(
        "u2",
        "Command of the PZT2 amplifier channel (x pair), within command_min..command_max (wire to FlexureStage.u2)",
        "V",
        u[1]
    )
    // Before the first step the command rests at 0 V clamped into the
    // command range (PiezoController's rest output).
    .initially_depends_on(&["command_min", "command_max"]),
    output!(
        "u3",
        "Command of the PZT3 amplifier channel (x pair), within command_min..command_max (wire to FlexureStage.u3)",
        "V",
        u[2]
    )
    // Before the first step the command rests at 0 V clamped into the
    // command range (PiezoController's rest output).
    .initially_depends_on(&["command_min", "command_max"]),
    output!(
        "u1_ff",
        "Feedforward part of u1: the inverse hysteresis model of y (Guo et al. eq. 3 or ABW-XY eq. 6)",
        "V",
        feedforward[0]
    ),
    output!(
        "u2_ff",
        "Feedforward part of u2: the inverse hysteresis model of x at x_r2",
        "V",
        feedforward[1]
    ),
    output!(
        "u3_ff",
        "Feedforward part of u3: the inverse hysteresis model of x at x_r3",
        "V",
        feedforward[2]
    ),
    output!(
        "u1_fb",
        "Feedback part of u1: the y PI law (Guo et al. eq. 10)",
        "V",
        feedback[0]
    ),
    output!(
        "u2_fb",
        "Feedback part of u2: x PI + theta PI",
        "V",
        feedback[1]
    ),
    output!(
        "u3_fb",
        "Feedback part of u3: x PI − theta PI",
        "V",
        feedback[2]
    ),
    output!(
        "e_x",
        "Tracking error x_ref − (s2+s3)/2, each sensor less its sensor_offset",
        "um",
        e_x
    ),
    output!(
        "e_y",
        "Tracking error y_ref − s1, s1 less sensor_offset[1]",
        "um",
        e_y
    ),
    Variable::<PiezoControllerFmu>::real_output(
        "e_theta",
        "Tracking error theta_ref − (s2−s3)/L, each sensor less its sensor_offset",
        "rad",
        |m| m.output().e_theta,
    )
    .display_unit("deg"),
    output!(
        "x_r2",
        "Input of PZT2's inverse model after decoupling, x_d2 + D1 (Guo et al. eq. 11)",
        "um",
        decoupled.x_r2
    ),
    output!(
        "x_r3",
        "Input of PZT3's inverse model after decoupling, x_d3 + D2 (Guo et al. eq. 11)",
        "um",
        decoupled.x_r3
    ),
    output!(
        "y_rx",
        "y reference compensated for x, y_d + D3 (Guo et al. eq. 11)",
        "um",
        decoupled.y_rx
    ),
    output!(
        "y_rtheta",
        "y reference compensated for rotation, y_d + D4 (Guo et al. eq. 11)",
        "um",
        decoupled.y_rtheta
    ),
];

/// Switches, gains, geometry and command range.
const SETTINGS: &[Variable<PiezoControllerFmu>] = &[
    switch!(
        "feedforward",
        "Apply the inverse hysteresis feedforward (hysteresis_model selects it)",
        feedforward
    ),
    switch!(
        "decoupling",
        "Apply the decoupling law (decoupling_model selects it) to the inverse models' inputs",
        decoupling
    ),
    switch!(
        "feedback_x",
        "Close the x PI loop (Guo et al. eq. 10)",
        feedback_x
    ),
    switch!(
        "feedback_y",
        "Close the y PI loop (Guo et al. eq. 10)",
        feedback_y
    ),
    switch!(
        "feedback_theta",
        "Close the theta_z PI loop (Guo et al. eq. 10)",
        feedback_theta
    ),
    tunable_parameter!(
        "translation.kp",
        "Proportional gain of the x and y PI laws (Guo et al. §3.2: 0.05)",
        "V/um",
        PiGains::GAIN,
        translation_gains.kp
    ),
    tunable_parameter!(
        "translation.ki",
        "Integral gain of the x and y PI laws (Guo et al. §3.2: 50)",
        "V/(um.s)",
        PiGains::GAIN,
        translation_gains.ki
    ),
    tunable_parameter!(
        "rotation.kp",
        "Proportional gain of the theta_z PI law, on the differential error e_theta·L/2 (Guo et al. §3.2: 0.06)",
        "V/um",
        PiGains::GAIN,
        rotation_gains.kp
    ),
    tunable_parameter!(
        "rotation.ki",
        "Integral gain of the theta_z PI law, on e_theta·L/2 (Guo et al. §3.2: 70)",
        "V/(um.s)",
        PiGains::GAIN,
        rotation_gains.ki
    ),
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "L",
        "Distance between the x sensors s2 and s3 (and PZT2, PZT3): theta_z = (s2 − s3)/L, > 0",
        "mm",
        ControllerParams::SENSOR_SPACING_MM,
        sensor_spacing_mm
    ),
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "command_min",
        "Lowest command of every channel (PI's recommended E-505 input: -2 V, -20 V at the stack)",
        "V",
        Range::FINITE,
        command_min
    ),
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "command_max",
        "Highest command of every channel (PI's recommended E-505 input: 12 V, 120 V at the stack)",
        "V",
        Range::FINITE,
        command_max
    ),
];

const X_MODEL: &[Variable<PiezoControllerFmu>] =
    &inverse_pi_parameters!("x", "Inverse P-I model of the x pair (PZT2, PZT3)", x_model);

const Y_MODEL: &[Variable<PiezoControllerFmu>] =
    &inverse_pi_parameters!("y", "Inverse P-I model of y (PZT1)", y_model);

// Δk, Δb, p, q of the four compensations D_i (seed 000 eq. 11, Table 2).
const DECOUPLING_DK: &[Variable<PiezoControllerFmu>] = &indexed!("compensation", dk,
        "Slope Δk_i of compensation D_i: D1, D2 on y_d [um/um], D3 on x_d [um/um] (Guo et al. eq. 11)",
        "", decoupling_params; 1 => 0, 2 => 1, 3 => 2);
// D4's slope takes the rotation demand in microradians: a unit of its own,
// declared where the other three are dimensionless (listed right after them,
// so the value references stay as they were).
const DECOUPLING_DK_ROTATION: &[Variable<PiezoControllerFmu>] = &indexed!("compensation", dk,
        "Slope Δk_4 of compensation D4 on theta_zd [um/urad] (Guo et al. eq. 11)",
        "um/urad", decoupling_params; 4 => 3);
const DECOUPLING_DB: &[Variable<PiezoControllerFmu>] = &indexed!("compensation", db,
        "Offset Δb_i of compensation D_i (Guo et al. eq. 11)",
        "um", decoupling_params; 1 => 0, 2 => 1, 3 => 2, 4 => 3);
const DECOUPLING_P: &[Variable<PiezoControllerFmu>] = &indexed!("compensation", p,
        "Upper cutoff p_i of compensation D_i (Guo et al. eq. 11)",
        "um", decoupling_params; 1 => 0, 2 => 1, 3 => 2, 4 => 3);
const DECOUPLING_Q: &[Variable<PiezoControllerFmu>] = &indexed!("compensation", q,
        "Lower cutoff q_i of compensation D_i (Guo et al. eq. 11)",
        "um", decoupling_params; 1 => 0, 2 => 1, 3 => 2, 4 => 3);

/// The rest the models start from, added after the first release: appended
/// so that the value references of everything above stay as they were.
const RESTS: &[Variable<PiezoControllerFmu>] = &[
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "x.rest_cycle",
        "Inverse P-I model of the x pair: its memories start where a demand 0 → rest_cycle → 0 leaves them, the loop an operated actuator rests on (0: eq. 1's zero memories)",
        "um",
        InversePiParams::REST_CYCLE,
        x_model.rest_cycle
    ),
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "y.rest_cycle",
        "Inverse P-I model of y: its memories start where a demand 0 → rest_cycle → 0 leaves them (0: eq. 1's zero memories)",
        "um",
        InversePiParams::REST_CYCLE,
        y_model.rest_cycle
    ),
    piezo_fmu_tables::fixed_parameter!(
        PiezoControllerFmu,
        "bouc_wen.rest_cycle",
        "The Bouc-Wen models (ABW-XY) start at the 0 V end of their loop between 0 and this command, where an operated actuator rests (0: h = 0)",
        "V",
        BoucWenModels::REST_CYCLE,
        bouc_wen.rest_cycle
    ),
];

/// Each sensor's reading at the references' zero (appended, see [`BLOCKS`]).
const SENSOR_OFFSETS: &[Variable<PiezoControllerFmu>] = &[
    tunable_parameter!(
        "sensor_offset[1]",
        "Reading of s1 where y counts from (the y model's zero: its fit's displacement_offset_um or sensor_offset_um on raw readings; 0 for a sensor zeroed there), subtracted from s1 before the PI laws",
        "um",
        ControllerParams::SENSOR_OFFSET_UM,
        sensor_offsets[0]
    ),
    tunable_parameter!(
        "sensor_offset[2]",
        "Reading of s2 where x counts from (the x model's zero; 0 for a sensor zeroed there), subtracted from s2 before the PI laws",
        "um",
        ControllerParams::SENSOR_OFFSET_UM,
        sensor_offsets[1]
    ),
    tunable_parameter!(
        "sensor_offset[3]",
        "Reading of s3 where x counts from (the x model's zero; 0 for a sensor zeroed there), subtracted from s3 before the PI laws",
        "um",
        ControllerParams::SENSOR_OFFSET_UM,
        sensor_offsets[2]
    ),
];

/// Whether the Bouc-Wen models close their minor loops (appended, see
/// [`BLOCKS`]).
const BOUC_WEN_MEMORY: &[Variable<PiezoControllerFmu>] =
    &[Variable::<PiezoControllerFmu>::boolean_parameter(
        "bouc_wen.return_point_memory",
        "The Bouc-Wen models (ABW-XY) close their minor loops, as FlexureStage's stacks do with its \
         return_point_memory: each branch is the eq. 3 branch tilted to end at the reversal it \
         returns to, and an excursion past a reversal wipes its loop out (false: eq. 3 as \
         integrated, whose minor loops drift)",
        Variability::Fixed,
        |m| m.params.bouc_wen.return_point_memory,
        |m, v| m.params.bouc_wen.return_point_memory = v,
    )
    .model_path("bouc_wen.return_point_memory")];

/// The blocks of the table, in value-reference order.
///
/// APPEND ONLY. A variable's value reference is its position in this table,
/// and importers keep value references (saved models, SSP parameter sets,
/// compiled wiring): a new variable goes at the end (a new block after the
/// last), never between existing ones, and no variable is removed or moved.
/// `valueReferences.txt` beside this crate records every name's reference
/// and a test fails when an existing one changes.
const BLOCKS: &[&[Variable<PiezoControllerFmu>]] = &[
    PORTS,
    SETTINGS,
    X_MODEL,
    Y_MODEL,
    DECOUPLING_DK,
    DECOUPLING_DK_ROTATION,
    DECOUPLING_DB,
    DECOUPLING_P,
    DECOUPLING_Q,
    MODEL_SELECTORS,
    BOUC_WEN_X,
    BOUC_WEN_Y,
    BOUC_WEN_X_FROM_Y,
    BOUC_WEN_Y_FROM_X,
    RESTS,
    SENSOR_OFFSETS,
    BOUC_WEN_MEMORY,
];

/// Every variable, in value-reference order.
static VARIABLES: [Variable<PiezoControllerFmu>; piezo_fmu_tables::total_len(BLOCKS)] =
    fmi2_cosim::variables::concat(BLOCKS);

impl PiezoControllerFmu {
    /// The first Real output that is not finite, by its FMI name.
    fn non_finite_output(&self) -> Option<(&'static str, f64)> {
        VARIABLES
            .iter()
            .filter(|v| v.causality == Causality::Output)
            .find_map(|v| match &v.value {
                Value::Real(r) => {
                    let value = (r.get)(self);
                    (!value.is_finite()).then_some((v.name, value))
                }
                _ => None,
            })
    }
}

impl CoSimModel for PiezoControllerFmu {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "PiezoController",
        model_name: "PiezoController",
        description: "Controller of the 3-DOF piezo flexure stage: modified inverse \
                      Prandtl-Ishlinskii (Guo et al.) or inverse asymmetric Bouc-Wen (ABW-XY) \
                      feedforward, PI feedback, piecewise-linear (Guo et al.) or model-based \
                      (ABW-XY) decoupling; Co-Simulation only: a sampled controller has no \
                      continuous states for an importer's integrator; references in \
                      documentation/index.html",
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

    fn variables() -> &'static [Variable<Self>] {
        &VARIABLES
    }

    fn new() -> Self {
        Self::with_params(ControllerParams::default())
            .expect("the shipped preset validates (tested in piezo-models)")
    }

    fn exit_initialization_mode(
        &mut self,
        ctx: &mut Context<'_>,
        _start_time: f64,
    ) -> Result<(), ModelError> {
        let refused = |name: &str, code: i32, allowed: &str| {
            ModelError(format!(
                "parameter {name} = {code} is not allowed: {allowed}"
            ))
        };
        self.params.hysteresis_model = selected(&HysteresisModel::CODES, self.selector_codes[0])
            .ok_or_else(|| {
                refused(
                    "hysteresis_model",
                    self.selector_codes[0],
                    "1 (modified inverse P-I) or 2 (Bouc-Wen)",
                )
            })?;
        self.params.decoupling_model = selected(&DecouplingModel::CODES, self.selector_codes[1])
            .ok_or_else(|| {
                refused(
                    "decoupling_model",
                    self.selector_codes[1],
                    "1 (piecewise-linear) or 2 (model-based)",
                )
            })?;
        // The controller starts with empty integrators and de-energized
        // backlash memories (seed 000 eq. 1: zero initial state).
        self.controller = PiezoController::new(self.params.clone()).map_err(refused_parameter)?;
        self.saturation_reported = [false; 3];
        ctx.event(format_args!(
            "controller built from the parameters: feedforward {} ({:?}), decoupling {} ({:?}), feedback x/y/theta {}/{}/{}",
            self.params.feedforward,
            self.params.hysteresis_model,
            self.params.decoupling,
            self.params.decoupling_model,
            self.params.feedback_x,
            self.params.feedback_y,
            self.params.feedback_theta
        ));
        Ok(())
    }

    // Inlined into the FMI entry point: one call less on every sample.
    #[inline]
    fn do_step(
        &mut self,
        ctx: &mut Context<'_>,
        current_time: f64,
        step_size: f64,
    ) -> Result<StepOutcome, ModelError> {
        // The inputs are finite: fmi2SetReal refuses a non-finite value, and
        // fmi2DeSerializeFMUstate a state that holds one (the FMI layer).
        let [x_ref, y_ref, theta_ref] = self.references;
        self.controller
            .step(x_ref, y_ref, theta_ref, self.sensors, step_size);
        // Finite inputs do not make every step computable: a huge step
        // overflows the PI integrators. Such a step fails instead of handing
        // NaN or infinite commands to the stage. The sample is checked where
        // the controller keeps it, which the getters read: no copy of it.
        if !self.controller.output().is_finite() {
            return Err(self.non_finite_step(current_time, step_size));
        }
        // Limiting is part of normal operation (a demand of 0 µm asks for a
        // slightly negative voltage; anti-windup handles it), so it is an
        // event, logged once per channel, not a warning. Most samples limit
        // nothing: one test of the three flags.
        let [l1, l2, l3] = self.controller.limited();
        if l1 | l2 | l3 != 0 {
            self.report_limiting(ctx, current_time);
        }
        Ok(StepOutcome::Completed)
    }

    /// Past initialization the controller was built from the FMU's
    /// parameters: the selector codes must be the selectors and the
    /// controller must hold the same parameters, and it is rebuilt from them
    /// and its dynamic state (`PiezoController::rebuilt` validates both).
    /// Before it, `exit_initialization_mode` validates and builds everything.
    fn validate_restored(
        &mut self,
        _ctx: &mut Context<'_>,
        state: FmiState,
    ) -> Result<(), ModelError> {
        // Before initialization, and in the error state, nothing runs the
        // controller: its values are only read back (the last sample, as it
        // is), and exit_initialization_mode builds it again from the
        // parameters. Its tunable parameters may hold there what
        // initialization will refuse (an importer's tuning reaches it before
        // any range check), so it is neither checked nor rebuilt.
        if !state.initialized() {
            return Ok(());
        }
        // Past initialization every parameter holds its range (the layer
        // checked the fixed ones at initialization and checks the tunable
        // ones when they are set), so the controller is rebuilt from them
        // and its dynamic state.
        self.controller = self.controller.rebuilt().map_err(refused_parameter)?;
        if let Some(unreachable) = self.controller.unreachable_state() {
            return Err(ModelError(unreachable.to_string()));
        }
        let selectors = (
            selected(&HysteresisModel::CODES, self.selector_codes[0]),
            selected(&DecouplingModel::CODES, self.selector_codes[1]),
        );
        if selectors
            != (
                Some(self.params.hysteresis_model),
                Some(self.params.decoupling_model),
            )
            || self.controller.params() != &self.params
        {
            return Err(ModelError(
                "the controller's parameters or selectors differ from the FMU's: the state \
                 was not taken from an instance of this FMU"
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

impl PiezoControllerFmu {
    #[cold]
    #[inline(never)]
    fn non_finite_step(&self, current_time: f64, step_size: f64) -> ModelError {
        let (name, value) = self.non_finite_output().unwrap_or(("an output", f64::NAN));
        ModelError(format!(
            "{name} became {value} in the step of {step_size} s from t = {current_time}: the \
             control law cannot be computed over this step (restore an FMU state or reset)"
        ))
    }

    /// Logs each limited channel once (out of the step's line; while a
    /// channel stays limited it runs at every sample and logs nothing).
    #[inline(never)]
    fn report_limiting(&mut self, ctx: &Context<'_>, current_time: f64) {
        let limited = self.controller.limited();
        for (channel, limited) in limited.into_iter().enumerate() {
            if limited == 0 || self.saturation_reported[channel] {
                continue;
            }
            self.saturation_reported[channel] = true;
            let out = self.controller.output();
            let demanded = out.feedforward[channel] + out.feedback[channel];
            ctx.event(format_args!(
                "t = {current_time}: u{} demanded {demanded} V, outside {}..{} V; the \
                 command is limited and the integrators hold (reported once per channel)",
                channel + 1,
                self.params.command_min,
                self.params.command_max
            ));
        }
    }
}

fmi2_cosim::export_fmi2!(PiezoControllerFmu);
