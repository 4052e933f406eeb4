//! Writing a run's time series.

use std::io::Write;
use std::path::Path;

use crate::master::Series;

/// A new file in `path`'s folder, to be persisted as `path` once written
/// whole; created with the permissions a plain `File::create` gives (the
/// umask applies), not a temporary file's owner-only ones.
pub fn temporary_beside(path: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let folder = match path.parent() {
        Some(f) if !f.as_os_str().is_empty() => f,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".piezo-cosim-");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(folder)
}

/// Writes `series` as CSV: a header `t,<instance.variable>,...` and one row
/// per communication point, every number in the shortest form that reads
/// back to the same double.
pub fn write_csv(series: &Series, path: &Path) -> Result<(), String> {
    let fail = |e: std::io::Error| format!("{}: {e}", path.display());
    // Written under a temporary name in the same folder and renamed into
    // place when whole: a run stopped while writing (Ctrl-C, a full disk)
    // leaves no cut table under the name a reader takes as complete.
    let file = temporary_beside(path).map_err(fail)?;
    let mut out = std::io::BufWriter::new(file);
    let mut header = String::from("t");
    for name in &series.names {
        header.push(',');
        header.push_str(name);
    }
    writeln!(out, "{header}").map_err(fail)?;
    let mut line = String::new();
    for (k, t) in series.t.iter().enumerate() {
        line.clear();
        line.push_str(&t.to_string());
        for column in &series.columns {
            line.push(',');
            line.push_str(&column[k].to_string());
        }
        writeln!(out, "{line}").map_err(fail)?;
    }
    let file = out.into_inner().map_err(|e| fail(e.into_error()))?;
    file.persist(path).map_err(|e| fail(e.error))?;
    Ok(())
}
