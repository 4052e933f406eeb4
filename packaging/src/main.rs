//! fmu-pack: assembles an FMI 2.0 FMU archive.
//!
//! ```text
//! fmu-pack --description build/FlexureStage \
//!          --binary linux64=build/binaries/linux64/libfmu_plant.so \
//!          --binary win64=build/binaries/win64/fmu_plant.dll \
//!          --out dist/FlexureStage.fmu
//! ```
//!
//! The description folder holds `modelDescription.xml` and `documentation/`
//! (written by the model's describe binary): one description for every
//! platform. Each binary is stored as
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
    /// A platform binary as `<platform>=<path>` (platform: linux64, win64,
    /// darwin64), added as binaries/<platform>/<modelIdentifier>.<ext>;
    /// repeat for each platform.
    #[arg(long = "binary", required = true, value_parser = parse_binary)]
    binaries: Vec<PlatformBinary>,
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

#[derive(Clone, Debug)]
struct PlatformBinary {
    platform: String,
    path: PathBuf,
}

fn parse_binary(argument: &str) -> Result<PlatformBinary, String> {
    let (platform, path) = argument
        .split_once('=')
        .ok_or_else(|| format!("{argument:?}: expected <platform>=<path>"))?;
    extension(platform)?;
    if path.is_empty() {
        return Err(format!("{argument:?}: no path after '='"));
    }
    Ok(PlatformBinary {
        platform: platform.to_owned(),
        path: PathBuf::from(path),
    })
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
    for (i, binary) in args.binaries.iter().enumerate() {
        if args.binaries[..i]
            .iter()
            .any(|b| b.platform == binary.platform)
        {
            return Err(format!("two binaries for {}", binary.platform));
        }
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
    for binary in &args.binaries {
        let name = format!(
            "binaries/{}/{identifier}.{}",
            binary.platform,
            extension(&binary.platform)?
        );
        add_file(
            &mut zip,
            &name,
            &binary.path,
            options.unix_permissions(0o755),
        )?;
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

#[cfg(test)]
mod tests {
    use super::*;

    const DESCRIPTION: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="{0}">
  <CoSimulation modelIdentifier="Model"/>
</fmiModelDescription>
"#;

    /// A fresh folder below the system's temporary one, per test.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("fmu-pack-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(dir.join("description")).unwrap();
        fs::write(dir.join("description/modelDescription.xml"), DESCRIPTION).unwrap();
        dir
    }

    fn binary(argument: &str) -> PlatformBinary {
        parse_binary(argument).unwrap()
    }

    #[test]
    fn binaries_are_given_as_platform_equals_path() {
        let b = binary("win64=target/x.dll");
        assert_eq!(
            (b.platform.as_str(), b.path.as_path()),
            ("win64", Path::new("target/x.dll"))
        );
        assert!(
            parse_binary("target/x.dll")
                .unwrap_err()
                .contains("<platform>=<path>")
        );
        assert!(
            parse_binary("win65=x.dll")
                .unwrap_err()
                .contains("unknown FMI platform")
        );
        assert!(parse_binary("linux64=").unwrap_err().contains("no path"));
    }

    #[test]
    fn every_platform_binary_is_stored_under_the_model_identifier() {
        let dir = scratch("platforms");
        fs::write(dir.join("a.so"), b"linux").unwrap();
        fs::write(dir.join("a.dll"), b"windows").unwrap();
        let args = Args {
            description: dir.join("description"),
            binaries: vec![
                binary(&format!("linux64={}", dir.join("a.so").display())),
                binary(&format!("win64={}", dir.join("a.dll").display())),
            ],
            out: dir.join("Model.fmu"),
        };
        pack(&args).unwrap();
        let mut archive = zip::ZipArchive::new(File::open(&args.out).unwrap()).unwrap();
        for (name, content) in [
            ("binaries/linux64/Model.so", "linux"),
            ("binaries/win64/Model.dll", "windows"),
        ] {
            let mut text = String::new();
            io::Read::read_to_string(&mut archive.by_name(name).unwrap(), &mut text).unwrap();
            assert_eq!(text, content, "{name}");
        }
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn two_binaries_for_one_platform_are_refused() {
        let dir = scratch("duplicate");
        let args = Args {
            description: dir.join("description"),
            binaries: vec![binary("linux64=a.so"), binary("linux64=b.so")],
            out: dir.join("Model.fmu"),
        };
        assert_eq!(pack(&args).unwrap_err(), "two binaries for linux64");
        assert!(
            !args.out.exists(),
            "nothing is written for a refused command"
        );
        fs::remove_dir_all(&dir).unwrap();
    }
}
