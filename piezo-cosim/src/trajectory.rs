//! Trajectories: the demands a run feeds to inputs, as data.
//!
//! A trajectory is a path `p(tau)`, `tau = t - start`, that is either a sum of
//! sines on an offset, `offset + sum_i a_i sin(2 pi f_i tau + phi_i)`, or a
//! table of samples read from a CSV file and interpolated linearly. Before
//! `start` the demand approaches the path's first value from zero by a raised
//! cosine over `approach` seconds and then holds it (the demo's approach from
//! rest; with `start = 0` the path starts at once).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// One input's demand over time.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Trajectory {
    /// Constant part of the path.
    #[serde(default)]
    pub offset: f64,
    /// Sines added to the offset.
    #[serde(default)]
    pub sines: Vec<Sine>,
    /// Samples of the path instead of offset and sines.
    #[serde(default)]
    pub table: Option<TableSource>,
    /// Time at which the path starts [s].
    #[serde(default)]
    pub start: f64,
    /// Duration of the raised-cosine approach from zero to the path's first
    /// value [s]; it then holds until `start`. 0: the first value is held
    /// from t = 0.
    #[serde(default)]
    pub approach: f64,
}

/// `amplitude * sin(2 pi frequency tau + phase)`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Sine {
    pub amplitude: f64,
    /// [Hz]
    pub frequency: f64,
    /// [rad]
    #[serde(default)]
    pub phase: f64,
}

/// A column of a CSV file with a time column (`t`, or `t[s]`, ...).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TableSource {
    pub file: PathBuf,
    /// The column's header, with or without a `[unit]` suffix, which is
    /// converted to the input's declared unit (or refused).
    pub column: String,
    /// The time column's header (default `t`).
    #[serde(default = "default_time_column")]
    pub time: String,
}

fn default_time_column() -> String {
    "t".to_owned()
}

/// The first and last times of a reference table's path [s].
pub type TableSpan = (f64, f64);

impl Trajectory {
    /// A constant demand.
    pub fn constant(value: f64) -> Trajectory {
        Trajectory {
            offset: value,
            ..Trajectory::default()
        }
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        let finite = |v: f64, what: &str| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{what} is {v}"))
            }
        };
        finite(self.offset, "offset")?;
        finite(self.start, "start")?;
        finite(self.approach, "approach")?;
        if self.start < 0.0 || self.approach < 0.0 {
            return Err("start and approach cannot be negative".to_owned());
        }
        if self.approach > self.start {
            return Err(format!(
                "the approach ({} s) must end by the start of the path ({} s)",
                self.approach, self.start
            ));
        }
        for sine in &self.sines {
            finite(sine.amplitude, "a sine's amplitude")?;
            finite(sine.frequency, "a sine's frequency")?;
            finite(sine.phase, "a sine's phase")?;
        }
        if self.table.is_some() && (self.offset != 0.0 || !self.sines.is_empty()) {
            return Err("a table replaces offset and sines; give one or the other".to_owned());
        }
        Ok(())
    }

    /// Evaluates the trajectory at `times` (ascending) for an input in
    /// `unit` (its declared unit, if any); reads the table file if there is
    /// one, converting a column whose header names another unit.
    pub fn sample(&self, times: &[f64], unit: Option<&str>) -> Result<Vec<f64>, String> {
        self.sample_to_end(times, unit).map(|(values, _)| values)
    }

    /// [`Self::sample`], and for a table the times its path starts and ends
    /// [s] (`start` plus its first and last samples' times), before and
    /// after which its first and last values hold.
    pub fn sample_to_end(
        &self,
        times: &[f64],
        unit: Option<&str>,
    ) -> Result<(Vec<f64>, Option<TableSpan>), String> {
        let table = match &self.table {
            Some(source) => Some(Table::read(source, unit)?),
            None => None,
        };
        let path = |tau: f64| match &table {
            Some(table) => table.at(tau),
            None => self.sines_at(tau),
        };
        let first = path(0.0);
        let values = times
            .iter()
            .map(|&t| {
                let tau = t - self.start;
                if tau >= 0.0 {
                    path(tau)
                } else {
                    self.blend(t) * first
                }
            })
            .collect();
        let span = table
            .as_ref()
            .and_then(|t| Some((*t.tau.first()?, *t.tau.last()?)))
            .map(|(first, last)| (self.start + first, self.start + last));
        Ok((values, span))
    }

    fn sines_at(&self, tau: f64) -> f64 {
        self.sines.iter().fold(self.offset, |sum, s| {
            sum + s.amplitude * (std::f64::consts::TAU * s.frequency * tau + s.phase).sin()
        })
    }

    /// The raised cosine from 0 to 1 over the approach, 1 after it.
    fn blend(&self, t: f64) -> f64 {
        if self.approach <= 0.0 {
            return 1.0;
        }
        let s = (t / self.approach).clamp(0.0, 1.0);
        0.5 * (1.0 - (std::f64::consts::PI * s).cos())
    }
}

