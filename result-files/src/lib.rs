//! Where the project's command-line tools (`piezo-identify`, `piezo-cosim`)
//! write their results, checked before the work and written whole.
//!
//! A fit or a co-simulation may run for minutes; a result path that cannot
//! be written should fail before it, not after ([`check_destination`]), and
//! a path that names a file the run reads, or two outputs that name one
//! file, lose data ([`same_file`]). A result is written under a temporary
//! name beside its file and renamed into place when whole
//! ([`write_atomically`]), so that a run stopped while writing (Ctrl-C, a
//! full disk) leaves no cut file under the name a reader takes as complete.
//! Where a rename would change what the file is (another owner, other hard
//! links, a folder that takes no new file) the result is made in memory and
//! written in place, as `File::create` would: a failure of the disk in that
//! write can still cut it. Devices (`/dev/null`, a named pipe) are no files
//! to lose and are written straight through ([`is_device`]).

use std::io::Write;
use std::path::{Path, PathBuf};

/// Whether `path` exists and is neither a file nor a folder: `/dev/null`,
/// `/dev/stdout`, a named pipe (links are followed).
pub fn is_device(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// Whether two paths name one file, written yet or not: `./a.csv` and
/// `a.csv`, a link and its target. A device, named twice, is no file to
/// lose: never the same file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    if is_device(a) || is_device(b) {
        return false;
    }
    match (resolved(a), resolved(b)) {
        (Some(a), Some(b)) => a == b,
        _ => a == b,
    }
}

/// The absolute path a file has, or would have once written: its own where
/// it exists (links resolved), else its folder's with its name.
fn resolved(path: &Path) -> Option<PathBuf> {
    path.canonicalize().ok().or_else(|| {
        let folder = path.parent().filter(|f| !f.as_os_str().is_empty());
        let folder = folder.unwrap_or(Path::new(".")).canonicalize().ok()?;
        Some(folder.join(path.file_name()?))
    })
}

/// Why a result cannot be written where it was asked to be
/// ([`check_destination`]); the caller names the path (and the option).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Unwritable {
    #[error("is a folder; give the name of the file to write")]
    Folder,
    #[error("there is no folder {} to write it in", .0.display())]
    NoFolder(PathBuf),
    #[error("cannot be written: {0}")]
    Denied(String),
}

/// Whether a result can be written at `path`: a device; a file that exists
/// and can be written; or a new file in a folder that exists and takes new
/// files (tried with an empty temporary file, removed at once).
pub fn check_destination(path: &Path) -> Result<(), Unwritable> {
    if path.is_dir() {
        return Err(Unwritable::Folder);
    }
    if is_device(path) {
        return Ok(());
    }
    // The error's kind alone: a temporary file's name means nothing to the
    // user.
    let denied = |e: std::io::Error| Unwritable::Denied(e.kind().to_string());
    let target = link_target(path).map_err(denied)?;
    let folder = target.parent().filter(|f| !f.as_os_str().is_empty());
    if let Some(folder) = folder
        && !folder.is_dir()
    {
        return Err(Unwritable::NoFolder(folder.to_owned()));
    }
    if target.exists() {
        std::fs::OpenOptions::new()
            .write(true)
            .open(&target)
            .map_err(denied)?;
    } else {
        tempfile::Builder::new()
            .prefix(".partial-")
            .tempfile_in(folder.unwrap_or(Path::new(".")))
            .map_err(denied)?;
    }
    Ok(())
}

/// The file a path names once its links are followed, whether that file
/// exists yet or not (a dangling link names the file it will create); a
/// loop of links is an error, as for the kernel.
fn link_target(path: &Path) -> std::io::Result<PathBuf> {
    let mut target = path.to_owned();
    // The kernel's bound on a chain of links.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&target) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&target)?;
                target = if link.is_absolute() {
                    link
                } else {
                    target.parent().unwrap_or(Path::new("")).join(link)
                };
            }
            _ => return Ok(target),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{}: too many levels of links", path.display()),
    ))
}

