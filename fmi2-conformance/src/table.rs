//! Checks that tie a model's variable table (the one source of truth) to the
//! modelDescription.xml generated from it and committed beside the code. They
//! are generic over the model; an FMU crate runs them all with
//! [`table_tests!`](crate::table_tests).
//!
//! Unlike the ABI checks in [`checks`](crate::checks), these know the layer
//! (`fmi2-cosim`): their point is to compare its table with what an importer
//! parses (fmi-schema).

use fmi_schema::fmi2::{Causality, Fmi2ModelDescription, ScalarVariableElement};
use fmi_schema::traits::FmiModelDescription;
use fmi2_cosim::CoSimModel;
use fmi2_cosim::Variable;
use fmi2_cosim::model_description::{
    description_without_guid, guid, guid_of_description, model_description,
};
use fmi2_cosim::variables::{Causality as TableCausality, Value};

fn generated<M: CoSimModel>() -> String {
    model_description::<M>().expect("the description renders")
}

/// The committed `modelDescription/<id>.xml` equals a fresh generation.
pub fn committed_description_is_current<M: CoSimModel>(committed_path: &str) {
    let committed = std::fs::read_to_string(committed_path)
        .unwrap_or_else(|e| panic!("{committed_path}: {e}; run `make model-descriptions`"));
    assert!(
        committed == generated::<M>(),
        "{committed_path} differs from the variable table of {}; run `make model-descriptions` \
         and commit the result",
        M::INFO.model_identifier
    );
}

/// The GUID appears in the XML and tracks the interface: it is the hash of
/// the description, and the same description with one value reference moved
/// hashes to another GUID. (That it is the same across builds and machines is
/// `committed_description_is_current`: the committed XML carries it.)
pub fn guid_is_deterministic<M: CoSimModel>() {
    let first = guid::<M>().unwrap();
    assert_eq!(first.len(), 38, "{{8-4-4-4-12}} with braces");
    assert!(generated::<M>().contains(&format!("guid=\"{first}\"")));
    let description = description_without_guid::<M>().unwrap();
    assert_eq!(guid_of_description(&description), first);
    let moved = description.replacen("valueReference=\"0\"", "valueReference=\"4294967295\"", 1);
    assert_ne!(
        moved, description,
        "the description has a value reference 0"
    );
    assert_ne!(
        guid_of_description(&moved),
        first,
        "a moved value reference must change the GUID"
    );
}

/// fmi-schema parses the XML, and every variable agrees with the table: name,
/// value reference, causality, type and start value (read from the model the
/// binary starts with).
pub fn parsed_description_matches_the_table<M: CoSimModel>() {
    let md = Fmi2ModelDescription::deserialize(&generated::<M>()).expect("fmi-schema parses it");
    let table = M::variables();
    assert_eq!(md.model_variables.variables.len(), table.len());
    let model = M::new();
    for (vr, (parsed, var)) in md.model_variables.variables.iter().zip(table).enumerate() {
        assert_eq!(parsed.name, var.name);
        assert_eq!(parsed.value_reference as usize, vr, "{}", var.name);
        let causality = match var.causality {
            TableCausality::Parameter => Causality::Parameter,
            TableCausality::CalculatedParameter => Causality::CalculatedParameter,
            TableCausality::Input => Causality::Input,
            TableCausality::Output => Causality::Output,
            TableCausality::Local => Causality::Local,
            TableCausality::Independent => Causality::Independent,
        };
        assert_eq!(parsed.causality, causality, "{}", var.name);
        assert_eq!(
            parsed
                .variability
                .as_ref()
                .map(ToString::to_string)
                .as_deref(),
            Some(var.variability.as_str()),
            "variability of {}",
            var.name
        );
        assert_eq!(
            parsed.initial.as_ref().map(ToString::to_string).as_deref(),
            var.initial().map(|i| i.as_str()),
            "initial of {}",
            var.name
        );
        match (&parsed.elem, &var.value) {
            (ScalarVariableElement::Real(r), Value::Real(v)) => {
                if var.has_start() {
                    assert_eq!(r.start, Some((v.get)(&model)), "start of {}", var.name);
                } else {
                    assert_eq!(r.start, None, "{} has no start", var.name);
                }
            }
            (ScalarVariableElement::Real(r), Value::Time(_)) => {
                assert_eq!(r.start, None, "the independent {} has no start", var.name);
            }
            (ScalarVariableElement::Integer(i), Value::Integer(v)) => {
                let start = var.has_start().then(|| (v.get)(&model));
                assert_eq!(i.start, start, "start of {}", var.name);
            }
            (ScalarVariableElement::Boolean(b), Value::Boolean(v)) => {
                let start = var.has_start().then(|| (v.get)(&model));
                assert_eq!(b.start, start, "start of {}", var.name);
            }
            // fmi-schema keeps no attribute of a String element: its start
            // is compared as the importer reads it (`string_starts`).
            (ScalarVariableElement::String, Value::String(_)) => {}
            (parsed, _) => panic!("{}: type {parsed:?} differs from the table", var.name),
        }
    }
    let starts = crate::string_starts(&generated::<M>()).expect("the description reads");
    for (var, start) in table.iter().zip(starts) {
        let expected = match &var.value {
            Value::String(s) if var.has_start() => Some((s.get)(&model).to_owned()),
            _ => None,
        };
        assert_eq!(start, expected, "String start of {}", var.name);
    }
}

