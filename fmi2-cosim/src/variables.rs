//! The variable table: the one source of truth for value references, names,
//! units, causality, variability, dependencies and (through the accessors and the
//! model's start-up values) start values.
//!
//! The value reference of a variable is its position in the table, so the binary's
//! dispatch (`table[vr]`) and the generated `modelDescription.xml` cannot disagree.

/// FMI 2.0 causality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    CalculatedParameter,
    Input,
    Output,
    Local,
}

impl Causality {
    pub fn as_str(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::CalculatedParameter => "calculatedParameter",
            Causality::Input => "input",
            Causality::Output => "output",
            Causality::Local => "local",
        }
    }
}

/// FMI 2.0 variability.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variability {
    Constant,
    Fixed,
    Tunable,
    Discrete,
    Continuous,
}

impl Variability {
    pub fn as_str(self) -> &'static str {
        match self {
            Variability::Constant => "constant",
            Variability::Fixed => "fixed",
            Variability::Tunable => "tunable",
            Variability::Discrete => "discrete",
            Variability::Continuous => "continuous",
        }
    }
}

/// FMI 2.0 `initial` attribute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Initial {
    Exact,
    Approx,
    Calculated,
}

impl Initial {
    pub fn as_str(self) -> &'static str {
        match self {
            Initial::Exact => "exact",
            Initial::Approx => "approx",
            Initial::Calculated => "calculated",
        }
    }
}

/// Accessors and attributes of a Real variable.
pub struct RealVariable<M> {
    pub get: fn(&M) -> f64,
    pub set: Option<fn(&mut M, f64)>,
    pub unit: Option<&'static str>,
    pub display_unit: Option<&'static str>,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

/// Accessors and attributes of an Integer variable.
pub struct IntegerVariable<M> {
    pub get: fn(&M) -> i32,
    pub set: Option<fn(&mut M, i32)>,
    pub min: Option<i32>,
    pub max: Option<i32>,
}

/// Accessors of a Boolean variable.
pub struct BooleanVariable<M> {
    pub get: fn(&M) -> bool,
    pub set: Option<fn(&mut M, bool)>,
}

// Variables hold only function pointers, static strings and numbers, so they
// are Copy whatever the model type (a derive would demand `M: Copy`). That lets
// const code assemble a table from blocks (see `concat`).
impl<M> Clone for RealVariable<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for RealVariable<M> {}
impl<M> Clone for IntegerVariable<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for IntegerVariable<M> {}
impl<M> Clone for BooleanVariable<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for BooleanVariable<M> {}
impl<M> Clone for Value<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Value<M> {}
impl<M> Clone for Variable<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Variable<M> {}

/// Concatenates blocks of variables into one table at compile time, so a
/// model can declare its table as `static T: [Variable<M>; N] = concat(&[&A, &B])`
/// and build repeated blocks (one per actuator, one per model) with a macro
/// that returns an array. `N` must equal the total length (checked at compile
/// time when used in a static).
pub const fn concat<M, const N: usize>(blocks: &[&[Variable<M>]]) -> [Variable<M>; N] {
    assert!(
        !blocks.is_empty() && !blocks[0].is_empty(),
        "the first block is empty"
    );
    let mut table = [blocks[0][0]; N];
    let mut filled = 0;
    let mut b = 0;
    while b < blocks.len() {
        let mut i = 0;
        while i < blocks[b].len() {
            assert!(filled < N, "the blocks hold more variables than N");
            table[filled] = blocks[b][i];
            filled += 1;
            i += 1;
        }
        b += 1;
    }
    assert!(filled == N, "the blocks hold fewer variables than N");
    table
}

/// The typed part of a variable.
pub enum Value<M> {
    Real(RealVariable<M>),
    Integer(IntegerVariable<M>),
    Boolean(BooleanVariable<M>),
}

impl<M> Value<M> {
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Real(_) => "Real",
            Value::Integer(_) => "Integer",
            Value::Boolean(_) => "Boolean",
        }
    }

    fn is_settable(&self) -> bool {
        match self {
            Value::Real(r) => r.set.is_some(),
            Value::Integer(i) => i.set.is_some(),
            Value::Boolean(b) => b.set.is_some(),
        }
    }
}

