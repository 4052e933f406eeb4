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
            eprintln!("{program}: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
