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
    /// The independent variable, time (FMI 2.0.4 §2.2.7): at most one per
    /// table, a continuous Real with no start value and no `initial`, whose
    /// value is the instance's time ([`Value::Time`]).
    Independent,
}

impl Causality {
    pub fn as_str(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::CalculatedParameter => "calculatedParameter",
            Causality::Input => "input",
            Causality::Output => "output",
            Causality::Local => "local",
            Causality::Independent => "independent",
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

/// Accessors of a String variable. The getter lends the model's text, which
/// `fmi2GetString` copies into C strings the instance owns (FMI 2.0.4
/// §2.1.7: valid until the next call on the instance); the setter is given
/// the importer's text after `fmi2SetString` checked it (not NULL, UTF-8),
/// and keeps a copy (the importer's string is its own again after the call).
/// A value never holds a NUL byte: no C string can carry one.
pub struct StringVariable<M> {
    pub get: fn(&M) -> &str,
    pub set: Option<fn(&mut M, &str)>,
}

/// The independent variable (causality `independent`): a Real whose value is
/// the instance's time, which the layer keeps (`fmi2SetupExperiment` and
/// `fmi2ExitInitializationMode` put it at the start time, `fmi2DoStep` moves
/// it to the end of each step, `fmi2SetTime` sets it in Model Exchange), so
/// the model has no accessor for it, and no importer may set it
/// (FMI 2.0.4 §2.2.7).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeVariable {
    pub unit: Option<&'static str>,
    pub display_unit: Option<&'static str>,
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
impl<M> Clone for StringVariable<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for StringVariable<M> {}
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
    String(StringVariable<M>),
    /// The independent variable: a Real the layer answers with the time.
    Time(TimeVariable),
}

impl<M> Value<M> {
    /// The type element of modelDescription (`Real` for the time too).
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Real(_) | Value::Time(_) => "Real",
            Value::Integer(_) => "Integer",
            Value::Boolean(_) => "Boolean",
            Value::String(_) => "String",
        }
    }

    fn is_settable(&self) -> bool {
        match self {
            Value::Real(r) => r.set.is_some(),
            Value::Integer(i) => i.set.is_some(),
            Value::Boolean(b) => b.set.is_some(),
            Value::String(s) => s.set.is_some(),
            Value::Time(_) => false,
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

    /// The independent variable, time, in `unit` (empty for none): its value
    /// is the instance's time (see [`TimeVariable`]).
    pub const fn independent(
        name: &'static str,
        description: &'static str,
        unit: &'static str,
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Independent,
            Variability::Continuous,
            Value::Time(TimeVariable {
                unit: if unit.is_empty() { None } else { Some(unit) },
                display_unit: None,
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

    /// A String parameter (start value read from the model at start-up).
    pub const fn string_parameter(
        name: &'static str,
        description: &'static str,
        variability: Variability,
        get: fn(&M) -> &str,
        set: fn(&mut M, &str),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Parameter,
            variability,
            Value::String(StringVariable {
                get,
                set: Some(set),
            }),
        )
    }

    /// A String input (discrete: only a Real is continuous).
    pub const fn string_input(
        name: &'static str,
        description: &'static str,
        get: fn(&M) -> &str,
        set: fn(&mut M, &str),
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Input,
            Variability::Discrete,
            Value::String(StringVariable {
                get,
                set: Some(set),
            }),
        )
    }

    /// A String output (discrete), computed by the model.
    pub const fn string_output(
        name: &'static str,
        description: &'static str,
        get: fn(&M) -> &str,
    ) -> Self {
        Self::new(
            name,
            description,
            Causality::Output,
            Variability::Discrete,
            Value::String(StringVariable { get, set: None }),
        )
    }

    /// Makes an output or local a constant: its value never changes, and
    /// modelDescription declares it with `initial="exact"` and its value as
    /// the start value (FMI 2.0.4 §2.2.7). Its getter must answer the same
    /// in every state; it has no setter.
    pub const fn constant(mut self) -> Self {
        self.variability = Variability::Constant;
        self
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
        match self.value {
            Value::Real(ref mut r) => r.display_unit = Some(display_unit),
            Value::Time(ref mut t) => t.display_unit = Some(display_unit),
            _ => {}
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

    /// A state whose initial value the model computes from the parameters (a
    /// rest it settles into): it initially depends on every known, as an
    /// InitialUnknown without a `dependencies` list says (FMI 2.0.4 §2.2.8).
    pub const fn initially_depends_on_every_known(mut self) -> Self {
        self.initial_dependencies = None;
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

    /// The `initial` attribute, derived from causality and variability as
    /// FMI 2.0.4 §2.2.7 requires: parameters and constants are exact (their
    /// start value is their value); everything else the model computes is
    /// calculated; inputs and the independent variable carry no `initial`.
    pub fn initial(&self) -> Option<Initial> {
        match (self.causality, self.variability) {
            (Causality::Input | Causality::Independent, _) => None,
            (Causality::Parameter, _) | (_, Variability::Constant) => Some(Initial::Exact),
            (Causality::Output | Causality::Local | Causality::CalculatedParameter, _) => {
                Some(Initial::Calculated)
            }
        }
    }

    /// Whether modelDescription carries a start value for the variable:
    /// parameters, inputs and constants (§2.2.7: a start value is required
    /// where `initial` is exact, and for inputs).
    pub fn has_start(&self) -> bool {
        matches!(self.causality, Causality::Parameter | Causality::Input)
            || self.variability == Variability::Constant
    }

    /// Whether `fmi2SetXXX` may ever write it: parameters and inputs (a
    /// constant never, nor the independent variable, which moves with the
    /// instance's time).
    pub fn is_settable(&self) -> bool {
        matches!(self.causality, Causality::Parameter | Causality::Input)
            && self.variability != Variability::Constant
            && self.value.is_settable()
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

/// Whether FMI 2.0.4 §2.2.7 (the table of causality and variability)
/// allows the combination: constants are outputs or locals; parameters are
/// fixed or tunable, as are calculated parameters; inputs and outputs are
/// discrete or continuous; the independent variable is continuous; a local
/// may be anything.
pub fn combination_allowed(causality: Causality, variability: Variability) -> bool {
    use Causality as C;
    use Variability as V;
    match variability {
        V::Constant => matches!(causality, C::Output | C::Local),
        V::Fixed | V::Tunable => {
            matches!(causality, C::Parameter | C::CalculatedParameter | C::Local)
        }
        V::Discrete => matches!(causality, C::Input | C::Output | C::Local),
        V::Continuous => matches!(causality, C::Input | C::Output | C::Local | C::Independent),
    }
}

/// Checks that names are unique; that each causality goes with a variability
/// and a type FMI 2.0.4 §2.2.7 allows (only a Real is continuous; at most one
/// independent variable, the time, as [`Value::Time`]; a constant has no
/// setter and depends on nothing); that dependencies name existing inputs,
/// states, the independent variable or parameters; that state derivatives
/// name continuous Real states (one derivative per state); that settable
/// variables have setters; and that display units belong to declared units.
/// Used by modelDescription generation and by tests.
pub fn check_table<M>(
    table: &[Variable<M>],
    units: &[crate::model::UnitDefinition],
) -> Result<(), String> {
    let mut names = std::collections::HashSet::new();
    let mut independent: Option<&str> = None;
    for (vr, var) in table.iter().enumerate() {
        if !names.insert(var.name) {
            return Err(format!(
                "variable name {} (vr {vr}) appears twice",
                var.name
            ));
        }
        if !combination_allowed(var.causality, var.variability) {
            return Err(format!(
                "{}: causality {} with variability {} is not a combination FMI 2.0 allows",
                var.name,
                var.causality.as_str(),
                var.variability.as_str()
            ));
        }
        if var.variability == Variability::Continuous && var.value.type_name() != "Real" {
            return Err(format!(
                "{}: only a Real can be continuous (it is {})",
                var.name,
                var.value.type_name()
            ));
        }
        if matches!(var.value, Value::Time(_)) != (var.causality == Causality::Independent) {
            return Err(format!(
                "{}: the independent variable, and only it, is the time (Variable::independent)",
                var.name
            ));
        }
        if var.causality == Causality::Independent
            && let Some(first) = independent.replace(var.name)
        {
            return Err(format!(
                "{first} and {} are both independent; FMI 2.0 allows at most one",
                var.name
            ));
        }
        if var.variability == Variability::Constant {
            if var.value.is_settable() {
                return Err(format!(
                    "{}: a constant has a setter, which nothing may call",
                    var.name
                ));
            }
            if !var.output_dependencies.is_empty() || var.initial_dependencies != Some(&[]) {
                return Err(format!("{}: a constant depends on nothing", var.name));
            }
        }
        if var.has_start() && var.variability != Variability::Constant && !var.value.is_settable() {
            return Err(format!("{} has a start value but no setter", var.name));
        }
        let (unit, display_unit) = match &var.value {
            Value::Real(r) => (r.unit, r.display_unit),
            Value::Time(t) => (t.unit, t.display_unit),
            _ => (None, None),
        };
        if let Some(unit) = unit {
            let Some(def) = units.iter().find(|u| u.name == unit) else {
                return Err(format!("{}: unit {unit} is not declared", var.name));
            };
            if let Some(du) = display_unit
                && !def.display_units.iter().any(|d| d.name == du)
            {
                return Err(format!(
                    "{}: display unit {du} is not a display unit of {unit}",
                    var.name
                ));
            }
        } else if display_unit.is_some() {
            return Err(format!("{}: display unit without unit", var.name));
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
        // FMI 2.0.4 §2.2.8: the knowns of outputs and derivatives are the
        // inputs, the continuous states and the independent variable.
        for dep in var.output_dependencies {
            match table.iter().find(|v| v.name == *dep) {
                Some(v) if matches!(v.causality, Causality::Input | Causality::Independent) => {}
                Some(v) if is_state(table, v.name) => {}
                Some(_) => {
                    return Err(format!(
                        "{}: dependency {dep} is neither an input, a continuous state nor the \
                         independent variable",
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

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Model {
        x: f64,
        label: String,
    }

    const fn label_parameter() -> Variable<Model> {
        Variable::string_parameter(
            "label",
            "",
            Variability::Fixed,
            |m| &m.label,
            |m, v| m.label = v.to_owned(),
        )
    }

    const fn x_output() -> Variable<Model> {
        Variable::real_output("x", "", "1", |m| m.x)
    }

    fn check(table: &[Variable<Model>]) -> Result<(), String> {
        const ONE: crate::model::UnitDefinition = crate::model::UnitDefinition {
            name: "1",
            base: crate::model::BaseUnit::NONE,
            display_units: &[],
        };
        check_table(table, &[ONE])
    }

    #[test]
    fn a_constant_is_exact_with_a_start_and_never_settable() {
        let constant = x_output().constant();
        assert_eq!(constant.initial(), Some(Initial::Exact));
        assert!(constant.has_start());
        assert!(!constant.is_settable());
        let local = Variable::real_local("y", "", "1", |m: &Model| m.x).constant();
        assert_eq!(local.initial(), Some(Initial::Exact));
        check(&[constant, local]).unwrap();
    }

    #[test]
    fn the_independent_variable_has_no_start_no_initial_and_no_setter() {
        let time = Variable::<Model>::independent("time", "", "");
        assert_eq!(time.causality, Causality::Independent);
        assert_eq!(time.variability, Variability::Continuous);
        assert_eq!(time.value.type_name(), "Real");
        assert_eq!(time.initial(), None);
        assert!(!time.has_start());
        assert!(!time.is_settable());
        check(&[time]).unwrap();
    }

    #[test]
    fn strings_follow_their_causality() {
        let parameter = label_parameter();
        assert_eq!(parameter.value.type_name(), "String");
        assert!(parameter.has_start() && parameter.is_settable());
        assert_eq!(parameter.initial(), Some(Initial::Exact));
        let input = Variable::string_input(
            "in",
            "",
            |m: &Model| &m.label,
            |m, v| m.label = v.to_owned(),
        );
        assert_eq!(input.variability, Variability::Discrete);
        assert!(input.is_settable() && input.initial().is_none());
        let output = Variable::string_output("out", "", |m: &Model| &m.label).depends_on(&["in"]);
        assert!(!output.is_settable() && !output.has_start());
        check(&[parameter, input, output]).unwrap();
    }

    #[test]
    fn at_most_one_independent_variable() {
        let err = check(&[
            Variable::independent("time", "", ""),
            Variable::independent("t2", "", ""),
        ])
        .unwrap_err();
        assert!(err.contains("at most one"), "{err}");
    }

    #[test]
    fn the_time_is_the_independent_variable_and_only_it() {
        let mut local_time = Variable::<Model>::independent("time", "", "");
        local_time.causality = Causality::Local;
        let err = check(&[local_time]).unwrap_err();
        assert!(err.contains("independent"), "{err}");
        let mut real_independent = x_output();
        real_independent.causality = Causality::Independent;
        let err = check(&[real_independent]).unwrap_err();
        assert!(err.contains("independent"), "{err}");
    }

    #[test]
    fn combinations_outside_the_standards_table_are_refused() {
        // Constants are outputs or locals; parameters fixed or tunable.
        for (causality, variability) in [
            (Causality::Parameter, Variability::Constant),
            (Causality::Input, Variability::Constant),
            (Causality::CalculatedParameter, Variability::Constant),
            (Causality::Independent, Variability::Constant),
            (Causality::Parameter, Variability::Discrete),
            (Causality::Parameter, Variability::Continuous),
            (Causality::Input, Variability::Fixed),
            (Causality::Output, Variability::Tunable),
            (Causality::Independent, Variability::Discrete),
        ] {
            assert!(
                !combination_allowed(causality, variability),
                "{causality:?} {variability:?}"
            );
        }
        let mut fixed_output = x_output();
        fixed_output.variability = Variability::Fixed;
        let err = check(&[fixed_output]).unwrap_err();
        assert!(err.contains("not a combination"), "{err}");
        // A parameter made constant keeps its setter: refused either way.
        let err = check(&[label_parameter().constant()]).unwrap_err();
        assert!(err.contains("not a combination"), "{err}");
    }

    #[test]
    fn only_a_real_is_continuous() {
        let mut continuous_string = Variable::string_output("out", "", |m: &Model| &m.label);
        continuous_string.variability = Variability::Continuous;
        let err = check(&[continuous_string]).unwrap_err();
        assert!(err.contains("only a Real can be continuous"), "{err}");
    }

    #[test]
    fn a_constant_has_no_setter_and_no_dependencies() {
        let mut settable = x_output().constant();
        settable.value = Value::Real(RealVariable {
            get: |m: &Model| m.x,
            set: Some(|m, v| m.x = v),
            unit: None,
            display_unit: None,
            min: None,
            max: None,
        });
        let err = check(&[settable]).unwrap_err();
        assert!(err.contains("a constant has a setter"), "{err}");
        let input = Variable::real_input("u", "", "1", |m: &Model| m.x, |m, v| m.x = v);
        let err = check(&[input, x_output().constant().depends_on(&["u"])]).unwrap_err();
        assert!(err.contains("a constant depends on nothing"), "{err}");
    }

    #[test]
    fn outputs_may_depend_on_the_time() {
        check(&[
            Variable::independent("time", "", ""),
            x_output().depends_on(&["time"]),
        ])
        .unwrap();
    }
}
