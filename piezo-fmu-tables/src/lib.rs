//! What both piezo FMUs build alike from `piezo-models`' parameter
//! declarations: the variable-table entries of an asymmetric Bouc-Wen model
//! ([`bouc_wen_variables!`]), a declared [`Range`] as FMI min/max
//! ([`with_range`]), the units those need, and the test that the FMU
//! tables' ranges agree with the models' validation
//! ([`check_declared_ranges`]).
//!
//! The layering stays as the guide draws it: `piezo-models` declares field,
//! unit, range and meaning as plain data and knows nothing of FMI;
//! `fmi2-cosim` knows nothing of piezos; this crate and the FMU crates are
//! the join.

use fmi2_cosim::variables::Value;
use fmi2_cosim::{BaseUnit, Causality, ModelError, UnitDefinition, Variable};
use piezo_models::{ParamError, Range};

#[doc(hidden)]
pub use const_format;
#[doc(hidden)]
pub use piezo_models::BoucWenParams;

/// µm per volt (Bouc-Wen p and A): m / (kg m² s⁻³ A⁻¹).
pub const MICROMETRE_PER_VOLT: UnitDefinition = UnitDefinition {
    name: "um/V",
    base: BaseUnit {
        kg: -1,
        m: -1,
        s: 3,
        a: 1,
        factor: 1e-6,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

/// µm per volt squared (Bouc-Wen delta).
pub const MICROMETRE_PER_VOLT_SQUARED: UnitDefinition = UnitDefinition {
    name: "um/V2",
    base: BaseUnit {
        kg: -2,
        m: -3,
        s: 6,
        a: 2,
        factor: 1e-6,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

/// `variable` with the declared `range` as its FMI min and max. FMI's bounds
/// are inclusive: an open end is declared as the nearest double inside it (a
/// tool that samples at the declared bounds gets values the model takes),
/// stated in the variable's description as the open condition, and
/// enforced by the model's validation, which reads the same declaration
/// ([`check_declared_ranges`] tests all three).
pub const fn with_range<M>(variable: Variable<M>, range: Range) -> Variable<M> {
    variable.range(range.min_value(), range.max_value())
}

/// The FMI name of the parameter the model calls `path` (its serde path, as
/// in the JSON presets), through the table's `model_path`.
pub fn fmi_name<M>(variables: &[Variable<M>], path: &str) -> Option<&'static str> {
    variables
        .iter()
        .find(|v| v.model_path.is_some_and(|p| p.replace(' ', "") == path))
        .map(|v| v.name)
}

/// The error an FMU returns for a parameter its model refuses, naming the
/// parameter by its FMI name and its serde path.
pub fn refused_parameter<M>(variables: &[Variable<M>], error: &ParamError) -> ModelError {
    let name = fmi_name(variables, &error.parameter).unwrap_or("a parameter");
    ModelError(format!(
        "parameter {name} ({}) = {} is not allowed: {}",
        error.parameter,
        error.value,
        with_fmi_names(variables, &error.allowed)
    ))
}

/// `text` with every model path of a group of parameters (a serde path up
/// to its last field, `actuators[0].hysteresis`) written as the importer
/// knows the group (`pzt[1]`), longest paths first so that
/// `actuators[0].hysteresis` is not read as `actuators[0]` and a field.
fn with_fmi_names<M>(variables: &[Variable<M>], text: &str) -> String {
    let mut groups: Vec<(String, &str)> = variables
        .iter()
        .filter_map(|v| {
            let path = v.model_path?.replace(' ', "");
            let (group, _) = path.rsplit_once('.')?;
            let (name_group, _) = v.name.rsplit_once('.')?;
            (group != name_group).then(|| (group.to_owned(), name_group))
        })
        .collect();
    groups.sort_by(|a, b| b.0.len().cmp(&a.0.len()).then_with(|| a.0.cmp(&b.0)));
    groups.dedup();
    groups.iter().fold(text.to_owned(), |text, (group, name)| {
        text.replace(group.as_str(), name)
    })
}

/// How many variables `blocks` hold together: the length of the table
/// `fmi2_cosim::variables::concat(blocks)` builds, so that no table length
/// is counted by hand.
pub const fn total_len<M>(blocks: &[&[Variable<M>]]) -> usize {
    let mut total = 0;
    let mut b = 0;
    while b < blocks.len() {
        total += blocks[b].len();
        b += 1;
    }
    total
}

/// A fixed Real parameter of `$model` whose value lives at
/// `model.params.<path>`, in the range piezo-models declares for it (an
/// open end is stated in the description), with `<path>` as its model path.
#[macro_export]
macro_rules! fixed_parameter {
    ($model:ty, $name:expr, $description:expr, $unit:expr, $range:expr, $($path:tt)+) => {
        $crate::with_range(
            ::fmi2_cosim::Variable::real_parameter(
                $name,
                $description,
                $unit,
                ::fmi2_cosim::Variability::Fixed,
                |m: &$model| m.params.$($path)+,
                |m: &mut $model, v: f64| m.params.$($path)+ = v,
            ),
            $range,
        )
        .model_path(stringify!($($path)+))
    };
}

/// The seven fixed Real parameters `<prefix>.<symbol>` of the asymmetric
/// Bouc-Wen model at `model.params.<path>`, as an array of table entries in
/// [`BoucWenParams::PARAMETERS`] order, each described as
/// `<who>: <declared description>`:
///
/// ```text
/// const PZT1: [Variable<FlexureStageFmu>; 7] =
///     bouc_wen_variables!(FlexureStageFmu, "pzt[1]", "PZT1 hysteresis", actuators[0].hysteresis);
/// ```
#[macro_export]
macro_rules! bouc_wen_variables {
    ($model:ty, $prefix:literal, $who:literal, $($path:tt)+) => {
        [
            $crate::bouc_wen_variables!(@one $model, 0, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 1, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 2, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 3, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 4, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 5, $prefix, $who, $($path)+),
            $crate::bouc_wen_variables!(@one $model, 6, $prefix, $who, $($path)+),
        ]
    };
    (@one $model:ty, $i:literal, $prefix:literal, $who:literal, $($path:tt)+) => {
        $crate::with_range(
            ::fmi2_cosim::Variable::real_parameter(
                $crate::const_format::concatcp!(
                    $prefix,
                    ".",
                    $crate::BoucWenParams::PARAMETERS[$i].symbol
                ),
                $crate::const_format::concatcp!(
                    $who,
                    ": ",
                    $crate::BoucWenParams::PARAMETERS[$i].description
                ),
                $crate::BoucWenParams::PARAMETERS[$i].unit,
                ::fmi2_cosim::Variability::Fixed,
                |m: &$model| ($crate::BoucWenParams::PARAMETERS[$i].get)(&m.params.$($path)+),
                |m: &mut $model, v: f64| {
                    ($crate::BoucWenParams::PARAMETERS[$i].set)(&mut m.params.$($path)+, v)
                },
            ),
            $crate::BoucWenParams::PARAMETERS[$i].range,
        )
        .model_path($crate::const_format::concatcp!(
            stringify!($($path)+),
            ".",
            $crate::BoucWenParams::PARAMETERS[$i].field
        ))
    };
}

/// One `const NAME: &[Variable<$model>]` block of [`bouc_wen_variables!`]
/// per line `NAME = (prefix, who, path);`, so that a table lists its
/// Bouc-Wen models one line each.
#[macro_export]
macro_rules! bouc_wen_blocks {
    ($model:ty; $($name:ident = ($prefix:literal, $who:literal, $($path:tt)+);)+) => {
        $(
            const $name: &[::fmi2_cosim::Variable<$model>] =
                &$crate::bouc_wen_variables!($model, $prefix, $who, $($path)+);
        )+
    };
}

/// Checks, for every Real parameter of `variables` that declares a min or a
/// max, that the model's validation agrees with the table: a value at the
/// bound is accepted (FMI's min and max are inclusive), a value just beyond
/// it is refused by name (its `model_path`), and an open end (declared as
/// the double next to a round value, or the smallest normal double for `> 0`)
/// has the round value
/// refused and its strict bound stated in the description (`> 0`, `0 <`,
/// `< 1`). `fresh` gives a model with valid parameters, `validate` runs the
/// model's validation on a model's parameters. A parameter whose name ends
/// with one of `tied` has a rule against other parameters tighter than its
/// own range (a creep time above ten amplifier time constants): its declared
/// bound may be refused, by that rule, which its description must state
/// (`more than`).
pub fn check_declared_ranges<M>(
    variables: &[Variable<M>],
    fresh: impl Fn() -> M,
    validate: impl Fn(&M) -> Result<(), ParamError>,
    tied: &[&str],
) {
    let refused_by_name = |model: &M, path: &str| match validate(model) {
        Ok(()) => false,
        Err(e) => e.parameter == path.replace(' ', ""),
    };
    let mut checked = 0;
    for variable in variables {
        let Value::Real(real) = &variable.value else {
            continue;
        };
        let Some(set) = real.set else { continue };
        if variable.causality != Causality::Parameter {
            continue;
        }
        let path = variable
            .model_path
            .unwrap_or_else(|| panic!("{} has no model path", variable.name));
        for (bound, outward) in [(real.min, -1.0), (real.max, 1.0)] {
            let Some(bound) = bound else { continue };
            checked += 1;
            let mut model = fresh();
            set(&mut model, bound);
            if tied.iter().any(|t| variable.name.ends_with(t)) {
                assert!(
                    variable.description.contains("more than"),
                    "{}: a rule against other parameters must be stated: {:?}",
                    variable.name,
                    variable.description
                );
            } else {
                assert!(
                    !refused_by_name(&model, path),
                    "{} = {bound} is its declared (inclusive) bound, but the model refuses it",
                    variable.name
                );
            }
            let beyond = bound + outward * (bound.abs() * 1e-6).max(1e-9);
            let mut model = fresh();
            set(&mut model, beyond);
            assert!(
                refused_by_name(&model, path),
                "{} = {beyond} is beyond its declared bound {bound}, but the model's \
                 validation does not refuse it by name",
                variable.name
            );
            // The smallest normal double declares an open end at 0.
            let outside = if bound.abs() == f64::MIN_POSITIVE {
                0.0
            } else if outward < 0.0 {
                bound.next_down()
            } else {
                bound.next_up()
            };
            if fmt(outside).len() < fmt(bound).len() {
                let strict = if outward < 0.0 {
                    [format!("> {}", fmt(outside)), format!("{} <", fmt(outside))]
                } else {
                    [format!("< {}", fmt(outside)), format!("{} >", fmt(outside))]
                };
                assert!(
                    strict
                        .iter()
                        .any(|s| variable.description.contains(s.as_str())),
                    "{}: its declared bound {bound} stands for the open end {outside}, so the \
                     description must say so ({strict:?}): {:?}",
                    variable.name,
                    variable.description
                );
                let mut model = fresh();
                set(&mut model, outside);
                assert!(
                    refused_by_name(&model, path),
                    "{} = {outside} is the open end of its range, but the model takes it",
                    variable.name
                );
            }
        }
    }
    assert!(checked > 0, "no Real parameter declares a range");
}

fn fmt(value: f64) -> String {
    fmi2_cosim::model_description::format_real(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Model(f64);

    const fn real(name: &'static str) -> Variable<Model> {
        Variable::real_local(name, "", "", |m: &Model| m.0)
    }

    #[test]
    fn total_len_adds_the_blocks() {
        let table = [real("a"), real("b"), real("c")];
        assert_eq!(total_len(&[&table, &table[..1]]), 4);
    }
}
