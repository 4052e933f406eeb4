//! Parameter values by FMI name, as a host sets them between
//! fmi2EnterInitializationMode and fmi2ExitInitializationMode: the JSON
//! parameter sets `{ "<FMI name>": value, ... }` (what an FMU crate's
//! `*-parameters` binary writes), a value typed by its variable's type, and
//! the name a user most likely meant by one the FMU does not have.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::{Instance, sys};

/// A parameter value as JSON holds it; the variable's own type decides the
/// setter (a whole number for an Integer, true/false for a Boolean).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ParameterValue {
    Boolean(bool),
    Number(f64),
}

impl<'de> Deserialize<'de> for ParameterValue {
    /// By hand rather than `untagged`, whose error for a string says only
    /// that no variant matched: this one says what a value may be.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Value;
        impl serde::de::Visitor<'_> for Value {
            type Value = ParameterValue;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a number, or true or false")
            }
            fn visit_bool<E>(self, v: bool) -> Result<ParameterValue, E> {
                Ok(ParameterValue::Boolean(v))
            }
            fn visit_f64<E>(self, v: f64) -> Result<ParameterValue, E> {
                Ok(ParameterValue::Number(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<ParameterValue, E> {
                Ok(ParameterValue::Number(v as f64))
            }
            fn visit_u64<E>(self, v: u64) -> Result<ParameterValue, E> {
                Ok(ParameterValue::Number(v as f64))
            }
        }
        deserializer.deserialize_any(Value)
    }
}

impl std::fmt::Display for ParameterValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParameterValue::Boolean(b) => write!(f, "{b}"),
            ParameterValue::Number(v) => write!(f, "{v}"),
        }
    }
}

/// A value ready for the setter of its variable's type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TypedValue {
    Real(f64),
    Integer(i32),
    Boolean(bool),
}

impl ParameterValue {
    /// The value for a variable of FMI type `kind` ("Real", "Integer",
    /// "Boolean", ...), or what such a variable takes ("a whole number").
    pub fn typed(self, kind: &str) -> Result<TypedValue, &'static str> {
        match (kind, self) {
            ("Real", ParameterValue::Number(v)) => Ok(TypedValue::Real(v)),
            ("Integer", ParameterValue::Number(v))
                if v.fract() == 0.0 && (f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&v) =>
            {
                Ok(TypedValue::Integer(v as i32))
            }
            ("Boolean", ParameterValue::Boolean(v)) => Ok(TypedValue::Boolean(v)),
            ("Real", _) => Err("a number"),
            // A whole number beyond fmi2Integer's 32 bits is not "not whole".
            ("Integer" | "Enumeration", ParameterValue::Number(v)) if v.fract() == 0.0 => {
                Err("a whole number from -2147483648 to 2147483647 (32 bits)")
            }
            ("Integer" | "Enumeration", _) => Err("a whole number"),
            ("Boolean", _) => Err("true or false"),
            _ => Err("no value set by name"),
        }
    }
}

impl Instance<'_> {
    /// Sets one typed value; returns the FMI function called and its status.
    pub fn set_typed(&self, vr: u32, value: TypedValue) -> (&'static str, sys::fmi2Status) {
        match value {
            TypedValue::Real(v) => ("fmi2SetReal", self.set_real(&[vr], &[v])),
            TypedValue::Integer(v) => ("fmi2SetInteger", self.set_integer(&[vr], &[v])),
            TypedValue::Boolean(v) => ("fmi2SetBoolean", self.set_boolean(&[vr], &[v])),
        }
    }
}

impl crate::Fmu {
    /// What an unknown name's message adds: ` (did you mean "x.c"?)` with
    /// the variable the user most likely meant ([`meant`]), else nothing.
    pub fn hint_for(&self, unknown: &str) -> String {
        meant(unknown, self.variables.iter().map(|v| v.name.as_str()))
            .map(|name| format!(" (did you mean {name:?}?)"))
            .unwrap_or_default()
    }
}

