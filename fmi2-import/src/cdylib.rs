//! Where a workspace FMU crate's binary is, and whether it is current.
//!
//! `cargo test` rebuilds the rlib a test links, not the cdylib it loads with
//! dlopen, so a stale binary would be tested silently. What a binary is built
//! from is not written down by hand: it is the FMU crate's own directory and
//! those of its path dependencies, read from the `Cargo.toml` files (the
//! crate's and the workspace's `[workspace.dependencies]`), followed
//! transitively, so a dependency added to any of them is watched without
//! anyone remembering to.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The workspace this crate belongs to (the FMU crates are its members).
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("fmi2-import lives in the workspace")
        .to_owned()
}

fn read_manifest(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse()
        .unwrap_or_else(|e| panic!("{}: not a Cargo manifest: {e}", path.display()))
}

/// The directory of workspace member `package` (by its package name).
fn member_dir(root: &Path, workspace: &toml::Table, package: &str) -> PathBuf {
    let members = workspace
        .get("workspace")
        .and_then(|w| w.get("members"))
        .and_then(|m| m.as_array())
        .expect("the root Cargo.toml lists workspace.members");
    members
        .iter()
        .filter_map(|m| m.as_str())
        .map(|m| root.join(m))
        .find(|dir| {
            let manifest = read_manifest(&dir.join("Cargo.toml"));
            manifest
                .get("package")
                .and_then(|p| p.get("name"))
                .and_then(|n| n.as_str())
                == Some(package)
        })
        .unwrap_or_else(|| panic!("{package} is not a member of the workspace"))
}

/// The directories of the path dependencies (normal and build) of the crate in
/// `dir`; `workspace = true` entries resolve through the root manifest.
fn path_dependencies(root: &Path, workspace: &toml::Table, dir: &Path) -> Vec<PathBuf> {
    let manifest = read_manifest(&dir.join("Cargo.toml"));
    let shared = workspace
        .get("workspace")
        .and_then(|w| w.get("dependencies"))
        .and_then(|d| d.as_table());
    let mut found = Vec::new();
    // [dependencies], [build-dependencies] and their per-target forms: what
    // the library is compiled from (dev-dependencies are the tests').
    let mut tables: Vec<&toml::Table> = Vec::new();
    for key in ["dependencies", "build-dependencies"] {
        tables.extend(manifest.get(key).and_then(|t| t.as_table()));
        if let Some(targets) = manifest.get("target").and_then(|t| t.as_table()) {
            for target in targets.values() {
                tables.extend(target.get(key).and_then(|t| t.as_table()));
            }
        }
    }
    for (name, spec) in tables.into_iter().flatten() {
        if let Some(path) = spec.get("path").and_then(|p| p.as_str()) {
            found.push(dir.join(path));
        } else if spec.get("workspace").and_then(|w| w.as_bool()) == Some(true)
            && let Some(path) = shared
                .and_then(|s| s.get(name))
                .and_then(|s| s.get("path"))
                .and_then(|p| p.as_str())
        {
            found.push(root.join(path));
        }
    }
    found
}

/// The directories the cdylib of workspace member `package` is built from: its
/// own and those of its path dependencies, transitively.
pub fn cdylib_sources(package: &str) -> Vec<PathBuf> {
    let root = workspace_root();
    let workspace = read_manifest(&root.join("Cargo.toml"));
    let mut seen = BTreeSet::new();
    let mut pending = vec![member_dir(&root, &workspace, package)];
    while let Some(dir) = pending.pop() {
        let dir = dir.canonicalize().unwrap_or(dir);
        if seen.insert(dir.clone()) {
            pending.extend(path_dependencies(&root, &workspace, &dir));
        }
    }
    seen.into_iter().collect()
}

/// Path of the cdylib of workspace member `package` (e.g. `"fmu-plant"`) built
/// in the same target directory as the running test
/// (`target/<profile>/lib<name>.so`), refused when a source it is built from
/// ([`cdylib_sources`]) is newer than it.
pub fn cdylib_path(package: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows its path");
    // target/<profile>/deps/<test binary>, target/<profile>/examples/<example>
    // or target/<profile>/<binary>.
    let profile_dir = exe
        .ancestors()
        .skip(1)
        .find(|dir| {
            dir.file_name()
                .is_some_and(|n| n != "deps" && n != "examples")
        })
        .expect("binaries live in target/<profile>");
    let file = format!(
        "{}{}{}",
        std::env::consts::DLL_PREFIX,
        package.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    );
    let path = profile_dir.join(file);
    let built = std::fs::metadata(&path)
        .and_then(|m| m.modified())
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e}; build the cdylib first (cargo build -p {package})",
                path.display()
            )
        });
    for dir in cdylib_sources(package) {
        if let Some(newer) = newer_file(&dir, built) {
            panic!(
                "{} is older than {}: rebuild it (cargo build -p {package}) before running \
                 the ABI tests",
                path.display(),
                newer.display()
            );
        }
    }
    path
}

/// A source file under `dir` modified after `than`. The crate's tests,
/// benches and examples are not part of its library and are skipped.
fn newer_file(dir: &Path, than: SystemTime) -> Option<PathBuf> {
    let entries = std::fs::read_dir(dir).ok()?;
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            let name = entry.file_name();
            if ["tests", "benches", "examples", "target"]
                .iter()
                .any(|skip| name == *skip)
            {
                continue;
            }
            if let Some(found) = newer_file(&path, than) {
                return Some(found);
            }
        } else if path
            .extension()
            .is_some_and(|e| e == "rs" || e == "json" || e == "map")
            && entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|m| m > than)
        {
            return Some(path);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn relative(package: &str) -> Vec<String> {
        let root = workspace_root().canonicalize().unwrap();
        cdylib_sources(package)
            .iter()
            .map(|d| d.strip_prefix(&root).unwrap().display().to_string())
            .collect()
    }

    #[test]
    fn sources_follow_path_dependencies() {
        // fmu-plant depends on fmi2-cosim and piezo-models through
        // `workspace = true`; serde and the rest are not in the workspace.
        let plant = relative("fmu-plant");
        for dir in ["fmu-plant", "fmi2-cosim", "piezo-models"] {
            assert!(
                plant.iter().any(|d| d == dir),
                "{dir} missing from {plant:?}"
            );
        }
        assert!(!plant.iter().any(|d| d == "fmu-controller"), "{plant:?}");
        // Nothing depends on what depends on it.
        let layer = relative("fmi2-cosim");
        assert!(layer.iter().any(|d| d == "fmi2-cosim"), "{layer:?}");
        assert!(!layer.iter().any(|d| d.starts_with("fmu-")), "{layer:?}");
    }
}
