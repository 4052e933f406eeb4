//! The workspace's FMU binaries as their tests load them: the cdylib of an FMU
//! crate (refused when older than what it is built from, see
//! [`cdylib_path`](crate::cdylib_path)) with its modelDescription, either
//! rendered from the crate's variable table or as committed.

use std::path::{Path, PathBuf};

use fmi2_cosim::CoSimModel;
use fmi2_cosim::model_description::model_description;

use crate::{Fmu, cdylib_path};

/// The workspace root (fmi2-conformance is one of its members).
pub fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The committed modelDescription of `model_identifier`
/// (`modelDescription/<id>.xml`).
pub fn committed_description_path(model_identifier: &str) -> PathBuf {
    root().join(format!("modelDescription/{model_identifier}.xml"))
}

/// The binary of FMU crate `package` (e.g. `"fmu-plant"`) with the description
/// its model `M` renders: what the crate's own tests check.
pub fn load<M: CoSimModel>(package: &str) -> Fmu {
    let description = model_description::<M>()
        .unwrap_or_else(|e| panic!("{package}: the description renders: {e}"));
    Fmu::load(&cdylib_path(package), &description)
}

/// The binary of FMU crate `package` with its committed description: another
/// crate's FMU, whose own tests keep that file current.
pub fn load_committed(package: &str, model_identifier: &str) -> Fmu {
    let path = committed_description_path(model_identifier);
    let description =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    Fmu::load(&cdylib_path(package), &description)
}
