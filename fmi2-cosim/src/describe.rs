//! Writes the files of an FMU that come from the model's description:
//! `modelDescription.xml` and `documentation/index.html`.

use std::fs;
use std::io;
use std::path::Path;

use crate::model::CoSimModel;
use crate::model_description::{guid, model_description, start_text, variables_html};

/// Fills a documentation template. Placeholders: `{{model_identifier}}`,
/// `{{version}}`, `{{guid}}`, `{{variables}}` (the table of every variable
/// with unit, start value and range, generated from the variable table) and
/// `{{start:NAME}}` (variable NAME's start value, so that prose quoting a
/// default never goes stale).
pub fn documentation_html<M: CoSimModel>(template: &str) -> Result<String, String> {
    let guid = guid::<M>()?;
    let mut html = template
        .replace("{{model_identifier}}", M::INFO.model_identifier)
        .replace("{{version}}", M::INFO.version)
        .replace("{{guid}}", &guid)
        .replace("{{variables}}", &variables_html::<M>());
    while let Some(at) = html.find("{{start:") {
        let rest = &html[at + "{{start:".len()..];
        let name = rest.find("}}").map(|end| &rest[..end]).ok_or_else(|| {
            "an unclosed {{start: placeholder in the documentation template".to_owned()
        })?;
        let value = start_text::<M>(name).ok_or_else(|| {
            format!("{{{{start:{name}}}}} in the documentation template: no variable {name} with a start value")
        })?;
        html.replace_range(at..at + "{{start:".len() + name.len() + 2, &value);
    }
    if let Some(start) = html.find("{{") {
        let end = html[start..]
            .find("}}")
            .map_or(html.len(), |e| start + e + 2);
        return Err(format!(
            "unknown placeholder {} in the documentation template",
            &html[start..end]
        ));
    }
    Ok(html)
}

/// Writes `dir/modelDescription.xml` and `dir/documentation/index.html`.
pub fn write_description_files<M: CoSimModel>(
    dir: &Path,
    documentation_template: &str,
) -> io::Result<()> {
    let invalid = |e: String| io::Error::new(io::ErrorKind::InvalidData, e);
    let xml = model_description::<M>().map_err(invalid)?;
    let html = documentation_html::<M>(documentation_template).map_err(invalid)?;
    fs::create_dir_all(dir.join("documentation"))?;
    fs::write(dir.join("modelDescription.xml"), xml)?;
    fs::write(dir.join("documentation").join("index.html"), html)?;
    Ok(())
}

/// `main` of a model's describe binary: `<binary> <output-dir>`.
pub fn main<M: CoSimModel>(documentation_template: &str) -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let program = args.first().map_or("describe", String::as_str);
    let [_, dir] = args.as_slice() else {
        eprintln!(
            "usage: {program} <output-dir>\n\nwrites <output-dir>/modelDescription.xml and \
             <output-dir>/documentation/index.html for {}",
            M::INFO.model_identifier
        );
        return std::process::ExitCode::from(2);
    };
    match write_description_files::<M>(Path::new(dir), documentation_template) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "{program}: cannot write the description of {} into {dir}: {e}",
                M::INFO.model_identifier
            );
            std::process::ExitCode::FAILURE
        }
    }
}
