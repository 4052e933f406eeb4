//! fmu-pack: assembles an FMI 2.0 FMU archive.
//!
//! ```text
//! fmu-pack --description build/FlexureStage \
//!          --binary target/release/libfmu_plant.so --platform linux64 \
//!          --out dist/FlexureStage.fmu
//! ```
//!
//! The description folder holds `modelDescription.xml` and `documentation/`
//! (written by the model's describe binary). The binary is stored as
//! `binaries/<platform>/<modelIdentifier>.<ext>`, with the identifier read from
//! the description, so the file name and `modelIdentifier` cannot disagree.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use quick_xml::Reader;
use quick_xml::events::Event;
use zip::write::SimpleFileOptions;

#[derive(Parser)]
#[command(version, about = "Assemble an FMI 2.0 co-simulation FMU archive")]
struct Args {
    /// Folder with modelDescription.xml and documentation/.
    #[arg(long)]
    description: PathBuf,
    /// Platform binary, added as binaries/<platform>/<modelIdentifier>.<ext>
    /// (repeat --binary/--platform for several platforms).
    #[arg(long, required = true)]
    binary: Vec<PathBuf>,
    /// FMI platform folder of each binary: linux64, win64, darwin64.
    #[arg(long, required = true)]
    platform: Vec<String>,
    /// Output .fmu file.
    #[arg(long)]
    out: PathBuf,
}

/// `modelIdentifier` of the `<CoSimulation>` element.
fn model_identifier(xml: &str, path: &Path) -> Result<String, String> {
    let mut reader = Reader::from_str(xml);
    loop {
        let event = reader.read_event().map_err(|e| {
            format!(
                "{}: byte {}: not well-formed XML: {e}",
                path.display(),
                reader.buffer_position()
            )
        })?;
        match event {
            Event::Start(e) | Event::Empty(e) if e.name().as_ref() == "CoSimulation" => {
                for attribute in e.attributes() {
                    let attribute = attribute.map_err(|e| format!("{}: {e}", path.display()))?;
                    if attribute.key.as_ref() == "modelIdentifier" {
                        let value = attribute
                            .normalized_value(quick_xml::XmlVersion::default())
                            .map_err(|e| format!("{}: {e}", path.display()))?;
                        return Ok(value.into_owned());
                    }
                }
                return Err(format!(
                    "{}: <CoSimulation> has no modelIdentifier",
                    path.display()
                ));
            }
            Event::Eof => {
                return Err(format!("{}: no <CoSimulation> element", path.display()));
            }
            _ => {}
        }
    }
}

fn extension(platform: &str) -> Result<&'static str, String> {
    match platform {
        "linux64" | "linux32" => Ok("so"),
        "win64" | "win32" => Ok("dll"),
        "darwin64" => Ok("dylib"),
        other => Err(format!(
            "unknown FMI platform {other:?} (linux64, win64, darwin64)"
        )),
    }
}

fn add_file(
    zip: &mut zip::ZipWriter<File>,
    name: &str,
    source: &Path,
    options: SimpleFileOptions,
) -> Result<(), String> {
    let bytes = fs::read(source).map_err(|e| format!("{}: {e}", source.display()))?;
    zip.start_file(name, options).map_err(|e| e.to_string())?;
    zip.write_all(&bytes).map_err(|e| e.to_string())
}

fn add_tree(
    zip: &mut zip::ZipWriter<File>,
    root: &Path,
    prefix: &str,
    options: SimpleFileOptions,
) -> Result<(), String> {
    let mut entries: Vec<_> = fs::read_dir(root)
        .map_err(|e| format!("{}: {e}", root.display()))?
        .collect::<io::Result<_>>()
        .map_err(|e| format!("{}: {e}", root.display()))?;
    // Sorted, so that the archive's layout does not depend on the file system.
    entries.sort_by_key(|e| e.file_name());
    for entry in entries {
        let name = format!("{prefix}{}", entry.file_name().to_string_lossy());
        let path = entry.path();
        if path.is_dir() {
            add_tree(zip, &path, &format!("{name}/"), options)?;
        } else {
            add_file(zip, &name, &path, options)?;
        }
    }
    Ok(())
}

fn pack(args: &Args) -> Result<(), String> {
    if args.binary.len() != args.platform.len() {
        return Err("give one --platform per --binary".into());
    }
    let description = args.description.join("modelDescription.xml");
    let xml =
        fs::read_to_string(&description).map_err(|e| format!("{}: {e}", description.display()))?;
    let identifier = model_identifier(&xml, &description)?;
    if let Some(parent) = args.out.parent() {
        fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    }
    let file = File::create(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    let mut zip = zip::ZipWriter::new(file);
    let options = SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        // A fixed time stamp: the same inputs give the same archive.
        .last_modified_time(zip::DateTime::default());
    add_file(&mut zip, "modelDescription.xml", &description, options)?;
    let documentation = args.description.join("documentation");
    if documentation.is_dir() {
        add_tree(&mut zip, &documentation, "documentation/", options)?;
    }
    let resources = args.description.join("resources");
    if resources.is_dir() {
        add_tree(&mut zip, &resources, "resources/", options)?;
    }
    for (binary, platform) in args.binary.iter().zip(&args.platform) {
        let name = format!("binaries/{platform}/{identifier}.{}", extension(platform)?);
        add_file(&mut zip, &name, binary, options.unix_permissions(0o755))?;
    }
    zip.finish().map_err(|e| e.to_string())?;
    Ok(())
}

fn main() -> ExitCode {
    let args = Args::parse();
    match pack(&args) {
        Ok(()) => {
            println!("wrote {}", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("fmu-pack: {e}");
            ExitCode::FAILURE
        }
    }
}