/// Reads a parameter set `{ "<FMI name>": value, ... }`, sorted by name. A
/// malformed file is named with its line and column.
pub fn read_parameter_set(path: &Path) -> Result<Vec<(String, ParameterValue)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    // A UTF-8 byte-order mark (Windows editors write one) is no JSON.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let map: serde_json::Map<String, serde_json::Value> =
        serde_json::from_str(text).map_err(|e| {
            format!(
                "{}:{}:{}: {}",
                path.display(),
                e.line(),
                e.column(),
                json_problem(&e)
            )
        })?;
    let nested = |name: &str, kind: &str| {
        format!(
            "{}: parameter {name}: {kind} is no value; a parameter set maps each variable's FMI \
             name to a number or a Boolean, and a nested file is parameters in another form, to \
             be converted to one first",
            path.display()
        )
    };
    map.into_iter()
        .map(|(name, value)| match value {
            serde_json::Value::Bool(b) => Ok((name, ParameterValue::Boolean(b))),
            serde_json::Value::Number(n) => {
                let v = n.as_f64().expect("serde_json numbers convert to f64");
                Ok((name, ParameterValue::Number(v)))
            }
            // A nested value is a file of parameters in another form (a
            // model's own struct, say): printed whole it was hundreds of
            // characters that did not say so.
            serde_json::Value::Object(_) => Err(nested(&name, "an object")),
            serde_json::Value::Array(_) => Err(nested(&name, "an array")),
            other => Err(format!(
                "{}: parameter {name}: {other} is neither a number nor a Boolean",
                path.display()
            )),
        })
        .collect()
}

/// serde_json's message without the place it ends with ("at line 3 column
/// 7"), for messages that lead with it as `file:line:column`.
pub fn json_problem(error: &serde_json::Error) -> String {
    let message = error.to_string();
    let place = format!(" at line {} column {}", error.line(), error.column());
    match message.strip_suffix(&place) {
        Some(problem) => problem.to_owned(),
        None => message,
    }
}

