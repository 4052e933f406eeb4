//! Opening an FMU as a user hands it over: a `.fmu` archive, or the folder it
//! was unpacked into (fmpy's `extract`, a master's cache).
//!
//! From an archive only what an importer needs is unpacked, into a temporary
//! folder that lives as long as the [`FmuArchive`]: `modelDescription.xml`,
//! this platform's binary (`binaries/<platform>/<modelIdentifier>.<so|dll>`,
//! FMI 2.0.4 §2.3) and `resources/`, whose `file:` URI is handed to
//! `fmi2Instantiate` as the resource location.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::{Fmu, Instance, LogRecord};

/// The platform folder of `binaries/` this process loads from (FMI 2.0.4 §2.3).
pub fn platform_folder() -> &'static str {
    match (std::env::consts::OS, std::env::consts::ARCH) {
        ("linux", "x86_64") => "linux64",
        ("linux", _) => "linux32",
        ("windows", "x86_64") => "win64",
        ("windows", _) => "win32",
        ("macos", _) => "darwin64",
        _ => "unknown",
    }
}

/// Why an FMU could not be opened.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenError {
    /// The `.fmu` file or folder.
    pub path: PathBuf,
    pub problem: String,
}

impl std::fmt::Display for OpenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.problem)
    }
}

impl std::error::Error for OpenError {}

/// An FMU opened from its archive or folder, its binary loaded.
pub struct FmuArchive {
    /// The `.fmu` file or folder it was opened from.
    pub path: PathBuf,
    pub fmu: Fmu,
    /// `file:` URI of `resources/`, when the FMU has that folder.
    resource_location: Option<String>,
    /// Keeps the unpacked files (the loaded binary among them) while the FMU
    /// is in use; `None` when opened from a folder.
    _unpacked: Option<tempfile::TempDir>,
}

impl FmuArchive {
    /// Opens `path`: a `.fmu` (zip) file, or a folder with
    /// `modelDescription.xml` and `binaries/` in it.
    pub fn open(path: &Path) -> Result<FmuArchive, OpenError> {
        let fail = |problem: String| OpenError {
            path: path.to_owned(),
            problem,
        };
        let (root, unpacked) = if path.is_dir() {
            (path.to_owned(), None)
        } else {
            let unpacked = tempfile::Builder::new()
                .prefix("fmu-")
                .tempdir()
                .map_err(|e| fail(format!("cannot make a folder to unpack into: {e}")))?;
            unpack(path, unpacked.path()).map_err(fail)?;
            (unpacked.path().to_owned(), Some(unpacked))
        };
        let description = std::fs::read_to_string(root.join("modelDescription.xml"))
            .map_err(|e| fail(format!("modelDescription.xml: {e}")))?;
        let identifier = co_simulation_identifier(&description).map_err(fail)?;
        let library = root
            .join("binaries")
            .join(platform_folder())
            .join(format!("{identifier}{}", std::env::consts::DLL_SUFFIX));
        if !library.is_file() {
            return Err(fail(format!(
                "no binary for this platform: binaries/{}/{identifier}{} is missing",
                platform_folder(),
                std::env::consts::DLL_SUFFIX
            )));
        }
        let fmu = Fmu::try_load(&library, &description).map_err(fail)?;
        let resources = root.join("resources");
        let resource_location = if resources.is_dir() {
            let absolute = resources
                .canonicalize()
                .map_err(|e| fail(format!("resources/: {e}")))?;
            url::Url::from_directory_path(&absolute)
                .map(String::from)
                .ok()
        } else {
            None
        };
        Ok(FmuArchive {
            path: path.to_owned(),
            fmu,
            resource_location,
            _unpacked: unpacked,
        })
    }

    /// The `file:` URI of `resources/` passed to `fmi2Instantiate`.
    pub fn resource_location(&self) -> Option<&str> {
        self.resource_location.as_deref()
    }

    /// A co-simulation instance with this FMU's GUID and resource location;
    /// `Err` carries the log when the FMU refused.
    pub fn instantiate(
        &self,
        name: &str,
        logging_on: bool,
    ) -> Result<Instance<'_>, Vec<LogRecord>> {
        self.fmu
            .try_instantiate(name, &self.fmu.guid, self.resource_location(), logging_on)
    }
}

/// The `modelIdentifier` of the `<CoSimulation>` element.
fn co_simulation_identifier(description: &str) -> Result<String, String> {
    use fmi_schema::traits::FmiModelDescription;
    let parsed = fmi_schema::fmi2::Fmi2ModelDescription::deserialize(description)
        .map_err(|e| format!("modelDescription.xml does not parse: {e}"))?;
    parsed
        .co_simulation
        .map(|c| c.model_identifier)
        .ok_or_else(|| "not a co-simulation FMU (no <CoSimulation> element)".to_owned())
}

/// Unpacks modelDescription.xml, this platform's binaries and resources/.
fn unpack(archive: &Path, into: &Path) -> Result<(), String> {
    let file = std::fs::File::open(archive).map_err(|e| e.to_string())?;
    let mut zip =
        zip::ZipArchive::new(file).map_err(|e| format!("not an FMU (zip) archive: {e}"))?;
    let binaries = format!("binaries/{}/", platform_folder());
    for index in 0..zip.len() {
        let mut entry = zip
            .by_index(index)
            .map_err(|e| format!("entry {index}: {e}"))?;
        let name = entry
            .name()
            .map_err(|e| format!("entry {index}: {e}"))?
            .into_owned();
        let wanted = name == "modelDescription.xml"
            || name.starts_with(&binaries)
            || name.starts_with("resources/");
        if !wanted {
            continue;
        }
        // enclosed_name refuses absolute paths and `..` (a zip-slip archive).
        let relative = entry
            .enclosed_name()
            .ok_or_else(|| format!("{name}: unsafe path in the archive"))?;
        let target = into.join(relative);
        if entry.is_dir() {
            std::fs::create_dir_all(&target).map_err(|e| format!("{name}: {e}"))?;
            continue;
        }
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{name}: {e}"))?;
        }
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| format!("{name}: {e}"))?;
        std::fs::write(&target, bytes).map_err(|e| format!("{name}: {e}"))?;
    }
    if !into.join("modelDescription.xml").is_file() {
        return Err("no modelDescription.xml in the archive".to_owned());
    }
    Ok(())
}
