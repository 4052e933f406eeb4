//! Feedthrough: a fixture FMU for the FMI layer, in the spirit of the
//! Reference FMUs' Feedthrough model. It serves one variable of every type,
//! causality and variability that `fmi2-cosim` serves, and its outputs equal
//! its inputs as soon as they are set (direct feedthrough, before any step),
//! so the conformance checks and the fuzzer test the layer on a model whose
//! every answer is known, apart from the piezo models.
//!
//! What the layer serves, and so what the table holds:
//! - types Real, Integer, Boolean, String;
//! - causalities parameter, calculatedParameter, input, output, local, and
//!   independent (the time, `time`, which reads the instance's time);
//! - variabilities constant (a Real output, exact, with its value as start
//!   value), fixed, tunable, discrete, continuous.
//!
//! Not here because the layer does not serve them: Enumeration variables,
//! `initial="approx"`, and a constant local (a constant output shows the
//! rule both share).
//!
//! Value references are positions in [`VARIABLES`]: append only, recorded in
//! `valueReferences.txt` (tested).

use fmi2_cosim::variables::{BooleanVariable, IntegerVariable, RealVariable, Value};
use fmi2_cosim::{
    Causality, CoSimModel, Context, DefaultExperiment, ModelError, ModelInfo, StepOutcome,
    UnitDefinition, Variability, Variable, units,
};
use serde::{Deserialize, Serialize};

/// The model: what the importer sets, and the two locals it computes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Feedthrough {
    real_fixed_parameter: f64,
    /// The gain of the integral in `real_continuous_local`.
    real_tunable_parameter: f64,
    integer_fixed_parameter: i32,
    /// Holds the integral while true.
    boolean_tunable_parameter: bool,
    /// `startTime` of `fmi2SetupExperiment`, taken at initialization.
    start_time: f64,
    real_continuous_input: f64,
    real_discrete_input: f64,
    integer_input: i32,
    boolean_input: bool,
    /// The integral of `real_continuous_input` times the tunable gain over
    /// the steps taken: a continuous value the model computes, so that FMU
    /// states and resets have something to restore.
    real_continuous_local: f64,
    /// Steps completed since initialization.
    integer_discrete_local: i32,
    string_fixed_parameter: String,
    string_input: String,
}

/// The value of `real_constant_output`.
pub const REAL_CONSTANT: f64 = std::f64::consts::E;

/// The start value of `string_fixed_parameter`: characters XML must escape,
/// and one outside ASCII, so that an importer's reading of the start value
/// is tested too.
pub const STRING_PARAMETER_START: &str = "a \"String\" <parameter> & µ";

const UNITS: &[UnitDefinition] = &[units::SECOND];

/// A row of the table with no unit, range, dependency or model path; the
/// builders of [`Variable`] add them.
const fn variable(
    name: &'static str,
    description: &'static str,
    causality: Causality,
    variability: Variability,
    value: Value<Feedthrough>,
) -> Variable<Feedthrough> {
    Variable {
        name,
        description,
        causality,
        variability,
        value,
        output_dependencies: &[],
        initial_dependencies: Some(&[]),
        derivative_of: None,
        model_path: None,
    }
}

const fn real(
    get: fn(&Feedthrough) -> f64,
    set: Option<fn(&mut Feedthrough, f64)>,
) -> Value<Feedthrough> {
    Value::Real(RealVariable {
        get,
        set,
        unit: None,
        display_unit: None,
        min: None,
        max: None,
    })
}

const fn integer(
    get: fn(&Feedthrough) -> i32,
    set: Option<fn(&mut Feedthrough, i32)>,
) -> Value<Feedthrough> {
    Value::Integer(IntegerVariable {
        get,
        set,
        min: None,
        max: None,
    })
}

const fn boolean(
    get: fn(&Feedthrough) -> bool,
    set: Option<fn(&mut Feedthrough, bool)>,
) -> Value<Feedthrough> {
    Value::Boolean(BooleanVariable { get, set })
}

use Causality::{CalculatedParameter, Input, Local, Output, Parameter};
use Variability::{Continuous, Discrete, Fixed, Tunable};