/// One row of the variable table.
pub struct Variable<M> {
    pub name: &'static str,
    pub description: &'static str,
    pub causality: Causality,
    pub variability: Variability,
    pub value: Value<M>,
    /// For outputs: the inputs (by name) that reach this output within one
    /// communication point, i.e. direct feedthrough, and, in a model that
    /// offers Model Exchange, the continuous states it is computed from (an
    /// output that is itself a state lists none). For state derivatives: the
    /// inputs and states the derivative is computed from. Empty means none.
    pub output_dependencies: &'static [&'static str],
    /// For outputs, states and derivatives: the inputs and exact parameters
    /// (by name) that the value after `fmi2ExitInitializationMode` depends
    /// on. Empty means none; `None` means every known (the `dependencies`
    /// attribute is left out), the default of state derivatives.
    pub initial_dependencies: Option<&'static [&'static str]>,
    /// For a state derivative: the name of its state (the `derivative`
    /// attribute). The order of the derivatives in the table is the order of
    /// the continuous-state vector of Model Exchange.
    pub derivative_of: Option<&'static str>,
    /// Where the model keeps the value in its own parameter structure (e.g. the
    /// path in a JSON preset), so that the model's own messages can be mapped to
    /// the FMI name and the documentation can show both.
    pub model_path: Option<&'static str>,
}

impl<M> Variable<M> {
    const fn new(
        name: &'static str,
        description: &'static str,
        causality: Causality,
        variability: Variability,
        value: Value<M>,
    ) -> Self {
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

    /// A continuous Real input (start value read from the model at start-up).
    pub const fn real_input(
        name: &'static str,
        description: &'static str,
        unit: &'static str,
        get: fn(&M) -> f64,
        set: fn(&mut M, f64),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Input,
            Variability::Continuous,
            Value::Real(RealVariable {
                get,
                set: Some(set),
                unit: Some(unit),
                display_unit: None,
                min: None,
                max: None,
            }),
        )
    }

