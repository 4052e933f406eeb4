//! Writing a run's time series.

use std::io::Write;
use std::path::Path;

use crate::master::Series;

/// Writes a result to `path` through `write`. A regular file, or one not
/// there yet, is written under a temporary name in its folder and renamed
/// into place when whole, so that a run stopped while writing (Ctrl-C, a
/// full disk) leaves no cut file under the name a reader takes as complete;
/// a link is followed, and its file replaced, not the link. Anything else
/// (`/dev/null`, a named pipe) is written straight through, as
/// `File::create` would: renaming onto it would replace the device.
pub fn write_result(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        write(&mut out)?;
        return out.flush();
    }
    let target = path.canonicalize().unwrap_or_else(|_| path.to_owned());
    let folder = match target.parent() {
        Some(f) if !f.as_os_str().is_empty() => f,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".piezo-cosim-");
    // The permissions a plain `File::create` gives (the umask applies), not
    // a temporary file's owner-only ones.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut out = std::io::BufWriter::new(builder.tempfile_in(folder)?);
    write(&mut out)?;
    let file = out.into_inner().map_err(|e| e.into_error())?;
    file.persist(&target).map_err(|e| e.error)?;
    Ok(())
}

/// Writes `series` as CSV: a header `t,<instance.variable>,...` and one row
/// per communication point, every number in the shortest form that reads
/// back to the same double.
pub fn write_csv(series: &Series, path: &Path) -> Result<(), String> {
    write_result(path, |out| {
        let mut header = String::from("t");
        for name in &series.names {
            header.push(',');
            header.push_str(name);
        }
        writeln!(out, "{header}")?;
        let mut line = String::new();
        for (k, t) in series.t.iter().enumerate() {
            line.clear();
            line.push_str(&t.to_string());
            for column in &series.columns {
                line.push(',');
                line.push_str(&column[k].to_string());
            }
            writeln!(out, "{line}")?;
        }
        Ok(())
    })
    .map_err(|e| format!("{}: {e}", path.display()))
}