/// The variable table; a variable's value reference is its index.
pub static VARIABLES: [Variable<Feedthrough>; 20] = [
    variable(
        "real_fixed_parameter",
        "A fixed Real parameter, declared in [-1e6, 1e6]",
        Parameter,
        Fixed,
        real(
            |m| m.real_fixed_parameter,
            Some(|m, v| m.real_fixed_parameter = v),
        ),
    )
    .range(Some(-1e6), Some(1e6))
    .model_path("real_fixed_parameter"),
    variable(
        "real_tunable_parameter",
        "A tunable Real parameter: the gain of real_continuous_local's integral",
        Parameter,
        Tunable,
        real(
            |m| m.real_tunable_parameter,
            Some(|m, v| m.real_tunable_parameter = v),
        ),
    )
    .model_path("real_tunable_parameter"),
    variable(
        "integer_fixed_parameter",
        "A fixed Integer parameter, declared in [0, 100]",
        Parameter,
        Fixed,
        integer(
            |m| m.integer_fixed_parameter,
            Some(|m, v| m.integer_fixed_parameter = v),
        ),
    )
    .integer_range(Some(0), Some(100))
    .model_path("integer_fixed_parameter"),
    variable(
        "boolean_tunable_parameter",
        "A tunable Boolean parameter: true holds real_continuous_local",
        Parameter,
        Tunable,
        boolean(
            |m| m.boolean_tunable_parameter,
            Some(|m, v| m.boolean_tunable_parameter = v),
        ),
    )
    .model_path("boolean_tunable_parameter"),
    variable(
        "start_time",
        "A calculated parameter: the experiment's start time, taken at initialization",
        CalculatedParameter,
        Fixed,
        Value::Real(RealVariable {
            get: |m| m.start_time,
            set: None,
            unit: Some("s"),
            display_unit: None,
            min: None,
            max: None,
        }),
    ),
    variable(
        "real_continuous_input",
        "A continuous Real input",
        Input,
        Continuous,
        real(
            |m| m.real_continuous_input,
            Some(|m, v| m.real_continuous_input = v),
        ),
    ),
    variable(
        "real_continuous_output",
        "real_continuous_input, fed through",
        Output,
        Continuous,
        real(|m| m.real_continuous_input, None),
    )
    .depends_on(&["real_continuous_input"])
    .initially_depends_on(&["real_continuous_input"]),
    variable(
        "real_discrete_input",
        "A discrete Real input",
        Input,
        Discrete,
        real(
            |m| m.real_discrete_input,
            Some(|m, v| m.real_discrete_input = v),
        ),
    ),
    variable(
        "real_discrete_output",
        "real_discrete_input, fed through",
        Output,
        Discrete,
        real(|m| m.real_discrete_input, None),
    )
    .depends_on(&["real_discrete_input"])
    .initially_depends_on(&["real_discrete_input"]),
    variable(
        "integer_input",
        "A discrete Integer input",
        Input,
        Discrete,
        integer(|m| m.integer_input, Some(|m, v| m.integer_input = v)),
    ),
    variable(
        "integer_output",
        "integer_input, fed through",
        Output,
        Discrete,
        integer(|m| m.integer_input, None),
    )
    .depends_on(&["integer_input"])
    .initially_depends_on(&["integer_input"]),
    variable(
        "boolean_input",
        "A discrete Boolean input",
        Input,
        Discrete,
        boolean(|m| m.boolean_input, Some(|m, v| m.boolean_input = v)),
    ),
    variable(
        "boolean_output",
        "boolean_input, fed through",
        Output,
        Discrete,
        boolean(|m| m.boolean_input, None),
    )
    .depends_on(&["boolean_input"])
    .initially_depends_on(&["boolean_input"]),
    variable(
        "real_continuous_local",
        "A continuous Real local: the integral of real_continuous_input times real_tunable_parameter",
        Local,
        Continuous,
        real(|m| m.real_continuous_local, None),
    ),
    variable(
        "integer_discrete_local",
        "A discrete Integer local: the steps completed since initialization",
        Local,
        Discrete,
        integer(|m| m.integer_discrete_local, None),
    ),
    Variable::string_parameter(
        "string_fixed_parameter",
        "A fixed String parameter",
        Fixed,
        |m: &Feedthrough| &m.string_fixed_parameter,
        |m, v| m.string_fixed_parameter = v.to_owned(),
    )
    .model_path("string_fixed_parameter"),
    Variable::string_input(
        "string_input",
        "A discrete String input",
        |m: &Feedthrough| &m.string_input,
        |m, v| m.string_input = v.to_owned(),
    ),
    Variable::string_output(
        "string_output",
        "string_input, fed through",
        |m: &Feedthrough| &m.string_input,
    )
    .depends_on(&["string_input"])
    .initially_depends_on(&["string_input"]),
    Variable::independent("time", "The independent variable: the simulation time", "s"),
    variable(
        "real_constant_output",
        "A Real constant output: e, in every state",
        Output,
        Continuous,
        real(|_| REAL_CONSTANT, None),
    )
    .constant(),
];

impl CoSimModel for Feedthrough {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "Feedthrough",
        model_name: "Feedthrough",
        description: "A fixture of the FMI layer: every type, causality and variability it \
                      serves, outputs equal to inputs (direct feedthrough)",
        author: "piezo-fmu project",
        version: env!("CARGO_PKG_VERSION"),
        license: "MIT OR Apache-2.0",
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
    };
    const UNITS: &'static [UnitDefinition] = UNITS;

    fn variables() -> &'static [Variable<Self>] {
        &VARIABLES
    }

    fn new() -> Self {
        Feedthrough {
            real_fixed_parameter: 1.0,
            real_tunable_parameter: 1.0,
            integer_fixed_parameter: 1,
            boolean_tunable_parameter: false,
            start_time: 0.0,
            real_continuous_input: 0.0,
            real_discrete_input: 0.0,
            integer_input: 0,
            boolean_input: false,
            real_continuous_local: 0.0,
            integer_discrete_local: 0,
            string_fixed_parameter: STRING_PARAMETER_START.to_owned(),
            string_input: String::new(),
        }
    }

    fn exit_initialization_mode(
        &mut self,
        _ctx: &mut Context<'_>,
        start_time: f64,
    ) -> Result<(), ModelError> {
        self.start_time = start_time;
        self.real_continuous_local = 0.0;
        self.integer_discrete_local = 0;
        Ok(())
    }

    fn do_step(
        &mut self,
        _ctx: &mut Context<'_>,
        current_time: f64,
        step_size: f64,
    ) -> Result<StepOutcome, ModelError> {
        if !self.boolean_tunable_parameter {
            let integral = self.real_continuous_local
                + self.real_tunable_parameter * self.real_continuous_input * step_size;
            if !integral.is_finite() {
                return Err(ModelError(format!(
                    "real_continuous_local overflows in the step from t = {current_time} by \
                     {step_size} s (real_tunable_parameter {}, real_continuous_input {})",
                    self.real_tunable_parameter, self.real_continuous_input
                )));
            }
            self.real_continuous_local = integral;
        }
        self.integer_discrete_local = self.integer_discrete_local.saturating_add(1);
        Ok(StepOutcome::Completed)
    }
}

fmi2_cosim::export_fmi2!(Feedthrough);