    /// A continuous Real output, computed by the model.
    pub const fn real_output(
        name: &'static str,
        description: &'static str,
        unit: &'static str,
        get: fn(&M) -> f64,
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Output,
            Variability::Continuous,
            Value::Real(RealVariable {
                get,
                set: None,
                unit: Some(unit),
                display_unit: None,
                min: None,
                max: None,
            }),
        )
    }

    /// A continuous Real local (a diagnostic that is not a port).
    pub const fn real_local(
        name: &'static str,
        description: &'static str,
        unit: &'static str,
        get: fn(&M) -> f64,
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Local,
            Variability::Continuous,
            Value::Real(RealVariable {
                get,
                set: None,
                unit: Some(unit),
                display_unit: None,
                min: None,
                max: None,
            }),
        )
    }

    /// A Real parameter; `unit` may be empty for a dimensionless or
    /// non-integer-exponent quantity.
    pub const fn real_parameter(
        name: &'static str,
        description: &'static str,
        unit: &'static str,
        variability: Variability,
        get: fn(&M) -> f64,
        set: fn(&mut M, f64),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Parameter,
            variability,
            Value::Real(RealVariable {
                get,
                set: Some(set),
                unit: if unit.is_empty() { None } else { Some(unit) },
                display_unit: None,
                min: None,
                max: None,
            }),
        )
    }

    /// An Integer parameter.
    pub const fn integer_parameter(
        name: &'static str,
        description: &'static str,
        variability: Variability,
        get: fn(&M) -> i32,
        set: fn(&mut M, i32),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Parameter,
            variability,
            Value::Integer(IntegerVariable {
                get,
                set: Some(set),
                min: None,
                max: None,
            }),
        )
    }

    /// A Boolean parameter.
    pub const fn boolean_parameter(
        name: &'static str,
        description: &'static str,
        variability: Variability,
        get: fn(&M) -> bool,
        set: fn(&mut M, bool),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Parameter,
            variability,
            Value::Boolean(BooleanVariable {
                get,
                set: Some(set),
            }),
        )
    }

    /// Declares the allowed range of a Real variable (`min`/`max` in
    /// modelDescription; parameters outside it are refused at
    /// `fmi2ExitInitializationMode`).
    pub const fn range(mut self, min: Option<f64>, max: Option<f64>) -> Self {
        if let Value::Real(ref mut r) = self.value {
            r.min = min;
            r.max = max;
        }
        self
    }

    /// Declares the allowed range of an Integer variable.
    pub const fn integer_range(mut self, min: Option<i32>, max: Option<i32>) -> Self {
        if let Value::Integer(ref mut i) = self.value {
            i.min = min;
            i.max = max;
        }
        self
    }

    /// Declares the display unit of a Real variable (must be a display unit of
    /// its unit).
    pub const fn display_unit(mut self, display_unit: &'static str) -> Self {
        if let Value::Real(ref mut r) = self.value {
            r.display_unit = Some(display_unit);
        }
        self
    }

    /// Records where the model keeps the value (see [`Variable::model_path`]).
    pub const fn model_path(mut self, path: &'static str) -> Self {
        self.model_path = Some(path);
        self
    }

    /// Direct feedthrough of an output (inputs by name).
    pub const fn depends_on(mut self, inputs: &'static [&'static str]) -> Self {
        self.output_dependencies = inputs;
        self
    }

    /// What an output depends on after initialization (inputs and exact
    /// parameters by name).
    pub const fn initially_depends_on(mut self, knowns: &'static [&'static str]) -> Self {
        self.initial_dependencies = Some(knowns);
        self
    }

    /// Marks a continuous Real variable as the time derivative of the state
    /// `state` (by name), and declares what it is computed from (inputs and
    /// states by name, for ModelStructure/Derivatives). After initialization
    /// it depends on every known unless [`Variable::initially_depends_on`]
    /// says otherwise.
    pub const fn derivative_of(
        mut self,
        state: &'static str,
        dependencies: &'static [&'static str],
    ) -> Self {
        self.derivative_of = Some(state);
        self.output_dependencies = dependencies;
        self.initial_dependencies = None;
        self
    }

    /// The `initial` attribute, derived from causality as FMI 2.0 requires:
    /// parameters and their start values are exact; everything the model
    /// computes is calculated; inputs carry no `initial`.
    pub fn initial(&self) -> Option<Initial> {
        match self.causality {
            Causality::Parameter => Some(Initial::Exact),
            Causality::Input => None,
            Causality::Output | Causality::Local | Causality::CalculatedParameter => {
                Some(Initial::Calculated)
            }
        }
    }

    /// Whether modelDescription carries a start value for the variable.
    pub fn has_start(&self) -> bool {
        matches!(self.causality, Causality::Parameter | Causality::Input)
    }

    /// Whether `fmi2SetXXX` may ever write it.
    pub fn is_settable(&self) -> bool {
        self.has_start() && self.variability != Variability::Constant && self.value.is_settable()
    }
}

/// Whether the variable called `name` is a continuous state (some variable is
/// its derivative).
pub fn is_state<M>(table: &[Variable<M>], name: &str) -> bool {
    table.iter().any(|v| v.derivative_of == Some(name))
}

/// The continuous states in state-vector order: (index of the state, index of
/// its derivative) in the table, ordered by the derivative's index.
pub fn continuous_states<M>(table: &[Variable<M>]) -> Vec<(usize, usize)> {
    table
        .iter()
        .enumerate()
        .filter_map(|(derivative, v)| {
            let state = v.derivative_of?;
            let state = table.iter().position(|s| s.name == state)?;
            Some((state, derivative))
        })
        .collect()
}

