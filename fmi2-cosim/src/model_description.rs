//! `modelDescription.xml`, generated from the variable table that the binary
//! serves, and the GUID derived from it.
//!
//! The XML is written with quick-xml rather than serialized through fmi-schema's
//! FMI 2.0 types because those types drop an empty `dependencies` list (which
//! would turn "depends on nothing" into "depends on everything") and carry no
//! `unit`, `displayUnit`, `min` or `max` on a ScalarVariable's `<Real>`. The
//! tests parse the result back with fmi-schema and check it against the table.
//!
//! The GUID is a name-based UUID (v5) of the description itself, rendered with a
//! placeholder GUID: the same in every build and on every platform, and
//! different as soon as anything a tool reads from the description changes.

use std::any::TypeId;
use std::io::Cursor;
use std::sync::Mutex;

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, BytesText, Event};

use crate::logging::LogCategory;
use crate::model::CoSimModel;
use crate::variables::{Causality, Initial, Value, Variable, check_table, continuous_states};

/// Namespace of the name-based GUIDs of this layer's FMUs.
const GUID_NAMESPACE: uuid::Uuid = uuid::uuid!("5d2b8a6e-3f4c-4e1a-9b7d-2c6f0e8a1d34");
const GUID_PLACEHOLDER: &str = "{00000000-0000-0000-0000-000000000000}";