/// Writes a result file whole or not at all (module comment): `write` fills
/// a temporary file beside the target, which is renamed over it once
/// written, with the permissions of the file it replaces (a new file gets
/// those `File::create` gives: 0o666 less the umask). Links are followed,
/// and the file they name is written, not the link, even one that does not
/// exist yet. An existing file must be writable, as for `File::create`.
/// Made in memory and written in place instead: a file with other hard
/// links (a rename would part it from them), one owned by another user (a
/// rename would make it the writer's), one in a folder that takes no new
/// file or whose rename the folder refuses (a sticky folder). A device is
/// written straight through.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    if is_device(path) {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        write(&mut out)?;
        return out.flush();
    }
    let target = link_target(path)?;
    let existing = std::fs::metadata(&target).ok();
    if existing.is_some() {
        // Write protection holds, as File::create would honour it.
        std::fs::OpenOptions::new().write(true).open(&target)?;
    }
    let folder = match target.parent() {
        Some(f) if !f.as_os_str().is_empty() => f,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".partial-");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let temporary = match builder.tempfile_in(folder) {
        Ok(file) => file,
        Err(_) if existing.is_some() => return write_in_place(&target, write),
        Err(e) => return Err(e),
    };
    if let Some(existing) = &existing {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            let ours = temporary.as_file().metadata()?;
            if existing.nlink() > 1 || existing.uid() != ours.uid() {
                drop(temporary);
                return write_in_place(&target, write);
            }
        }
    }
    let mut out = std::io::BufWriter::new(temporary);
    write(&mut out)?;
    let file = out.into_inner().map_err(|e| e.into_error())?;
    if let Some(existing) = &existing {
        file.as_file().set_permissions(existing.permissions())?;
    }
    match file.persist(&target) {
        Ok(_) => Ok(()),
        // A sticky folder refuses to rename over another user's file that
        // the writer may still write.
        Err(e) if e.error.kind() == std::io::ErrorKind::PermissionDenied => {
            let mut bytes = Vec::new();
            let mut made = e.file.reopen()?;
            std::io::Read::read_to_end(&mut made, &mut bytes)?;
            drop(e.file);
            std::fs::write(&target, bytes)
        }
        Err(e) => Err(e.error),
    }
}

/// The result made in memory, then written over the file: a failure of
/// `write` leaves the file as it was.
fn write_in_place(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut bytes = Vec::new();
    write(&mut bytes)?;
    std::fs::write(path, bytes)
}