/// Checks that names are unique, that dependencies name existing inputs,
/// states or parameters, that state derivatives name continuous Real states
/// (one derivative per state), that settable variables have setters, and that
/// display units belong to declared units. Used by modelDescription generation and by tests.
pub fn check_table<M>(
    table: &[Variable<M>],
    units: &[crate::model::UnitDefinition],
) -> Result<(), String> {
    let mut names = std::collections::HashSet::new();
    for (vr, var) in table.iter().enumerate() {
        if !names.insert(var.name) {
            return Err(format!(
                "variable name {} (vr {vr}) appears twice",
                var.name
            ));
        }
        if var.has_start() && var.variability != Variability::Constant && !var.value.is_settable() {
            return Err(format!("{} has a start value but no setter", var.name));
        }
        if let Value::Real(r) = &var.value {
            if let Some(unit) = r.unit {
                let Some(def) = units.iter().find(|u| u.name == unit) else {
                    return Err(format!("{}: unit {unit} is not declared", var.name));
                };
                if let Some(du) = r.display_unit
                    && !def.display_units.iter().any(|d| d.name == du)
                {
                    return Err(format!(
                        "{}: display unit {du} is not a display unit of {unit}",
                        var.name
                    ));
                }
            } else if r.display_unit.is_some() {
                return Err(format!("{}: display unit without unit", var.name));
            }
        }
        let is_output = var.causality == Causality::Output;
        let carries_dependencies = is_output || var.derivative_of.is_some();
        if !carries_dependencies && !var.output_dependencies.is_empty() {
            return Err(format!(
                "{}: only outputs and state derivatives carry dependencies",
                var.name
            ));
        }
        if !carries_dependencies
            && !is_state(table, var.name)
            && var.initial_dependencies != Some(&[])
        {
            return Err(format!(
                "{}: only outputs, states and state derivatives carry initial dependencies",
                var.name
            ));
        }
        if let Some(state) = var.derivative_of {
            let Value::Real(_) = var.value else {
                return Err(format!("{}: a state derivative must be Real", var.name));
            };
            if var.variability != Variability::Continuous
                || !matches!(var.causality, Causality::Local | Causality::Output)
            {
                return Err(format!(
                    "{}: a state derivative must be a continuous local or output",
                    var.name
                ));
            }
            match table.iter().find(|v| v.name == state) {
                Some(v)
                    if matches!(v.value, Value::Real(_))
                        && v.variability == Variability::Continuous
                        && matches!(v.causality, Causality::Local | Causality::Output) => {}
                Some(_) => {
                    return Err(format!(
                        "{}: its state {state} must be a continuous Real local or output",
                        var.name
                    ));
                }
                None => return Err(format!("{}: unknown state {state}", var.name)),
            }
            if table
                .iter()
                .filter(|v| v.derivative_of == Some(state))
                .count()
                > 1
            {
                return Err(format!("state {state} has more than one derivative"));
            }
        }
        for dep in var.output_dependencies {
            match table.iter().find(|v| v.name == *dep) {
                Some(v) if v.causality == Causality::Input => {}
                Some(v) if is_state(table, v.name) => {}
                Some(_) => {
                    return Err(format!(
                        "{}: dependency {dep} is neither an input nor a continuous state",
                        var.name
                    ));
                }
                None => return Err(format!("{}: unknown dependency {dep}", var.name)),
            }
        }
        for dep in var.initial_dependencies.unwrap_or(&[]) {
            match table.iter().find(|v| v.name == *dep) {
                Some(v) if matches!(v.causality, Causality::Input | Causality::Parameter) => {}
                Some(_) => {
                    return Err(format!(
                        "{}: initial dependency {dep} is neither an input nor a parameter",
                        var.name
                    ));
                }
                None => return Err(format!("{}: unknown initial dependency {dep}", var.name)),
            }
        }
    }
    Ok(())
}