/// The `derivative` attributes the XML carries are the table's state
/// derivatives, pointing at their states; `<ModelExchange>` is there exactly
/// when the model declares it, with `numberOfEventIndicators` as declared.
pub fn derivatives_match_the_table<M: CoSimModel>() {
    let md = Fmi2ModelDescription::deserialize(&generated::<M>()).expect("fmi-schema parses it");
    let table = M::variables();
    for (parsed, var) in md.model_variables.variables.iter().zip(table) {
        let parsed_state = match &parsed.elem {
            ScalarVariableElement::Real(r) => r.derivative,
            _ => None,
        };
        let table_state = var.derivative_of.map(|state| {
            table
                .iter()
                .position(|v| v.name == state)
                .expect("checked by the layer") as u32
                + 1
        });
        assert_eq!(
            parsed_state, table_state,
            "derivative attribute of {}",
            var.name
        );
    }
    let derivatives = table.iter().filter(|v| v.derivative_of.is_some()).count();
    assert_eq!(md.model_structure.derivatives.unknowns.len(), derivatives);
    assert_eq!(md.model_exchange.is_some(), M::MODEL_EXCHANGE.is_some());
    assert_eq!(
        md.number_of_event_indicators.unwrap_or(0) as usize,
        M::MODEL_EXCHANGE.map_or(0, |me| me.number_of_event_indicators)
    );
}

/// Inputs and outputs have flat names: a '.' in a port name becomes a bus in
/// Simulink, and '[' an array in some importers.
pub fn ports_have_flat_names<M: CoSimModel>() {
    for var in M::variables() {
        if matches!(
            var.causality,
            TableCausality::Input | TableCausality::Output
        ) {
            assert!(
                !var.name.contains('.') && !var.name.contains('['),
                "port {} is not flat",
                var.name
            );
        }
    }
}

/// How a structured name uses a group: `a[1]` as an array, `a.b` as a
/// record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Group {
    Array,
    Record,
}

/// The groups a structured name belongs to, outermost first: `a.b[2].c`
/// gives `a` (a record), `a.b` (an array) and `a.b[2]` (a record). Dots and
/// brackets inside a quoted identifier (`'x.y'`, with FMI's escapes such as
/// `\'`) or an index do not split.
fn enclosing_groups(name: &str) -> Vec<(&str, Group)> {
    let mut groups = Vec::new();
    let (mut quoted, mut escaped, mut depth) = (false, false, 0usize);
    for (at, character) in name.char_indices() {
        if escaped {
            escaped = false;
            continue;
        }
        match character {
            '\\' if quoted => escaped = true,
            '\'' => quoted = !quoted,
            _ if quoted => {}
            '[' => {
                if depth == 0 {
                    groups.push((&name[..at], Group::Array));
                }
                depth += 1;
            }
            ']' => {
                depth = depth.saturating_sub(1);
                if depth == 0 && name[at + 1..].starts_with('.') {
                    groups.push((&name[..=at], Group::Record));
                }
            }
            '.' if depth == 0 && !name[..at].ends_with(']') => {
                groups.push((&name[..at], Group::Record));
            }
            _ => {}
        }
    }
    groups
}

