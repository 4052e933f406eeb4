//! A model's parameter values by FMI name: what an importer sets, before
//! `fmi2ExitInitializationMode`, to load a parameter set into the FMU (an
//! fmpy `start_values` dict, a Simulink mask, an SSP parameter set). Read
//! through the same variable table that serves `fmi2GetReal`, so the names
//! are the FMU's own and nothing is written twice.

use serde::Serialize;

use crate::model::CoSimModel;
use crate::variables::{Causality, Value};

/// One parameter's value, in its FMI type.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ScalarValue {
    Real(f64),
    Integer(i32),
    Boolean(bool),
    String(String),
}

/// Every parameter of `model` (causality "parameter"), in value-reference
/// order, with the value `model` holds.
pub fn parameter_values<M: CoSimModel>(model: &M) -> Vec<(&'static str, ScalarValue)> {
    M::variables()
        .iter()
        .filter(|v| v.causality == Causality::Parameter)
        .filter_map(|v| {
            let value = match &v.value {
                Value::Real(r) => ScalarValue::Real((r.get)(model)),
                Value::Integer(i) => ScalarValue::Integer((i.get)(model)),
                Value::Boolean(b) => ScalarValue::Boolean((b.get)(model)),
                Value::String(s) => ScalarValue::String((s.get)(model).to_owned()),
                // The time is the independent variable, never a parameter.
                Value::Time(_) => return None,
            };
            Some((v.name, value))
        })
        .collect()
}

/// Reads a model's own parameter struct from the JSON file at `path`. A
/// malformed file is named with the line, column and key of the problem:
/// `my.json:49:15: x_model.c: invalid type: string "oops", expected f64`.
pub fn read_json<P: serde::de::DeserializeOwned>(path: &str) -> Result<P, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut reader = serde_json::Deserializer::from_str(&text);
    let params = serde_path_to_error::deserialize(&mut reader).map_err(|e| {
        let key = e.path().to_string();
        located(path, &key, &e.into_inner())
    })?;
    // Text after the object is an error too, as serde_json::from_str has it.
    reader.end().map_err(|e| located(path, ".", &e))?;
    Ok(params)
}

/// `path:line:column: key: problem` (no key for the document itself, ".",
/// nor where the text ended before a key was read, "?").
fn located(path: &str, key: &str, error: &serde_json::Error) -> String {
    // serde_json ends its message with the place, which leads here instead.
    let place = format!(" at line {} column {}", error.line(), error.column());
    let message = error.to_string();
    let message = message.strip_suffix(&place).unwrap_or(&message);
    let key = match key {
        "." | "?" => String::new(),
        key => format!("{key}: "),
    };
    format!("{path}:{}:{}: {key}{message}", error.line(), error.column())
}

/// `main` of a model's parameter-set binary: `<binary> <preset> <out.json>`
/// writes `{ "<FMI name>": value, ... }` for the model `build(preset)`
/// returns (a preset name the model knows, or a path to its own JSON).
pub fn main<M: CoSimModel>(
    presets: &str,
    build: impl Fn(&str) -> Result<M, String>,
) -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let program = args.first().map_or("parameters", String::as_str);
    let [_, preset, out] = args.as_slice() else {
        eprintln!(
            "usage: {program} <preset> <out.json>\n\nwrites the parameter values of {} for \
             <preset> ({presets}) by FMI name, as an importer sets them",
            M::INFO.model_identifier
        );
        return std::process::ExitCode::from(2);
    };
    let result = build(preset).and_then(|model| {
        let map: serde_json::Map<String, serde_json::Value> = parameter_values(&model)
            .into_iter()
            .map(|(name, value)| {
                let value = serde_json::to_value(value).expect("scalars serialise");
                (name.to_owned(), value)
            })
            .collect();
        let json = serde_json::to_string_pretty(&map).map_err(|e| e.to_string())?;
        std::fs::write(out, json + "\n").map_err(|e| format!("{out}: {e}"))
    });
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            match already_by_fmi_name::<M>(preset) {
                Some(names) => eprintln!(
                    "{program}: {preset} is already a parameter set by FMI name ({names} of {}'s \
                     variables, the form this tool writes): importers take it as it is (fmpy's \
                     start_values, a Simulink mask, an SSP parameter set). This tool takes {presets}.",
                    M::INFO.model_identifier
                ),
                None => eprintln!("{program}: {e}"),
            }
            std::process::ExitCode::FAILURE
        }
    }
}

/// The number of keys of the JSON object in the file at `path` when every
/// one of them names a variable of `M`: a set by FMI name, given where the
/// model's own parameter JSON is expected. `None` for anything else (not a
/// file, not JSON, not an object, an empty object, a key `M` lacks).
fn already_by_fmi_name<M: CoSimModel>(path: &str) -> Option<usize> {
    let text = std::fs::read_to_string(path).ok()?;
    let serde_json::Value::Object(map) = serde_json::from_str(&text).ok()? else {
        return None;
    };
    let known = |key: &String| M::variables().iter().any(|v| v.name == key);
    (!map.is_empty() && map.keys().all(known)).then_some(map.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, PartialEq)]
    struct Params {
        gain: f64,
        stages: Vec<Stage>,
    }

    #[derive(Debug, serde::Deserialize, PartialEq)]
    struct Stage {
        on: bool,
    }

    /// Reads `text` from a file of its own (tests run in parallel).
    fn read(text: &str) -> Result<Params, String> {
        static FILES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let number = FILES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let file = std::env::temp_dir().join(format!(
            "parameter-set-{}-{number}.json",
            std::process::id()
        ));
        std::fs::write(&file, text).unwrap();
        let path = file.to_str().unwrap().to_owned();
        let read = read_json(&path).map_err(|e| e.replacen(&path, "p.json", 1));
        std::fs::remove_file(&file).unwrap();
        read
    }

    #[test]
    fn a_well_formed_file_is_read() {
        let params = read("{\"gain\": 2.5, \"stages\": [{\"on\": true}]}\n").unwrap();
        assert_eq!(params.stages, [Stage { on: true }]);
    }

    #[test]
    fn a_bad_value_is_named_by_its_place_and_key_once() {
        let text = "{\n  \"gain\": 1,\n  \"stages\": [{\"on\": true}, {\"on\": \"yes\"}]\n}";
        assert_eq!(
            read(text).unwrap_err(),
            "p.json:3:39: stages[1].on: invalid type: string \"yes\", expected a boolean"
        );
    }

    #[test]
    fn a_missing_key_text_after_the_object_and_a_cut_file_are_named() {
        assert_eq!(
            read("{\"stages\": []}").unwrap_err(),
            "p.json:1:14: missing field `gain`"
        );
        assert_eq!(
            read("{\"gain\": 1, \"stages\": []} x").unwrap_err(),
            "p.json:1:27: trailing characters"
        );
        assert_eq!(
            read("{\"gain\": 1,").unwrap_err(),
            "p.json:1:11: EOF while parsing a value"
        );
    }

    #[test]
    fn a_missing_file_is_named() {
        let error = read_json::<Params>("/no/such/parameters.json").unwrap_err();
        assert!(error.starts_with("/no/such/parameters.json: "), "{error}");
    }
}