/// Samples of a path: times from 0 (tau), ascending.
struct Table {
    tau: Vec<f64>,
    value: Vec<f64>,
}

/// Whether a CSV header names `wanted`, with or without a `[unit]` (`t[ms]`,
/// or `t [ms]` as spreadsheets write it).
fn header_matches(header: &str, wanted: &str) -> bool {
    let header = header.trim();
    header == wanted
        || header.strip_prefix(wanted).is_some_and(|rest| {
            let rest = rest.trim_start();
            rest.starts_with('[') && rest.ends_with(']')
        })
}

/// The unit in a header's brackets: `y[nm]` is in nm.
fn header_unit(header: &str) -> Option<&str> {
    let header = header.trim();
    let open = header.rfind('[')?;
    header
        .strip_suffix(']')
        .map(|h| h[open + 1..].trim())
        .filter(|u| !u.is_empty())
}

/// Seconds per unit of a time column.
fn seconds_per(unit: &str) -> Option<f64> {
    Some(match unit {
        "s" => 1.0,
        "ms" => 1e-3,
        "us" | "µs" | "μs" => 1e-6,
        "ns" => 1e-9,
        "min" => 60.0,
        _ => return None,
    })
}

/// A unit's quantity and its size in that quantity's base unit (µm, rad,
/// V): what a column in one unit is multiplied by to read in another.
fn unit_size(unit: &str) -> Option<(&'static str, f64)> {
    Some(match unit {
        "m" => ("length", 1e6),
        "mm" => ("length", 1e3),
        "um" | "µm" | "μm" => ("length", 1.0),
        "nm" => ("length", 1e-3),
        "rad" => ("angle", 1.0),
        "mrad" => ("angle", 1e-3),
        "urad" | "µrad" | "μrad" => ("angle", 1e-6),
        "deg" | "°" => ("angle", std::f64::consts::PI / 180.0),
        "mdeg" => ("angle", std::f64::consts::PI / 180.0e3),
        "V" => ("voltage", 1.0),
        "mV" => ("voltage", 1e-3),
        "kV" => ("voltage", 1e3),
        _ => return None,
    })
}

/// What a column written in `from` is multiplied by to be in `to`; None
/// when the two are not units of one quantity this reads.
fn conversion(from: &str, to: &str) -> Option<f64> {
    if from == to {
        return Some(1.0);
    }
    let (from_quantity, from_size) = unit_size(from)?;
    let (to_quantity, to_size) = unit_size(to)?;
    (from_quantity == to_quantity).then_some(from_size / to_size)
}