/// Under `variableNamingConvention="structured"` the names form a tree: no
/// variable is also a group of others (`d` beside `d.k[1]`, or `v` beside
/// `v[1]`), and no group is both an array and a record (`a[1]` beside
/// `a.b`). Importers that build the tree (Simulink's structured parameters,
/// Modelica wrappers, tree views) have no place for a value on a branch nor
/// for a branch of two kinds. Derivatives, `der(...)`, are names of their
/// own and skipped.
pub fn structured_names_form_a_tree<M: CoSimModel>() {
    let names: Vec<&str> = M::variables().iter().map(|v| v.name).collect();
    let clashes = variables_on_branches(&names);
    assert!(clashes.is_empty(), "{}", clashes.join("\n"));
}

/// What keeps `names` from forming a tree, as messages: each name that is
/// also a group of another, and each group used as an array and a record.
fn variables_on_branches(names: &[&str]) -> Vec<String> {
    let all: std::collections::HashSet<&str> = names.iter().copied().collect();
    let mut kinds: std::collections::BTreeMap<&str, (Group, &str)> = Default::default();
    let mut clashes = Vec::new();
    for name in names.iter().filter(|name| !name.starts_with("der(")) {
        for (group, kind) in enclosing_groups(name) {
            if all.contains(group) {
                clashes.push(format!("`{group}` is a variable and the group of `{name}`"));
            }
            match kinds.get(group) {
                Some(&(first, by)) if first != kind => clashes.push(format!(
                    "`{group}` is an array in `{}` and a record in `{}`",
                    if first == Group::Array { by } else { name },
                    if first == Group::Array { name } else { by }
                )),
                Some(_) => {}
                None => {
                    kinds.insert(group, (kind, name));
                }
            }
        }
    }
    clashes
}

/// Every parameter records where the model keeps it (a serde path, as in
/// the JSON presets and the model's validation messages), and the path leads
/// there: the value at that path of the serialized model equals the
/// variable's start value.
pub fn every_parameter_has_a_model_path<M: CoSimModel>() {
    let model = M::new();
    let serialized = serde_json::to_value(&model).expect("the model serializes to JSON");
    // A path is relative to the model or to one of its fields (the FMUs keep
    // their parameters in a `params` struct, whose paths the presets use).
    let fields: Vec<&serde_json::Value> = match &serialized {
        serde_json::Value::Object(map) => {
            std::iter::once(&serialized).chain(map.values()).collect()
        }
        other => vec![other],
    };
    for var in M::variables() {
        if var.causality != TableCausality::Parameter {
            continue;
        }
        let path = var
            .model_path
            .unwrap_or_else(|| panic!("{} has no model path", var.name));
        assert!(
            !path.contains(' '),
            "{}: model path {path:?} has spaces",
            var.name
        );
        let start = match &var.value {
            Value::Real(r) => serde_json::json!((r.get)(&model)),
            Value::Integer(i) => serde_json::json!((i.get)(&model)),
            Value::Boolean(b) => serde_json::json!((b.get)(&model)),
            Value::String(s) => serde_json::json!((s.get)(&model)),
            Value::Time(_) => unreachable!("the independent variable is no parameter"),
        };
        let found: Vec<&serde_json::Value> = fields
            .iter()
            .filter_map(|field| at_path(field, path))
            .collect();
        assert!(
            !found.is_empty(),
            "{}: model path {path:?} leads nowhere in the serialized model",
            var.name
        );
        // An Integer parameter may select an enum, which serde writes by
        // its variant's name: the path leads there, the code is the FMU's.
        let selects_an_enum = matches!(var.value, Value::Integer(_));
        assert!(
            found
                .iter()
                .any(|v| same_value(v, &start) || (selects_an_enum && v.is_string())),
            "{}: model path {path:?} holds {found:?}, the variable starts at {start}",
            var.name
        );
    }
}