/// The name of `names` that `wanted` most likely means: the only one that
/// ends with it as a whole part (`x.p` for `bouc_wen.x.p`), else the only
/// one with the same name inside its group (a group renamed, as
/// PiezoController's `decoupling.dk[1]` became `compensation.dk[1]`), else
/// the only one closest to it within a typing error per four characters.
/// None when no name stands out.
pub fn meant<'a>(wanted: &str, names: impl Iterator<Item = &'a str> + Clone) -> Option<&'a str> {
    fn only<'a>(mut found: impl Iterator<Item = &'a str>) -> Option<&'a str> {
        match (found.next(), found.next()) {
            (Some(name), None) => Some(name),
            _ => None,
        }
    }
    let tail = format!(".{wanted}");
    if let Some(name) = only(names.clone().filter(|name| name.ends_with(&tail))) {
        return Some(name);
    }
    let inside = |name: &str| name.split_once('.').map(|(_, rest)| rest.to_owned());
    if let Some(leaf) = inside(wanted)
        && let Some(name) = only(
            names
                .clone()
                .filter(|name| inside(name).as_deref() == Some(leaf.as_str())),
        )
    {
        return Some(name);
    }
    // Short names get one edit: two would make most of `x.p` another name.
    let typos = (wanted.chars().count() / 4).max(1);
    let distance = |name: &str| strsim::levenshtein(wanted, name);
    let closest = names.clone().map(distance).min().filter(|&d| d <= typos)?;
    only(names.filter(|name| distance(name) == closest))
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: [&str; 7] = [
        "x_ref",
        "feedback_y",
        "compensation.dk[1]",
        "compensation.dk[2]",
        "x.k[1]",
        "y.k[1]",
        "decoupling",
    ];

    #[test]
    fn a_renamed_group_and_a_typo_are_found() {
        let names = NAMES.iter().copied();
        assert_eq!(
            meant("decoupling.dk[1]", names.clone()),
            Some("compensation.dk[1]")
        );
        assert_eq!(meant("feedbak_y", names.clone()), Some("feedback_y"));
        assert_eq!(meant("x_reff", names.clone()), Some("x_ref"));
        // A name given without its group is found by its ending, not by
        // the two-edit neighbour `x.c`.
        let names = ["x.c", "bouc_wen.x.p", "y.c", "translation.kp"];
        assert_eq!(meant("x.p", names.into_iter()), Some("bouc_wen.x.p"));
        // y's proportional gain is translation.kp's: its group renamed.
        assert_eq!(meant("y.kp", names.into_iter()), Some("translation.kp"));
        assert_eq!(meant("z.q", names.into_iter()), None);
    }

    #[test]
    fn no_name_is_offered_where_none_stands_out() {
        let names = NAMES.iter().copied();
        // Two groups hold k[1], and both are one edit away.
        assert_eq!(meant("z.k[1]", names.clone()), None);
        assert_eq!(meant("amplifier.gain", names.clone()), None);
    }

    /// A file a Windows editor saved with a UTF-8 byte-order mark reads as
    /// its twin without one; an error's line and column are an editor's.
    #[test]
    fn a_byte_order_mark_is_not_part_of_the_json() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("set.json");
        std::fs::write(&file, "\u{feff}{\"x.c\": 1.5, \"decoupling\": true}").unwrap();
        let set = read_parameter_set(&file).unwrap();
        assert_eq!(
            set,
            vec![
                ("decoupling".to_owned(), ParameterValue::Boolean(true)),
                ("x.c".to_owned(), ParameterValue::Number(1.5)),
            ]
        );
        std::fs::write(&file, "\u{feff}{\"x.c\": }").unwrap();
        let e = read_parameter_set(&file).unwrap_err();
        assert!(e.ends_with("set.json:1:9: expected value"), "{e}");
    }

    #[test]
    fn a_value_is_typed_by_its_variable() {
        use ParameterValue::{Boolean, Number};
        assert_eq!(Number(2.5).typed("Real"), Ok(TypedValue::Real(2.5)));
        assert_eq!(Number(3.0).typed("Integer"), Ok(TypedValue::Integer(3)));
        assert_eq!(Number(3.5).typed("Integer"), Err("a whole number"));
        assert_eq!(
            Number(1e10).typed("Integer"),
            Err("a whole number from -2147483648 to 2147483647 (32 bits)")
        );
        assert_eq!(
            Number(-2147483648.0).typed("Integer"),
            Ok(TypedValue::Integer(i32::MIN))
        );
        assert_eq!(
            Number(-2147483649.0).typed("Integer"),
            Err("a whole number from -2147483648 to 2147483647 (32 bits)")
        );
        assert_eq!(
            Boolean(true).typed("Boolean"),
            Ok(TypedValue::Boolean(true))
        );
        assert_eq!(Boolean(true).typed("Real"), Err("a number"));
        assert_eq!(Number(1.0).typed("Boolean"), Err("true or false"));
        assert_eq!(Number(1.0).typed("String"), Err("no value set by name"));
    }

    #[test]
    fn a_value_of_another_kind_is_refused_saying_what_a_value_may_be() {
        let parsed = |text| serde_json::from_str::<ParameterValue>(text);
        assert_eq!(parsed("3").unwrap(), ParameterValue::Number(3.0));
        assert_eq!(parsed("-2.5").unwrap(), ParameterValue::Number(-2.5));
        assert_eq!(parsed("false").unwrap(), ParameterValue::Boolean(false));
        let error = parsed("\"3\"").unwrap_err().to_string();
        assert!(
            error.starts_with("invalid type: string \"3\", expected a number, or true or false"),
            "{error}"
        );
    }

    #[test]
    fn a_parameter_set_is_read_and_a_bad_one_named_by_its_place() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.json");
        std::fs::write(&good, r#"{"b": true, "a": 1.5}"#).unwrap();
        assert_eq!(
            read_parameter_set(&good).unwrap(),
            [
                ("a".to_owned(), ParameterValue::Number(1.5)),
                ("b".to_owned(), ParameterValue::Boolean(true))
            ]
        );
        let bad = dir.path().join("bad.json");
        std::fs::write(&bad, "{\"x.c\": 1,\n\"L\" 2}").unwrap();
        assert_eq!(
            read_parameter_set(&bad).unwrap_err(),
            format!("{}:2:5: expected `:`", bad.display())
        );
        std::fs::write(&bad, r#"{"actuators": [{"gain": 1.0}]}"#).unwrap();
        assert_eq!(
            read_parameter_set(&bad).unwrap_err(),
            format!(
                "{}: parameter actuators: an array is no value; a parameter set maps each \
                 variable's FMI name to a number or a Boolean, and a nested file is parameters \
                 in another form, to be converted to one first",
                bad.display()
            )
        );
        std::fs::write(&bad, r#"{"name": "text"}"#).unwrap();
        assert_eq!(
            read_parameter_set(&bad).unwrap_err(),
            format!(
                "{}: parameter name: \"text\" is neither a number nor a Boolean",
                bad.display()
            )
        );
    }
}