/// Formats a Real so that it parses back to the same bits, in plain notation
/// where that is readable and in exponent notation otherwise.
pub fn format_real(x: f64) -> String {
    let magnitude = x.abs();
    if x == 0.0 || (1e-4..1e7).contains(&magnitude) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// The start value of the variable named `name`, as modelDescription.xml
/// writes it; None for an unknown name or a variable without one.
pub fn start_text<M: CoSimModel>(name: &str) -> Option<String> {
    let model = M::new();
    M::variables()
        .iter()
        .find(|v| v.name == name)
        .and_then(|v| start_value(v, &model))
}

/// The start value modelDescription declares for `var` (those that have
/// one: [`Variable::has_start`]), read from the start-up `model`.
fn start_value<M>(var: &Variable<M>, model: &M) -> Option<String> {
    if !var.has_start() {
        return None;
    }
    match &var.value {
        Value::Real(r) => Some(format_real((r.get)(model))),
        Value::Integer(i) => Some((i.get)(model).to_string()),
        Value::Boolean(b) => Some((b.get)(model).to_string()),
        Value::String(s) => Some((s.get)(model).to_owned()),
        // The independent variable has none (check_table).
        Value::Time(_) => None,
    }
}

/// Whether XML 1.0 can carry `c` at all (§2.2 Char): not even a character
/// reference spells the other control characters.
fn xml_char(c: char) -> bool {
    matches!(c, '\t' | '\n' | '\r' | '\u{20}'..='\u{d7ff}' | '\u{e000}'..='\u{fffd}' | '\u{10000}'..)
}

/// 1-based indices of the named variables, ascending, space separated.
fn index_list<M>(table: &[Variable<M>], names: &[&str]) -> String {
    let mut indices: Vec<usize> = names
        .iter()
        .map(|name| {
            table
                .iter()
                .position(|v| v.name == *name)
                .expect("dependencies were checked by check_table")
                + 1
        })
        .collect();
    indices.sort_unstable();
    indices
        .iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

type XmlResult = Result<(), String>;

struct Xml {
    writer: Writer<Cursor<Vec<u8>>>,
}

impl Xml {
    fn new() -> Xml {
        Xml {
            writer: Writer::new_with_indent(Cursor::new(Vec::new()), b' ', 2),
        }
    }

    fn event(&mut self, event: Event<'_>) -> XmlResult {
        self.writer.write_event(event).map_err(|e| e.to_string())
    }

    fn element(name: &str, attributes: &[(&str, &str)]) -> BytesStart<'static> {
        let mut start = BytesStart::new(name.to_owned());
        for (key, value) in attributes {
            start.push_attribute((*key, *value));
        }
        start
    }

    fn empty(&mut self, name: &str, attributes: &[(&str, &str)]) -> XmlResult {
        self.event(Event::Empty(Xml::element(name, attributes)))
    }

    fn open(&mut self, name: &str, attributes: &[(&str, &str)]) -> XmlResult {
        self.event(Event::Start(Xml::element(name, attributes)))
    }

    fn close(&mut self, name: &str) -> XmlResult {
        self.event(Event::End(BytesEnd::new(name.to_owned())))
    }

    fn comment(&mut self, text: &str) -> XmlResult {
        self.event(Event::Comment(BytesText::new(text)))
    }

    fn finish(self) -> String {
        let mut text = String::from_utf8(self.writer.into_inner().into_inner())
            .expect("quick-xml writes UTF-8");
        text.push('\n');
        text
    }
}

/// Checks that the model's Model Exchange declaration agrees with its table.
fn check_model_exchange<M: CoSimModel>() -> Result<(), String> {
    let states = continuous_states(M::variables()).len();
    match M::MODEL_EXCHANGE {
        Some(me) if me.number_of_continuous_states != states => Err(format!(
            "{} declares {} continuous states but its table has {states} state derivatives",
            M::INFO.model_identifier,
            me.number_of_continuous_states
        )),
        None if states > 0 => Err(format!(
            "{} is co-simulation only but its table declares {states} state derivatives",
            M::INFO.model_identifier
        )),
        _ => Ok(()),
    }
}

/// The description with `guid`, its start values read from `start_model`, a
/// model as [`CoSimModel::new`] builds it.
fn render<M: CoSimModel>(guid: &str, start_model: &M) -> Result<String, String> {
    let table = M::variables();
    check_table(table, M::UNITS)?;
    check_model_exchange::<M>()?;
    let event_indicators = M::MODEL_EXCHANGE
        .map_or(0, |me| me.number_of_event_indicators)
        .to_string();
    let info = M::INFO;
    let mut xml = Xml::new();

    xml.event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let version = info.version;
    let generation_tool = concat!("fmi2-cosim ", env!("CARGO_PKG_VERSION"));
    let structured = if table
        .iter()
        .any(|v| v.name.contains('.') || v.name.contains('['))
    {
        "structured"
    } else {
        "flat"
    };
    xml.open(
        "fmiModelDescription",
        &[
            ("fmiVersion", "2.0"),
            ("modelName", info.model_name),
            ("guid", guid),
            ("description", info.description),
            ("author", info.author),
            ("version", version),
            ("license", info.license),
            ("generationTool", generation_tool),
            ("variableNamingConvention", structured),
            ("numberOfEventIndicators", &event_indicators),
        ],
    )?;
    if M::MODEL_EXCHANGE.is_some() {
        // The same binary serves both interfaces (as the Reference FMUs
        // ship): one modelIdentifier.
        xml.empty(
            "ModelExchange",
            &[
                ("modelIdentifier", info.model_identifier),
                ("needsExecutionTool", "false"),
                // The model checks its state after every accepted step.
                ("completedIntegratorStepNotNeeded", "false"),
                ("canBeInstantiatedOnlyOncePerProcess", "false"),
                ("canNotUseMemoryManagementFunctions", "true"),
                ("canGetAndSetFMUstate", "true"),
                ("canSerializeFMUstate", "true"),
                ("providesDirectionalDerivative", "false"),
            ],
        )?;
    }
    xml.empty(
        "CoSimulation",
        &[
            ("modelIdentifier", info.model_identifier),
            ("needsExecutionTool", "false"),
            ("canHandleVariableCommunicationStepSize", "true"),
            ("canInterpolateInputs", "false"),
            ("maxOutputDerivativeOrder", "0"),
            ("canRunAsynchronuously", "false"),
            ("canBeInstantiatedOnlyOncePerProcess", "false"),
            ("canNotUseMemoryManagementFunctions", "true"),
            ("canGetAndSetFMUstate", "true"),
            ("canSerializeFMUstate", "true"),
            ("providesDirectionalDerivative", "false"),
        ],
    )?;

    xml.open("UnitDefinitions", &[])?;
    for unit in M::UNITS {
        xml.open("Unit", &[("name", unit.name)])?;
        let b = unit.base;
        let exponents = [
            ("kg", b.kg),
            ("m", b.m),
            ("s", b.s),
            ("A", b.a),
            ("K", b.k),
            ("mol", b.mol),
            ("cd", b.cd),
            ("rad", b.rad),
        ];
        let mut owned: Vec<(&str, String)> = exponents
            .iter()
            .filter(|(_, e)| *e != 0)
            .map(|(k, e)| (*k, e.to_string()))
            .collect();
        if b.factor != 1.0 {
            owned.push(("factor", format_real(b.factor)));
        }
        if b.offset != 0.0 {
            owned.push(("offset", format_real(b.offset)));
        }
        let attributes: Vec<(&str, &str)> = owned.iter().map(|(k, v)| (*k, v.as_str())).collect();
        xml.empty("BaseUnit", &attributes)?;
        for display in unit.display_units {
            let factor = format_real(display.factor);
            let offset = format_real(display.offset);
            let mut attributes = vec![("name", display.name), ("factor", factor.as_str())];
            if display.offset != 0.0 {
                attributes.push(("offset", offset.as_str()));
            }
            xml.empty("DisplayUnit", &attributes)?;
        }
        xml.close("Unit")?;
    }
    xml.close("UnitDefinitions")?;

    xml.open("LogCategories", &[])?;
    for category in LogCategory::ALL {
        xml.empty(
            "Category",
            &[
                ("name", category.name().to_str().expect("ASCII")),
                ("description", category.description()),
            ],
        )?;
    }
    xml.empty(
        "Category",
        &[
            ("name", LogCategory::ALL_NAME),
            ("description", "All of the above"),
        ],
    )?;
    xml.close("LogCategories")?;

    let experiment = info.default_experiment;
    xml.empty(
        "DefaultExperiment",
        &[
            ("startTime", &format_real(experiment.start_time)),
            ("stopTime", &format_real(experiment.stop_time)),
            ("stepSize", &format_real(experiment.step_size)),
        ],
    )?;

    xml.open("ModelVariables", &[])?;
    let index_of = |name: &str| {
        table
            .iter()
            .position(|v| v.name == name)
            .map(|i| (i + 1).to_string())
            .expect("states were checked by check_table")
    };
    for (vr, var) in table.iter().enumerate() {
        xml.comment(&format!(" index {} ", vr + 1))?;
        let vr_text = vr.to_string();
        let mut attributes = vec![("name", var.name), ("valueReference", vr_text.as_str())];
        if !var.description.is_empty() {
            attributes.push(("description", var.description));
        }
        attributes.push(("causality", var.causality.as_str()));
        attributes.push(("variability", var.variability.as_str()));
        if let Some(initial) = var.initial() {
            attributes.push(("initial", initial.as_str()));
        }
        xml.open("ScalarVariable", &attributes)?;
        let start = start_value(var, start_model);
        if let Some(bad) = start
            .as_deref()
            .and_then(|s| s.chars().find(|c| !xml_char(*c)))
        {
            return Err(format!(
                "the start value of {} holds U+{:04X}, which XML 1.0 cannot carry",
                var.name, bad as u32
            ));
        }
        let mut typed: Vec<(&str, String)> = Vec::new();
        match &var.value {
            Value::Real(r) => {
                if let Some(unit) = r.unit {
                    typed.push(("unit", unit.to_owned()));
                }
                if let Some(display) = r.display_unit {
                    typed.push(("displayUnit", display.to_owned()));
                }
                if let Some(min) = r.min {
                    typed.push(("min", format_real(min)));
                }
                if let Some(max) = r.max {
                    typed.push(("max", format_real(max)));
                }
            }
            Value::Time(t) => {
                if let Some(unit) = t.unit {
                    typed.push(("unit", unit.to_owned()));
                }
                if let Some(display) = t.display_unit {
                    typed.push(("displayUnit", display.to_owned()));
                }
            }
            Value::Integer(i) => {
                if let Some(min) = i.min {
                    typed.push(("min", min.to_string()));
                }
                if let Some(max) = i.max {
                    typed.push(("max", max.to_string()));
                }
            }
            Value::Boolean(_) | Value::String(_) => {}
        }
        if let Some(start) = start {
            typed.push(("start", start));
        }
        if let Some(state) = var.derivative_of {
            typed.push(("derivative", index_of(state)));
        }
        let attributes: Vec<(&str, &str)> = typed.iter().map(|(k, v)| (*k, v.as_str())).collect();
        xml.empty(var.value.type_name(), &attributes)?;
        xml.close("ScalarVariable")?;
    }
    xml.close("ModelVariables")?;

    xml.open("ModelStructure", &[])?;
    let outputs: Vec<(usize, &Variable<M>)> = table
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == Causality::Output)
        .collect();
    if !outputs.is_empty() {
        xml.open("Outputs", &[])?;
        for (i, var) in &outputs {
            let index = (i + 1).to_string();
            let deps = index_list(table, var.output_dependencies);
            xml.empty("Unknown", &[("index", &index), ("dependencies", &deps)])?;
        }
        xml.close("Outputs")?;
    }
    let derivatives: Vec<(usize, &Variable<M>)> = table
        .iter()
        .enumerate()
        .filter(|(_, v)| v.derivative_of.is_some())
        .collect();
    if !derivatives.is_empty() {
        xml.open("Derivatives", &[])?;
        for (i, var) in &derivatives {
            let index = (i + 1).to_string();
            let deps = index_list(table, var.output_dependencies);
            xml.empty("Unknown", &[("index", &index), ("dependencies", &deps)])?;
        }
        xml.close("Derivatives")?;
    }
    // FMI 2.0.4 §2.2.8: the outputs that are not exact (a constant output
    // is known from its start value), the calculated parameters, and the
    // states and state derivatives that are not exact, in index order.
    let states: Vec<usize> = continuous_states(table).iter().map(|(s, _)| *s).collect();
    let initial_unknowns: Vec<(usize, &Variable<M>)> = table
        .iter()
        .enumerate()
        .filter(|(i, v)| {
            let computed = v.initial() != Some(Initial::Exact);
            v.causality == Causality::CalculatedParameter
                || (computed
                    && (v.causality == Causality::Output
                        || v.derivative_of.is_some()
                        || states.contains(i)))
        })
        .collect();
    if !initial_unknowns.is_empty() {
        xml.open("InitialUnknowns", &[])?;
        for (i, var) in &initial_unknowns {
            let index = (i + 1).to_string();
            match var.initial_dependencies {
                Some(knowns) => {
                    let deps = index_list(table, knowns);
                    xml.empty("Unknown", &[("index", &index), ("dependencies", &deps)])?;
                }
                None => xml.empty("Unknown", &[("index", &index)])?,
            }
        }
        xml.close("InitialUnknowns")?;
    }
    xml.close("ModelStructure")?;
    xml.close("fmiModelDescription")?;
    Ok(xml.finish())
}