/// The value at a serde path such as `modes.damping` or `w_s[3]`.
fn at_path<'a>(value: &'a serde_json::Value, path: &str) -> Option<&'a serde_json::Value> {
    let mut here = value;
    for part in path.split('.') {
        let (key, indices) = match part.find('[') {
            Some(at) => (&part[..at], &part[at..]),
            None => (part, ""),
        };
        if !key.is_empty() {
            here = here.get(key)?;
        }
        for index in indices.split('[').filter(|s| !s.is_empty()) {
            here = here.get(index.trim_end_matches(']').parse::<usize>().ok()?)?;
        }
    }
    Some(here)
}

/// Numbers compared as numbers (an enum code may serialize as an integer),
/// anything else exactly.
fn same_value(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Asserts that each named port exists, is Real and has the unit given.
pub fn ports_have_units<M: CoSimModel>(ports: &[(&str, &str)]) {
    for (name, unit) in ports {
        let var = M::variables()
            .iter()
            .find(|v| v.name == *name)
            .unwrap_or_else(|| panic!("port {name} missing"));
        let Value::Real(r) = &var.value else {
            panic!("{name} is not Real")
        };
        assert_eq!(r.unit, Some(*unit), "unit of {name}");
    }
}

/// Asserts that every unit the model defines is some variable's unit:
/// PiezoController defined `um/urad` for D4's slope, which carried none.
pub fn every_defined_unit_is_used<M: CoSimModel>() {
    let used: Vec<&str> = M::variables()
        .iter()
        .filter_map(|v| match &v.value {
            Value::Real(r) => r.unit,
            Value::Time(t) => t.unit,
            _ => None,
        })
        .collect();
    let unused: Vec<&str> = M::UNITS
        .iter()
        .map(|u| u.name)
        .filter(|name| !used.contains(name))
        .collect();
    assert!(
        unused.is_empty(),
        "units defined but on no variable: {unused:?}"
    );
}

/// Checks a variable table against its committed record of value references
/// (`record`, each FMU crate's `valueReferences.txt`: lines
/// `<value reference> <name>`, `#` comments): every
/// recorded name still has its recorded reference, and every variable of the
/// table is recorded. Value references are append-only: a moved or removed
/// variable fails here, and a new variable fails until its line is appended
/// to the record (the message gives the lines). A released line never
/// changes; a name changes at its reference only by an appended line
/// `renamed <value reference> <old name> <new name>`, whose old name must be
/// the one the reference has at that point of the record. Importers that key
/// on references keep working; the line keeps the old name findable.
pub fn value_references_are_append_only<M>(variables: &[Variable<M>], record: &str) {
    let mut names: Vec<&str> = Vec::new();
    for (number, line) in record.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let words: Vec<&str> = line.split(' ').collect();
        match words.as_slice() {
            [vr, name] if vr.parse::<usize>().is_ok() => {
                assert_eq!(
                    vr.parse::<usize>().unwrap(),
                    names.len(),
                    "record line {}: references must run 0, 1, 2, ... in order",
                    number + 1
                );
                names.push(name);
            }
            ["renamed", vr, old, new] if vr.parse::<usize>().is_ok() => {
                let vr = vr.parse::<usize>().unwrap();
                let now = names.get(vr).unwrap_or_else(|| {
                    panic!(
                        "record line {}: reference {vr} is not recorded above",
                        number + 1
                    )
                });
                assert_eq!(
                    now,
                    old,
                    "record line {}: reference {vr} is named {now} at that point, not {old}",
                    number + 1
                );
                assert_ne!(
                    old,
                    new,
                    "record line {}: a rename to the same name",
                    number + 1
                );
                names[vr] = new;
            }
            _ => panic!(
                "record line {}: {line:?} is not `<value reference> <name>` or \
                 `renamed <value reference> <old name> <new name>`",
                number + 1
            ),
        }
    }
    let recorded = names.len();
    let mut changed = Vec::new();
    for (vr, name) in names.into_iter().enumerate() {
        match variables.iter().position(|v| v.name == name) {
            Some(now) if now == vr => {}
            Some(now) => changed.push(format!("{name}: {vr} in the record, {now} now")),
            None => changed.push(format!("{name} ({vr}) is no longer in the table")),
        }
    }
    assert!(
        changed.is_empty(),
        "value references are append-only (importers keep them), but:\n{}",
        changed.join("\n")
    );
    let unrecorded: Vec<String> = variables
        .iter()
        .enumerate()
        .skip(recorded)
        .map(|(vr, v)| format!("{vr} {}", v.name))
        .collect();
    assert!(
        unrecorded.is_empty(),
        "new variables: append their lines to the value-reference record:\n{}",
        unrecorded.join("\n")
    );
}