/// [`write_atomically`] of bytes already made.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomically(path, |out| out.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn one_file_by_two_names_and_devices_never() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.csv");
        std::fs::write(&a, "x").unwrap();
        let dotted = dir.path().join(".").join("a.csv");
        assert!(same_file(&a, &dotted));
        // Not written yet: by its folder and name.
        let new = dir.path().join("new.json");
        assert!(same_file(&new, &dir.path().join(".").join("new.json")));
        assert!(!same_file(&a, &new));
        #[cfg(unix)]
        {
            let link = dir.path().join("link.csv");
            std::os::unix::fs::symlink(&a, &link).unwrap();
            assert!(same_file(&a, &link));
        }
        let null = Path::new("/dev/null");
        if null.exists() {
            assert!(is_device(null));
            assert!(!same_file(null, null));
            assert!(!is_device(&a) && !is_device(dir.path()));
        }
    }

    #[test]
    fn a_destination_needs_a_folder_and_is_not_one() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(check_destination(dir.path()), Err(Unwritable::Folder));
        let missing = dir.path().join("missing");
        assert_eq!(
            check_destination(&missing.join("out.csv")),
            Err(Unwritable::NoFolder(missing.clone()))
        );
        assert_eq!(
            Unwritable::NoFolder(missing.clone()).to_string(),
            format!("there is no folder {} to write it in", missing.display())
        );
        assert_eq!(check_destination(&dir.path().join("out.csv")), Ok(()));
        assert_eq!(check_destination(Path::new("out.csv")), Ok(()));
    }

    #[test]
    fn a_result_is_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("result.csv");
        std::fs::write(&path, "old\n").unwrap();
        // A write that fails half-way leaves the old file and no other.
        let failed = write_atomically(&path, |out| {
            out.write_all(b"half")?;
            Err(std::io::Error::other("stopped"))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old\n");
        assert_eq!(names(dir.path()), ["result.csv"]);
        write_bytes(&path, b"new\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new\n");
        assert_eq!(names(dir.path()), ["result.csv"]);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            // The replaced file's permissions are kept.
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
            write_bytes(&path, b"newer\n").unwrap();
            assert_eq!(mode(&path), 0o600);
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
            write_bytes(&path, b"newest\n").unwrap();
            assert_eq!(mode(&path), 0o640);
            assert_eq!(std::fs::read_to_string(&path).unwrap(), "newest\n");
        }
    }

    #[cfg(unix)]
    #[test]
    fn links_are_followed_and_devices_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("file.csv");
        std::fs::write(&file, "old\n").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        write_bytes(&link, b"new\n").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "new\n");
        // A dangling link names the file it creates.
        let dangling = dir.path().join("dangling.csv");
        std::os::unix::fs::symlink("made.csv", &dangling).unwrap();
        assert_eq!(check_destination(&dangling), Ok(()));
        write_bytes(&dangling, b"made\n").unwrap();
        assert!(std::fs::symlink_metadata(&dangling).unwrap().is_symlink());
        assert_eq!(
            std::fs::read_to_string(dir.path().join("made.csv")).unwrap(),
            "made\n"
        );
        // A file with another hard link is written in place: both names
        // read the result.
        let other = dir.path().join("other.csv");
        std::fs::hard_link(&file, &other).unwrap();
        write_bytes(&file, b"both\n").unwrap();
        assert_eq!(std::fs::read_to_string(&other).unwrap(), "both\n");
        let null = Path::new("/dev/null");
        if null.exists() {
            write_bytes(null, b"nothing\n").unwrap();
            assert!(is_device(null));
            assert_eq!(check_destination(null), Ok(()));
        }
    }

    /// A loop of links is refused, the link kept; a write-protected file
    /// is refused as `File::create` refuses it (root may write it, as
    /// there); a file owned by another user is written in place and keeps
    /// its owner (shown where this test may give a file away: as root).
    #[cfg(unix)]
    #[test]
    fn loops_write_protection_and_owners() {
        use std::os::unix::fs::{MetadataExt, PermissionsExt};
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        assert!(matches!(check_destination(&a), Err(Unwritable::Denied(_))));
        assert!(write_bytes(&a, b"x").is_err());
        assert!(std::fs::symlink_metadata(&a).unwrap().is_symlink());
        let file = dir.path().join("kept.csv");
        std::fs::write(&file, "old\n").unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o444)).unwrap();
        let may_write = std::fs::OpenOptions::new().write(true).open(&file).is_ok();
        assert_eq!(write_bytes(&file, b"new\n").is_ok(), may_write);
        let expected = if may_write { "new\n" } else { "old\n" };
        assert_eq!(std::fs::read_to_string(&file).unwrap(), expected);
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o666)).unwrap();
        if std::os::unix::fs::chown(&file, Some(65534), None).is_ok() {
            write_bytes(&file, b"theirs\n").unwrap();
            assert_eq!(std::fs::metadata(&file).unwrap().uid(), 65534);
            assert_eq!(std::fs::read_to_string(&file).unwrap(), "theirs\n");
        }
    }

    /// A folder that takes no new file: an existing file in it is written
    /// in place, a new one is refused before the work. (Root writes
    /// anywhere; there the folder takes files and nothing is shown.)
    #[cfg(unix)]
    #[test]
    fn a_folder_that_takes_no_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("closed");
        std::fs::create_dir(&folder).unwrap();
        let existing = folder.join("result.csv");
        std::fs::write(&existing, "old\n").unwrap();
        std::fs::set_permissions(&folder, std::fs::Permissions::from_mode(0o555)).unwrap();
        let takes_files = tempfile::tempfile_in(&folder).is_ok();
        let new = folder.join("new.csv");
        if !takes_files {
            assert!(matches!(
                check_destination(&new),
                Err(Unwritable::Denied(_))
            ));
            assert_eq!(check_destination(&existing), Ok(()));
        }
        write_bytes(&existing, b"new\n").unwrap();
        assert_eq!(std::fs::read_to_string(&existing).unwrap(), "new\n");
        std::fs::set_permissions(&folder, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
}
