//! Writing a run's time series.

use std::path::Path;

use crate::master::Series;

/// Writes `series` as CSV: a header `t[s],<instance.variable>[unit],...`
/// (a column's unit as its FMU declares it, in brackets as a reference
/// table's header takes it; none where the FMU declares none) and one row
/// per communication point, every number in the shortest form that reads
/// back to the same double.
pub fn write_csv(series: &Series, path: &Path) -> Result<(), String> {
    result_files::write_atomically(path, |out| {
        let mut header = String::from("t[s]");
        for (name, unit) in series.names.iter().zip(&series.units) {
            header.push(',');
            header.push_str(name);
            if let Some(unit) = unit {
                header.push_str(&format!("[{unit}]"));
            }
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