/// Defines one `#[test]` per table check for model type `$model`, whose
/// committed description is at `$committed` (a path literal).
#[macro_export]
macro_rules! table_tests {
    ($model:ty, $committed:expr) => {
        #[test]
        fn committed_model_description_is_current() {
            $crate::table::committed_description_is_current::<$model>($committed);
        }
        #[test]
        fn guid_is_deterministic_and_tracks_the_interface() {
            $crate::table::guid_is_deterministic::<$model>();
        }
        #[test]
        fn parsed_description_matches_the_table() {
            $crate::table::parsed_description_matches_the_table::<$model>();
        }
        #[test]
        fn derivatives_match_the_table() {
            $crate::table::derivatives_match_the_table::<$model>();
        }
        #[test]
        fn ports_have_flat_names() {
            $crate::table::ports_have_flat_names::<$model>();
        }
        #[test]
        fn structured_names_form_a_tree() {
            $crate::table::structured_names_form_a_tree::<$model>();
        }
        #[test]
        fn every_parameter_maps_to_its_preset_path() {
            $crate::table::every_parameter_has_a_model_path::<$model>();
        }
        #[test]
        fn every_defined_unit_is_used() {
            $crate::table::every_defined_unit_is_used::<$model>();
        }
    };
}

/// A parameter-set binary (`fmi2_cosim::parameter_set::main`) given its own
/// output back, a set by FMI name, says what the file is (the model's
/// identifier) and what the binary takes (`presets`), with exit 1 and no
/// file written, instead of serde's "unknown field" for the set's first
/// name; a file with one key the model lacks still gets serde's message.
pub fn a_set_by_fmi_name_is_named_as_such(
    binary: &str,
    preset: &str,
    model_identifier: &str,
    presets: &str,
) {
    let folder = std::env::temp_dir().join(format!(
        "parameter-sets-{model_identifier}-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&folder).unwrap();
    let run = |input: &std::path::Path, out: &std::path::Path| {
        let run = std::process::Command::new(binary)
            .arg(input)
            .arg(out)
            .output()
            .unwrap();
        (
            run.status.code(),
            String::from_utf8_lossy(&run.stderr).into_owned(),
        )
    };
    let by_name = folder.join("by_name.json");
    let written = std::process::Command::new(binary)
        .arg(preset)
        .arg(&by_name)
        .status()
        .unwrap();
    assert!(written.success(), "{binary} {preset} failed");
    let again = folder.join("again.json");
    let (code, stderr) = run(&by_name, &again);
    assert_eq!(code, Some(1), "{stderr}");
    for part in [
        "is already a parameter set by FMI name".to_owned(),
        format!("of {model_identifier}'s variables"),
        format!("This tool takes {presets}."),
    ] {
        assert!(stderr.contains(&part), "{part:?} not in {stderr}");
    }
    assert!(!again.exists());
    let text = std::fs::read_to_string(&by_name).unwrap();
    let mixed = folder.join("mixed.json");
    std::fs::write(&mixed, text.replacen('{', "{\"no_such_variable\": 1,", 1)).unwrap();
    let (code, stderr) = run(&mixed, &again);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("unknown field `no_such_variable`"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&folder).unwrap();
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Model(f64);

    const fn real(name: &'static str) -> Variable<Model> {
        Variable::real_local(name, "", "", |m: &Model| m.0)
    }

    const TABLE: [Variable<Model>; 3] = [real("a"), real("b"), real("c")];
    const RECORD: &str = "# a comment\n0 a\n1 b\n2 c\n";

    #[test]
    fn the_unchanged_table_passes() {
        value_references_are_append_only(&TABLE, RECORD);
    }

    #[test]
    #[should_panic(expected = "b: 1 in the record, 2 now")]
    fn an_insertion_fails() {
        value_references_are_append_only(&[real("a"), real("new"), real("b"), real("c")], RECORD);
    }

    #[test]
    #[should_panic(expected = "c (2) is no longer in the table")]
    fn a_rename_fails() {
        value_references_are_append_only(&[real("a"), real("b"), real("c2")], RECORD);
    }

    #[test]
    fn groups_of_structured_names() {
        let groups =
            |name| -> Vec<&str> { enclosing_groups(name).into_iter().map(|(g, _)| g).collect() };
        assert_eq!(groups("a"), Vec::<&str>::new());
        assert_eq!(groups("a.b[2].c"), ["a", "a.b", "a.b[2]"]);
        assert_eq!(
            enclosing_groups("a.b[2].c")
                .into_iter()
                .map(|(_, kind)| kind)
                .collect::<Vec<_>>(),
            [Group::Record, Group::Array, Group::Record]
        );
        assert_eq!(groups("v[1,2]"), ["v"]);
        assert_eq!(groups("'x.y'.z"), ["'x.y'"]);
        // FMI's escaped quote inside a quoted identifier does not end it.
        assert_eq!(groups("'it\\'s.a'.z"), ["'it\\'s.a'"]);
        assert_eq!(groups("m[i.j]"), ["m"]);
    }

    #[test]
    fn a_variable_on_a_branch_is_found() {
        assert!(variables_on_branches(&["d", "d_params.k[1]", "der(d)", "v[1]"]).is_empty());
        assert_eq!(
            variables_on_branches(&["d", "d.k[1]", "d.k[2]", "v", "v[1]"]),
            [
                "`d` is a variable and the group of `d.k[1]`",
                "`d` is a variable and the group of `d.k[2]`",
                "`v` is a variable and the group of `v[1]`",
            ]
        );
        assert_eq!(
            variables_on_branches(&["a[1]", "a.b"]),
            ["`a` is an array in `a[1]` and a record in `a.b`"]
        );
    }

    #[test]
    fn a_rename_recorded_at_its_reference_passes() {
        let record = format!("{RECORD}renamed 1 b b2\n");
        value_references_are_append_only(&[real("a"), real("b2"), real("c")], &record);
        // Renamed twice: each line starts from the name the one before left.
        let record = format!("{record}renamed 1 b2 b3\n");
        value_references_are_append_only(&[real("a"), real("b3"), real("c")], &record);
    }

    #[test]
    #[should_panic(expected = "reference 1 is named b at that point, not x")]
    fn a_rename_of_a_name_the_reference_does_not_have_fails() {
        let record = format!("{RECORD}renamed 1 x b2\n");
        value_references_are_append_only(&[real("a"), real("b2"), real("c")], &record);
    }

    #[test]
    #[should_panic(expected = "a rename to the same name")]
    fn a_rename_to_the_same_name_fails() {
        value_references_are_append_only(&TABLE, &format!("{RECORD}renamed 1 b b\n"));
    }

    #[test]
    #[should_panic(expected = "reference 7 is not recorded above")]
    fn a_rename_of_an_unrecorded_reference_fails() {
        value_references_are_append_only(&TABLE, &format!("{RECORD}renamed 7 g h\n"));
    }

    #[test]
    #[should_panic(expected = "is not `<value reference> <name>`")]
    fn a_malformed_line_fails() {
        value_references_are_append_only(&TABLE, "0 a\n1 b (was x)\n2 c\n");
    }

    #[test]
    #[should_panic(expected = "append their lines to the value-reference record:\n3 d")]
    fn an_unrecorded_appended_variable_fails_until_recorded() {
        let table = [real("a"), real("b"), real("c"), real("d")];
        value_references_are_append_only(&table, &format!("{RECORD}3 d\n"));
        value_references_are_append_only(&table, RECORD);
    }
}