/// The GUID of model `M`: `{` + a UUID v5 of its description + `}`.
pub fn guid<M: CoSimModel>() -> Result<String, String> {
    guid_with(&M::new())
}

/// [`guid`] with the start values read from `start_model`, a model as
/// [`CoSimModel::new`] builds it (for a caller that holds one already: a
/// model's construction can cost more than the rendering).
fn guid_with<M: CoSimModel>(start_model: &M) -> Result<String, String> {
    Ok(guid_of_description(&render(GUID_PLACEHOLDER, start_model)?))
}

/// Model `M`'s description with a placeholder where the GUID goes: what the
/// GUID is a hash of.
pub fn description_without_guid<M: CoSimModel>() -> Result<String, String> {
    render(GUID_PLACEHOLDER, &M::new())
}

/// `{` + a UUID v5 of `description` + `}`: any change of the description
/// (a name, a value reference, a unit, a start value) changes the GUID.
pub fn guid_of_description(description: &str) -> String {
    let uuid = uuid::Uuid::new_v5(&GUID_NAMESPACE, description.as_bytes());
    format!("{{{}}}", uuid.hyphenated())
}

/// Length of a GUID as [`guid`] spells it: braces around 36 characters.
const GUID_LEN: usize = 38;
/// Models whose GUID this process has computed. A binary exports one model;
/// test binaries link a few. A fixed table, not a map, so that nothing stays
/// allocated for the life of the process.
type GuidTable = [Option<(TypeId, [u8; GUID_LEN])>; 8];
static GUIDS: Mutex<GuidTable> = Mutex::new([None; 8]);