impl Table {
    fn read(source: &TableSource, unit: Option<&str>) -> Result<Table, String> {
        let name = |path: &Path| path.display().to_string();
        let text = std::fs::read_to_string(&source.file)
            .map_err(|e| format!("{}: {e}", name(&source.file)))?;
        // The reader skips blank lines and counts none of them, and a
        // record's position is where the reader stood before skipping them:
        // its line in the file is found from that byte, past the line ends.
        let line_at = |position: Option<&csv::Position>, counted: u64| {
            position.map_or(counted, |p| {
                let bytes = text.as_bytes();
                let mut start = (p.byte() as usize).min(bytes.len());
                while start < bytes.len() && matches!(bytes[start], b'\n' | b'\r') {
                    start += 1;
                }
                1 + bytes[..start].iter().filter(|b| **b == b'\n').count() as u64
            })
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let headers = reader
            .headers()
            .map_err(|e| format!("{}: {e}", name(&source.file)))?
            .clone();
        let find = |wanted: &str| {
            let matching: Vec<usize> = (0..headers.len())
                .filter(|&i| header_matches(&headers[i], wanted))
                .collect();
            match matching[..] {
                [one] => Ok(one),
                [] => Err(format!(
                    "{}: no column {wanted:?} (columns: {})",
                    name(&source.file),
                    headers.iter().collect::<Vec<_>>().join(", ")
                )),
                // `y[um]` and `y[nm]` both answer to `y`: the first was taken
                // without a word.
                _ => Err(format!(
                    "{}: {} columns answer to {wanted:?} ({}): name one with its unit",
                    name(&source.file),
                    matching.len(),
                    matching
                        .iter()
                        .map(|&i| &headers[i])
                        .collect::<Vec<_>>()
                        .join(", ")
                )),
            }
        };
        let (time_column, value_column) = (find(&source.time)?, find(&source.column)?);
        // A unit the header names is read, never dropped: a column in nm
        // or a time in ms taken as µm or s would run with exit 0.
        let time_factor = match header_unit(&headers[time_column]) {
            None => 1.0,
            Some(given) => seconds_per(given).ok_or_else(|| {
                format!(
                    "{}: time column {:?} is in {given:?}, not a time unit (s, ms, us, ns, min)",
                    name(&source.file),
                    &headers[time_column]
                )
            })?,
        };
        let value_factor = match (header_unit(&headers[value_column]), unit) {
            (None, _) => 1.0,
            (Some(given), Some(wanted)) => conversion(given, wanted).ok_or_else(|| {
                format!(
                    "{}: column {:?} is in {given:?}, which is not read as {wanted:?}, the \
                     input's unit (lengths m, mm, um, nm; angles rad, mrad, urad, deg, mdeg; \
                     voltages V, mV, kV)",
                    name(&source.file),
                    &headers[value_column]
                )
            })?,
            (Some(given), None) => {
                return Err(format!(
                    "{}: column {:?} is in {given:?}, and the input declares no unit to read \
                     it in: write the column's header without one",
                    name(&source.file),
                    &headers[value_column]
                ));
            }
        };
        let mut table = Table {
            tau: Vec::new(),
            value: Vec::new(),
        };
        for (row, record) in reader.records().enumerate() {
            let counted = row as u64 + 2;
            let record = record.map_err(|e| {
                let line = line_at(e.position(), counted);
                // The csv crate's own message carries its position, which
                // counts a CRLF file's lines otherwise ("line: 2" on line 3).
                let problem = match e.kind() {
                    csv::ErrorKind::UnequalLengths {
                        expected_len, len, ..
                    } => format!("{len} fields where the header has {expected_len}"),
                    _ => e.to_string(),
                };
                format!("{}:{line}: {problem}", name(&source.file))
            })?;
            let line = line_at(record.position(), counted);
            let number = |column: usize| -> Result<f64, String> {
                let text = record.get(column).unwrap_or("");
                // NaN and infinities parse, and would reach an FMU's
                // fmi2SetReal mid-run as its failure (exit 1): they are the
                // table's.
                text.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        format!(
                            "{}:{line}: column {:?}: {text:?} is not a finite number",
                            name(&source.file),
                            &headers[column]
                        )
                    })
            };
            let (t, v) = (
                number(time_column)? * time_factor,
                number(value_column)? * value_factor,
            );
            if table.tau.last().is_some_and(|&last| t <= last) {
                return Err(format!(
                    "{}:{line}: times must increase ({t} after {})",
                    name(&source.file),
                    table.tau.last().unwrap()
                ));
            }
            table.tau.push(t);
            table.value.push(v);
        }
        if table.tau.is_empty() {
            return Err(format!("{}: no samples", name(&source.file)));
        }
        Ok(table)
    }

    /// Linear interpolation; the end values hold outside the table.
    fn at(&self, tau: f64) -> f64 {
        let n = self.tau.len();
        if tau <= self.tau[0] {
            return self.value[0];
        }
        if tau >= self.tau[n - 1] {
            return self.value[n - 1];
        }
        // The first sample later than tau; 1 <= i < n.
        let i = self.tau.partition_point(|&x| x <= tau);
        let (t0, t1) = (self.tau[i - 1], self.tau[i]);
        let w = (tau - t0) / (t1 - t0);
        self.value[i - 1] + w * (self.value[i] - self.value[i - 1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn sine_up_from_bottom_starts_at_its_minimum() {
        let y = Trajectory {
            offset: 7.0,
            sines: vec![Sine {
                amplitude: 5.0,
                frequency: 1.0,
                phase: -FRAC_PI_2,
            }],
            ..Trajectory::default()
        };
        let v = y.sample(&[0.0, 0.25, 0.5], None).unwrap();
        assert!((v[0] - 2.0).abs() < 1e-12 && (v[1] - 7.0).abs() < 1e-12);
        assert!((v[2] - 12.0).abs() < 1e-12);
    }

    #[test]
    fn approach_is_a_raised_cosine_then_holds() {
        let x = Trajectory {
            offset: 8.0,
            start: 1.0,
            approach: 0.5,
            sines: vec![Sine {
                amplitude: 1.0,
                frequency: 1.0,
                phase: 0.0,
            }],
            ..Trajectory::default()
        };
        let v = x.sample(&[0.0, 0.25, 0.5, 0.75, 1.0, 1.25], None).unwrap();
        assert_eq!(v[0], 0.0);
        assert!((v[1] - 4.0).abs() < 1e-12, "{}", v[1]);
        assert_eq!(v[2], 8.0);
        assert_eq!(v[3], 8.0);
        assert_eq!(v[4], 8.0);
        assert!((v[5] - (8.0 + (PI / 2.0).sin())).abs() < 1e-12);
    }

    #[test]
    fn tables_interpolate_and_hold_their_ends() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("r.csv");
        std::fs::write(&file, "t[s],y_ref[um]\n0,0\n1,10\n2,30\n").unwrap();
        let y = Trajectory {
            table: Some(TableSource {
                file: file.clone(),
                column: "y_ref".into(),
                time: "t".into(),
            }),
            ..Trajectory::default()
        };
        let v = y.sample(&[0.0, 0.5, 1.0, 1.5, 3.0], Some("um")).unwrap();
        assert_eq!(v, vec![0.0, 5.0, 10.0, 20.0, 30.0]);
    }

    /// A unit in a header's brackets is read: times in ms, a length in nm,
    /// an angle in degrees come in the input's units; a unit that is no
    /// such is refused, never dropped (it used to be, with exit 0).
    #[test]
    fn a_tables_units_are_converted_to_the_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("r.csv");
        std::fs::write(
            &file,
            "t[ms],y[nm],theta[deg],v[furlong]\n0,0,0,0\n1000,5000,90,1\n",
        )
        .unwrap();
        let column = |column: &str| Trajectory {
            table: Some(TableSource {
                file: file.clone(),
                column: column.into(),
                time: "t".into(),
            }),
            ..Trajectory::default()
        };
        let y = column("y").sample(&[0.0, 0.5, 1.0], Some("um")).unwrap();
        assert_eq!(y, vec![0.0, 2.5, 5.0]);
        // A space before the brackets, as spreadsheets write a unit.
        let spaced = dir.path().join("spaced.csv");
        std::fs::write(&spaced, "t [ms],y [nm]\n0,0\n1000,5000\n").unwrap();
        let y = Trajectory {
            table: Some(TableSource {
                file: spaced,
                column: "y".into(),
                time: "t".into(),
            }),
            ..Trajectory::default()
        };
        assert_eq!(y.sample(&[0.5], Some("um")).unwrap(), vec![2.5]);
        let theta = column("theta").sample(&[1.0], Some("rad")).unwrap();
        assert!((theta[0] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        let e = column("y").sample(&[0.0], Some("rad")).unwrap_err();
        assert!(e.ends_with("column \"y[nm]\" is in \"nm\", which is not read as \"rad\", the input's unit (lengths m, mm, um, nm; angles rad, mrad, urad, deg, mdeg; voltages V, mV, kV)"), "{e}");
        let e = column("v").sample(&[0.0], Some("um")).unwrap_err();
        assert!(e.contains("is in \"furlong\""), "{e}");
        let e = column("y").sample(&[0.0], None).unwrap_err();
        assert!(e.contains("the input declares no unit"), "{e}");
        std::fs::write(&file, "t[h],y\n0,0\n1,1\n").unwrap();
        let e = column("y").sample(&[0.0], Some("um")).unwrap_err();
        assert!(
            e.contains("time column \"t[h]\" is in \"h\", not a time unit"),
            "{e}"
        );
    }

    #[test]
    fn a_bad_table_names_file_line_and_column() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("r.csv");
        std::fs::write(&file, "t,y\n0,0\n1,ten\n").unwrap();
        let y = Trajectory {
            table: Some(TableSource {
                file,
                column: "y".into(),
                time: "t".into(),
            }),
            ..Trajectory::default()
        };
        let e = y.sample(&[0.0], None).unwrap_err();
        assert!(
            e.ends_with("r.csv:3: column \"y\": \"ten\" is not a finite number"),
            "{e}"
        );
        // Blank lines count (the reader skips them), and NaN or an infinity
        // is refused at its line, not sent to an FMU.
        for (bad, text) in [
            ("nan", "t,y\n0,0\n\n\n1,nan\n"),
            ("inf", "t,y\n\n0,0\n1,1\n2,inf\n"),
        ] {
            std::fs::write(y.table.as_ref().unwrap().file.clone(), text).unwrap();
            let e = y.sample(&[0.0], None).unwrap_err();
            assert!(
                e.ends_with(&format!(
                    "r.csv:5: column \"y\": \"{bad}\" is not a finite number"
                )),
                "{e}"
            );
        }
        // Two columns that answer to one name are refused, not taken first.
        std::fs::write(
            y.table.as_ref().unwrap().file.clone(),
            "t[s],y[um],y[nm]\n0,0,0\n",
        )
        .unwrap();
        let e = y.sample(&[0.0], None).unwrap_err();
        assert!(
            e.ends_with("r.csv: 2 columns answer to \"y\" (y[um], y[nm]): name one with its unit"),
            "{e}"
        );
        // A row of another width is named by its line alone, which the csv
        // crate's own message counted otherwise in a CRLF file.
        for text in [
            "t,y\n0,0\n0.1,1,\n0.2,1\n",
            "t,y\r\n0,0\r\n0.1,1,\r\n0.2,1\r\n",
        ] {
            std::fs::write(y.table.as_ref().unwrap().file.clone(), text).unwrap();
            let e = y.sample(&[0.0], None).unwrap_err();
            assert!(
                e.ends_with("r.csv:3: 3 fields where the header has 2"),
                "{e}"
            );
        }
    }

    #[test]
    fn an_approach_past_the_start_is_refused() {
        let t = Trajectory {
            start: 0.5,
            approach: 1.0,
            ..Trajectory::default()
        };
        assert!(t.validate().is_err());
    }
}