/// [`guid`], computed once per process and model: rendering and hashing the
/// description takes about 0.25 ms for PiezoController's 144 variables, which
/// every `fmi2Instantiate` paid. `start_model` is a model as
/// [`CoSimModel::new`] builds it, read for the start values (the instance's
/// own, before anything is set: FlexureStage's construction costs more than
/// the rendering).
pub fn cached_guid<M: CoSimModel>(start_model: &M) -> Result<String, String> {
    let id = TypeId::of::<M>();
    let known = |table: &GuidTable| {
        table
            .iter()
            .flatten()
            .find(|(model, _)| *model == id)
            .map(|(_, bytes)| String::from_utf8_lossy(bytes).into_owned())
    };
    if let Some(guid) = known(&GUIDS.lock().unwrap_or_else(|e| e.into_inner())) {
        return Ok(guid);
    }
    let guid = guid_with(start_model)?;
    let mut table = GUIDS.lock().unwrap_or_else(|e| e.into_inner());
    if let (Ok(bytes), None) = (<[u8; GUID_LEN]>::try_from(guid.as_bytes()), known(&table))
        && let Some(free) = table.iter_mut().find(|entry| entry.is_none())
    {
        *free = Some((id, bytes));
    }
    Ok(guid)
}

/// The complete `modelDescription.xml` of model `M`.
pub fn model_description<M: CoSimModel>() -> Result<String, String> {
    let start_model = M::new();
    render(&guid_with(&start_model)?, &start_model)
}

fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// An HTML table of every variable (name, causality, variability, unit, start,
/// range, description), for the FMU's `documentation/index.html`.
pub fn variables_html<M: CoSimModel>() -> String {
    let model = M::new();
    let mut html = String::from(
        "<table class=\"variables\">\n<thead><tr><th>name</th><th>vr</th><th>causality</th>\
         <th>variability</th><th>type</th><th>unit</th><th>start</th><th>range</th>\
         <th>description</th></tr></thead>\n<tbody>\n",
    );
    for (vr, var) in M::variables().iter().enumerate() {
        let unit_text = |unit: Option<&str>, display: Option<&str>| match (unit, display) {
            (Some(u), Some(d)) => format!("{u} (shown in {d})"),
            (Some(u), None) => u.to_owned(),
            _ => String::new(),
        };
        let (unit, range) = match &var.value {
            Value::Real(r) => {
                let unit = unit_text(r.unit, r.display_unit);
                let range = match (r.min, r.max) {
                    (None, None) => String::new(),
                    (min, max) => format!(
                        "[{}, {}]",
                        min.map_or("-inf".into(), format_real),
                        max.map_or("inf".into(), format_real)
                    ),
                };
                (unit, range)
            }
            Value::Integer(i) => {
                let range = match (i.min, i.max) {
                    (None, None) => String::new(),
                    (min, max) => format!(
                        "[{}, {}]",
                        min.map_or("-inf".into(), |v| v.to_string()),
                        max.map_or("inf".into(), |v| v.to_string())
                    ),
                };
                (String::new(), range)
            }
            Value::Time(t) => (unit_text(t.unit, t.display_unit), String::new()),
            Value::Boolean(_) | Value::String(_) => (String::new(), String::new()),
        };
        let start = match (&var.value, start_value(var, &model)) {
            // Quoted, so that an empty or blank String start shows.
            (Value::String(_), Some(text)) => format!("{text:?}"),
            (_, start) => start.unwrap_or_default(),
        };
        html.push_str(&format!(
            "<tr><td><code>{}</code></td><td>{vr}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td></tr>\n",
            html_escape(var.name),
            var.causality.as_str(),
            var.variability.as_str(),
            var.value.type_name(),
            html_escape(&unit),
            html_escape(&start),
            html_escape(&range),
            html_escape(var.description),
        ));
    }
    html.push_str("</tbody>\n</table>\n");
    html
}

#[cfg(test)]
mod tests {
    use super::format_real;

    #[test]
    fn reals_round_trip() {
        for x in [
            0.0,
            1.0,
            -0.1,
            1e-4,
            9.99e6,
            1e7,
            1e-20,
            123456.789,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
        ] {
            let text = format_real(x);
            assert_eq!(
                text.parse::<f64>().unwrap().to_bits(),
                x.to_bits(),
                "{x} -> {text}"
            );
        }
    }

    #[test]
    fn reals_are_readable() {
        assert_eq!(format_real(0.05), "0.05");
        assert_eq!(format_real(790.0), "790");
        assert_eq!(format_real(1.5e-5), "1.5e-5");
    }
}
