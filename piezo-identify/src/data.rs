//! Reading a numeric voltage/displacement record from a text file.
//!
//! The format is the common one of measurement exports: one sample per line,
//! columns separated by tabs, semicolons, commas or spaces ([`Separator`]
//! says how the file's first lines decide, unless an Excel `sep=;` line
//! states it), an optional header row of column names (with a separator
//! character, names may contain spaces, and a field in double quotes may
//! hold the separator), `#` starting a comment (whole line or trailing), `%`
//! starting a comment line (MATLAB, Octave) and blank lines ignored. A UTF-8
//! byte-order mark is dropped, UTF-16 with its mark is decoded, and a file
//! whose lines end in a lone CR is read by those. A column in m, mm or nm, or
//! in mV or kV, is read in µm or V ([`Conversion`]).
//! Options pick the input (voltage) and output (displacement) columns by
//! 0-based index or by header name, and give the sampling either as a time
//! column or as a sample rate. A header must have as many names as the rows
//! have fields: a header split differently from its rows would silently
//! shift every name onto another column.
//!
//! Every non-empty field of a data row must be a finite number, not only the
//! selected ones: a numeric export with a stray word or a NaN in any column
//! is more likely corrupt than intended, and refusing it early is cheaper
//! than a fit on garbage. Empty fields are accepted in columns that are not
//! read (a pandas export's unnamed index column, a trailing separator).
//!
//! A row of units right below the header (`s;V;um`, `(ms),(V)`: PicoScope,
//! LabVIEW and many DAQ exports write one) is read as such: a row of as many
//! fields as the header, each empty or unit-like ([`unit_like`]; a row of
//! typos or missing values is a bad data row). The time column's unit, from
//! that row or else from the end of its name (`Time (ms)`, `t [us]`,
//! `t/ms`, `time_ms`), scales it to seconds ([`seconds_per`]: h, min, s, ms,
//! us, µs, ns and their common spellings, in any case); a units row that gives the time
//! column another unit, or disagrees with its name, is refused, since the
//! rates and the sampling period would be off by that factor. The summary
//! names the units it read, and where the time unit came from.
//!
//! Exports made in a locale whose decimal mark is a comma (spreadsheets and
//! LabVIEW in much of Europe) separate their fields by semicolons, tabs or
//! spaces and write `-123,059`: in a file so separated, a field that is not a number as
//! written but is one with its single comma read as the decimal point (and
//! no point of its own) is read that way, and the summary says so
//! ([`ColumnsUsed::decimal_comma`]). One file has one decimal mark: a field
//! with a decimal comma in a file whose numbers have decimal points (or the
//! reverse) is refused, since `4,089` beside `0.005` is a thousands
//! separator, not a decimal. A comma-separated file has no decimal commas:
//! its commas are separators, and a headerless one whose whole numbers look
//! like decimal commas split by them is refused ([`SplitDecimalCommas`]).
//!
//! A time column may hold dates and times instead of numbers
//! ([`clock_time`]: ISO 8601 and its common spellings, or a time of day);
//! its times are then seconds from the first row's. A LabVIEW Measurement
//! file (`.lvm`) is read through its headers ([`Labview`]): its separator
//! and decimal mark, its `X_Value` column as the time in seconds, and its
//! `Delta_X` against a `--rate` given; one segment per file.
//! Errors name the file, the 1-based line and the problem (`file:line:
//! problem`).

use std::fmt;
use std::path::{Path, PathBuf};

/// Fewest data rows a record may have: more than the 31 parameters of the
/// largest model identified here (seed 000's proposed model and its 10 + 10
/// rival), so that even an unsampled fit is over-determined.
pub const MINIMUM_ROWS: usize = 32;

/// A number in messages, to 6 significant digits: `0.01` rather than the
/// `0.010000000000001563` a difference of two times prints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Short(pub f64);

impl fmt::Display for Short {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let value = self.0;
        if value == 0.0 || !value.is_finite() {
            return write!(f, "{value}");
        }
        let magnitude = value.abs().log10().floor() as i32;
        if (-4..6).contains(&magnitude) {
            let decimals = (5 - magnitude).max(0) as usize;
            let text = format!("{value:.decimals$}");
            let text = if text.contains('.') {
                text.trim_end_matches('0').trim_end_matches('.')
            } else {
                &text
            };
            write!(f, "{text}")
        } else {
            write!(f, "{value:.5e}")
        }
    }
}

/// Largest relative deviation of one time step from the usual (median) step
/// before the sampling counts as non-uniform (1 %): the hysteresis operators are
/// discrete-time (seed 000 eq. 1, sampling period T) and the rates are
/// backward differences, both of which assume one fixed period.
pub const UNIFORM_SAMPLING_TOLERANCE: f64 = 0.01;

/// A column chosen by 0-based index or by its name in the header row.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Column {
    Index(usize),
    Name(String),
    /// The one column whose header name says it is a time (`Time [s]`,
    /// `t_ms`, LabVIEW's `X_Value`): the sampling when none is given.
    NamedTime,
}

impl Column {
    /// Reads a command-line value: an unsigned integer is an index, anything
    /// else a header name.
    pub fn parse(text: &str) -> Column {
        match text.trim().parse::<usize>() {
            Ok(index) => Column::Index(index),
            Err(_) => Column::Name(text.trim().to_owned()),
        }
    }
}

impl fmt::Display for Column {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Column::Index(i) => write!(f, "{i}"),
            Column::Name(name) => write!(f, "\"{name}\""),
            Column::NamedTime => write!(f, "the column named as a time"),
        }
    }
}

/// How the samples are spaced in time.
#[derive(Clone, Debug, PartialEq)]
pub enum Sampling {
    /// A column of times [s]; must increase strictly and uniformly (within
    /// [`UNIFORM_SAMPLING_TOLERANCE`]).
    TimeColumn(Column),
    /// A fixed sample rate [Hz].
    Rate(f64),
    /// The spacing does not matter (a static fit, such as a decoupling
    /// compensation): the record's sample period is 1 s by convention. A time
    /// column, if named, is only skipped by the defaulted columns and must
    /// increase strictly; its spacing is not checked.
    Unspaced { time: Option<Column> },
}

/// Which columns to read and how the samples are spaced.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadOptions {
    /// The actuator command [V]; None: by the header's units and names
    /// ([`Roles::quantities`]), else the first column that neither the
    /// time column nor a given output takes.
    pub input: Option<Column>,
    /// The measured displacement [µm]; None: by the header's units and
    /// names, else the first column that neither
    /// the time column nor the input takes.
    pub output: Option<Column>,
    pub sampling: Sampling,
    /// What the input and output columns are called in messages.
    pub roles: Roles,
}

/// The names of the input and output columns' roles, as a command's options
/// name them: a message says "give --{role}".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roles {
    pub input: &'static str,
    pub output: &'static str,
    /// What each role's column measures, when the roles differ in it: a
    /// column left to the default is then chosen by what its header says it
    /// measures (its unit, or its name), not by its place alone.
    pub quantities: Option<(Quantity, Quantity)>,
}

impl Roles {
    /// A hysteresis record: the actuator command and the displacement.
    pub const INPUT_OUTPUT: Roles = Roles {
        input: "input",
        output: "output",
        quantities: Some((Quantity::Voltage, Quantity::Length)),
    };
}

/// What a column measures, as far as its header says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    Voltage,
    Length,
}

impl Quantity {
    fn name(self) -> &'static str {
        match self {
            Quantity::Voltage => "a voltage",
            Quantity::Length => "a length",
        }
    }
}

/// A voltage/displacement record sampled at a fixed period.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// Input (command) samples [V].
    pub input: Vec<f64>,
    /// Output (displacement) samples [µm].
    pub output: Vec<f64>,
    /// Sampling period [s].
    pub sample_period: f64,
}

/// The largest magnitude of an input or output value that is read: the
/// inverse model's cubic terms are squared in its normal equations (a value
/// to the sixth power), which overflow a double beyond about 1e51; 1e30 µm or
/// V leaves a margin and is no measurement in any unit (raw sensor counts
/// stay below 1e20).
pub const MAX_MEASURED_MAGNITUDE: f64 = 1e30;

/// What is wrong with a line (or, for [`Problem::TooFewRows`], the file).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    #[error("field {field} (\"{text}\") is not a number")]
    NotANumber { field: usize, text: String },
    #[error(
        "field {field} (\"{text}\") groups its digits with a thousands separator, which is not read: export the numbers without one"
    )]
    ThousandsSeparator { field: usize, text: String },
    #[error(
        "field {field} (\"{text}\") has a comma in quotes, which in a comma-separated file is a thousands separator (US) or a decimal comma, and nothing tells which: export with a point as the decimal mark and no thousands separator, or separate the fields with semicolons"
    )]
    QuotedComma { field: usize, text: String },
    #[error(
        "field {field} (\"{text}\"): the file writes decimals with a point (line {point_line}) and with a comma (line {comma_line}); {} is a thousands separator, which is not read",
        if *comma_last { "a comma beside decimal points" } else { "a point beside decimal commas" }
    )]
    TwoDecimalMarks {
        field: usize,
        text: String,
        /// Whether this field's mark, the one after the other's, is a comma.
        comma_last: bool,
        point_line: usize,
        comma_line: usize,
    },
    #[error(
        "field {field}, the time column, is in \"{unit}\"; give it in s, ms, us or ns, or give --rate instead"
    )]
    TimeUnit { field: usize, unit: String },
    #[error(
        "field {field}, the time column, is in \"{unit}\" by the units row but in \"{name_unit}\" by its name"
    )]
    TimeUnitsDisagree {
        field: usize,
        unit: String,
        name_unit: String,
    },
    #[error(
        "field {field} (\"{text}\") is a date and time{}; give it as the time column (--time {field}), or give --rate and a header that names it a time (\"Date\", \"Time\")",
        match role { Some(role) => format!(" in the {role} column"), None => String::new() }
    )]
    DateTime {
        field: usize,
        text: String,
        role: Option<&'static str>,
    },
    #[error(
        "field {field}, the time column, is \"{text}\", but it holds {} from line {first_line}: one time column is all dates and times or all numbers",
        if text.contains(':') { "numbers" } else { "dates and times" }
    )]
    MixedTimes {
        field: usize,
        text: String,
        first_line: usize,
    },
    #[error("field {field} is {value}, not a finite number")]
    NotFinite { field: usize, value: f64 },
    #[error(
        "every value is a whole number and fields {} have {} digits in every row, some with a \
         leading zero (\"{text}\" here): these read as the decimals of numbers written with a \
         decimal comma, split at it by the comma separator; export with a point as the decimal \
         mark, or separate the fields with semicolons or tabs",
        fraction_fields(*fields), digits
    )]
    SplitDecimalCommas {
        /// Number of fields per row.
        fields: usize,
        /// The digits of the fraction fields, in field order.
        digits: String,
        text: String,
    },
    #[error(
        "field {field} is {value:e}, beyond ±{MAX_MEASURED_MAGNITUDE:e}: no displacement or \
         voltage is that large in any unit, and the fits' sums of powers of it would overflow; \
         scale the column"
    )]
    TooLarge { field: usize, value: f64 },
    #[error("field {field} is empty, and it is the {role} column")]
    EmptySelected { field: usize, role: &'static str },
    #[error("row has {found} columns, column {needed} (0-based) is needed")]
    TooFewColumns { found: usize, needed: usize },
    #[error("column \"{name}\" is not in the header (columns: {header})")]
    UnknownColumn { name: String, header: String },
    #[error("column \"{name}\" is named twice in the header")]
    DuplicateColumn { name: String },
    #[error(
        "no column is left for the {role}: the header names {width}, and the others are taken or name a time (give --{role})"
    )]
    NoDefaultColumn { role: &'static str, width: usize },
    #[error(
        "the header names {count} columns of {quantity} that could be the {role} ({names}): give --{role}"
    )]
    AmbiguousDefault {
        role: &'static str,
        quantity: &'static str,
        count: usize,
        names: String,
    },
    #[error("field {field} is both the {first} and the {second} column")]
    SameColumn {
        field: usize,
        first: &'static str,
        second: &'static str,
    },
    #[error("column \"{name}\" is named but the file has no header row")]
    NoHeader { name: String },
    #[error("header has fields that are numbers and fields that are not")]
    MixedHeader,
    #[error(
        "the header (line {header_line}) has {names} {separator}-separated names but this row has {fields} fields"
    )]
    HeaderWidth {
        header_line: usize,
        names: usize,
        fields: usize,
        separator: &'static str,
    },
    #[error(
        "this row has {fields} {separator}-separated fields but the first row (line {first_line}) has {first_fields}"
    )]
    RowWidth {
        first_line: usize,
        first_fields: usize,
        fields: usize,
        separator: &'static str,
    },
    #[error("time {time} s does not increase (previous row: {previous} s)")]
    TimeNotIncreasing { previous: f64, time: f64 },
    #[error(
        "time step {step} s differs from the usual step {usual} s by more than 1 % (non-uniform sampling: resample the record, or give --rate instead of --time to take its rows as evenly spaced)"
    )]
    NonUniformSampling { step: Short, usual: Short },
    #[error(
        "the time jumps by {step} s, {steps} times the usual step of {usual} s: samples are missing, and the record is not continuous here (fit the part before or after the gap, each as its own file)"
    )]
    TimeGap {
        step: Short,
        usual: Short,
        steps: Short,
    },
    #[error(
        "the time column steps by {step} per row and names no unit, so it would be read in seconds: ten samples a second or fewer, too few for a hysteresis record; name its unit in the header (\"time [ms]\", \"time_ms\") or give --rate"
    )]
    SlowInSeconds { step: Short },
    #[error(
        "give the sampling: --rate HZ or --time COLUMN ({})",
        match names {
            Some(names) => format!("no column of the header, {names}, is named as a time"),
            None => "the file has no header to find a time column by".to_owned(),
        }
    )]
    NoSampling { names: Option<String> },
    #[error("give the sampling: --time COLUMN or --rate HZ (the header names {names} as times)")]
    TwoTimeColumns { names: String },
    #[error("only {found} data rows, at least {minimum} are needed")]
    TooFewRows { found: usize, minimum: usize },
    #[error(
        "the LabVIEW measurement file's header does not end: no second ***End_of_Header*** (the file header's, then the segment's)"
    )]
    LabviewHeaderUnended,
    #[error(
        "the LabVIEW header states the separator \"{separator}\"; this tool reads Tab and Comma"
    )]
    LabviewSeparator { separator: String },
    #[error(
        "a second LabVIEW segment starts here; this tool reads one continuous record: save each segment to its own file (or write the measurement without segment headers)"
    )]
    LabviewSegment,
    #[error(
        "--rate {rate} Hz is a step of {given} s, but the LabVIEW header's Delta_X is {stated} s (give --rate {stated_rate}, or --time X_Value)"
    )]
    LabviewRate {
        rate: Short,
        given: Short,
        stated: Short,
        stated_rate: Short,
    },
}

/// A record that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// `line` is 1-based; for a file-wide problem (too few rows) it is the
    /// last line of the file.
    #[error("{}:{line}: {problem}", path.display())]
    Malformed {
        path: PathBuf,
        line: usize,
        problem: Problem,
    },
    /// Nothing but blank lines and comments (or nothing at all).
    #[error("{}: the file is empty (no header and no data rows)", path.display())]
    Empty { path: PathBuf },
    /// The sample rate given in the options (not the file) is unusable.
    #[error("sample rate {rate} Hz is not a positive finite number")]
    InvalidRate { rate: f64 },
}

impl DataError {
    /// The problem, when the file was readable.
    pub fn problem(&self) -> Option<&Problem> {
        match self {
            DataError::Io { .. } | DataError::Empty { .. } | DataError::InvalidRate { .. } => None,
            DataError::Malformed { problem, .. } => Some(problem),
        }
    }
}

/// How the fields of a line are separated, decided on the file's first two
/// non-blank, non-comment lines ([`Separator::detect`]): the first of a tab,
/// a semicolon, a comma (each if the first line has one) and runs of spaces
/// under which the first line is a row of numbers, or a row of names with a
/// row of as many numbers below it; failing that, a tab if the first line
/// has one, else a comma, else a semicolon, else spaces (and the reading
/// reports what is wrong). So `0,005;1,856` (decimal commas) is
/// semicolon-separated, and so is `Zeit, s;Weg, um` above `0,005;1,856`,
/// while `time,u [V; amp],y` above `0.1,2,3` is comma-separated. With a
/// separator character every field counts, empty ones included (an unnamed
/// index column, a trailing separator), and a header name may contain spaces
/// ("Moment (Nm)").
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Separator {
    Tab,
    Comma,
    Semicolon,
    Whitespace,
}

impl Separator {
    /// The separator of a file whose first content lines are `first` and
    /// `next` (type comment; a units row may stand between the header and
    /// the first row of numbers).
    fn detect(first: &str, next: &[String]) -> Separator {
        let present = |separator: &Separator| match separator {
            Separator::Tab => first.contains('\t'),
            Separator::Semicolon => first.contains(';'),
            Separator::Comma => first.contains(','),
            Separator::Whitespace => true,
        };
        let fitting = [
            Separator::Tab,
            Separator::Semicolon,
            Separator::Comma,
            Separator::Whitespace,
        ]
        .into_iter()
        .filter(present)
        .find(|separator| {
            let fields = separator.split(first);
            let numbers = fields.iter().filter(|f| separator.value_like(f)).count();
            let empty = fields.iter().filter(|f| f.is_empty()).count();
            if numbers > 0 {
                return numbers + empty == fields.len();
            }
            let numbers_below = |line: &String| {
                let below = separator.split(line);
                below.len() == fields.len()
                    && below
                        .iter()
                        .all(|f| f.is_empty() || separator.value_like(f))
                    && below.iter().any(|f| !f.is_empty())
            };
            let units_below = |line: &String| {
                let below = separator.split(line);
                below.len() == fields.len() && below.iter().all(|f| separator.number(f).is_none())
            };
            match next {
                [second, ..] if numbers_below(second) => true,
                [second, third, ..] => units_below(second) && numbers_below(third),
                _ => false,
            }
        });
        fitting.unwrap_or(if first.contains('\t') {
            Separator::Tab
        } else if first.contains(',') {
            Separator::Comma
        } else if first.contains(';') {
            Separator::Semicolon
        } else {
            Separator::Whitespace
        })
    }

    /// The separator an Excel `sep=X` line states.
    fn stated(content: &str) -> Option<Separator> {
        let rest = content
            .trim_start()
            .get(..4)
            .filter(|key| key.eq_ignore_ascii_case("sep="))
            .map(|_| &content.trim_start()[4..])?;
        match rest.trim_end_matches(['\r', ' ']) {
            "," => Some(Separator::Comma),
            ";" => Some(Separator::Semicolon),
            "\t" | "" if rest.starts_with('\t') => Some(Separator::Tab),
            _ => None,
        }
    }

    /// The name used in messages.
    pub fn name(self) -> &'static str {
        match self {
            Separator::Tab => "tab",
            Separator::Comma => "comma",
            Separator::Semicolon => "semicolon",
            Separator::Whitespace => "space",
        }
    }

    /// The value of a field, and whether it was written with a decimal
    /// comma (module comment); None when it is not a number.
    fn number(self, text: &str) -> Option<(f64, bool)> {
        if let Ok(value) = text.parse::<f64>() {
            return Some((value, false));
        }
        // In a comma-separated file a field holds a comma only in quotes:
        // "5,000" is a thousand by a US spreadsheet's format and five by a
        // decimal-comma locale's, which nothing in the file tells apart.
        let decimal_comma_possible =
            self != Separator::Comma && text.matches(',').count() == 1 && !text.contains('.');
        if !decimal_comma_possible {
            return None;
        }
        text.replacen(',', ".", 1)
            .parse::<f64>()
            .ok()
            .map(|value| (value, true))
    }

    /// Whether a field is a value of a data row: a number, or a date and time
    /// ([`clock_time`]).
    fn value_like(self, text: &str) -> bool {
        self.number(text).is_some() || clock_time(text).is_some() || calendar_date(text)
    }

    /// The fields of a line. A field in double quotes (RFC 4180: R's
    /// write.csv, a name holding the separator) may hold the separator, and
    /// is read without its quotes.
    fn split(self, content: &str) -> Vec<&str> {
        fn unquoted(field: &str) -> &str {
            let field = field.trim_matches(' ');
            match field.strip_prefix('"').and_then(|f| f.strip_suffix('"')) {
                Some(inner) => inner,
                None => field,
            }
        }
        let by = |c: char| -> Vec<&str> {
            if !content.contains('"') {
                return content.split(c).map(unquoted).collect();
            }
            let mut fields = Vec::new();
            let (mut start, mut quoted) = (0, false);
            for (at, character) in content.char_indices() {
                // A quote opens only at a field's start (`Stroke 5"` is no
                // quoted field) and closes at the next one.
                if character == '"' && (quoted || content[start..at].trim_matches(' ').is_empty()) {
                    quoted = !quoted;
                } else if character == c && !quoted {
                    fields.push(unquoted(&content[start..at]));
                    start = at + c.len_utf8();
                }
            }
            fields.push(unquoted(&content[start..]));
            fields
        };
        match self {
            Separator::Tab => by('\t'),
            Separator::Comma => by(','),
            Separator::Semicolon => by(';'),
            Separator::Whitespace => content.split_whitespace().collect(),
        }
    }
}

/// A date and time, or a time of day, as data loggers and spreadsheets
/// write a time column: ISO 8601 (`2026-11-25T10:00:00.005`, with a space
/// for the `T`, with a zone `Z` or `+01:00`), with slashes
/// (`2026/11/25 10:00:00.005`, LabVIEW), day first with dots
/// (`25.11.2026 10:00:00,005`, German locales), or a time of day alone
/// (`10:00:00.005`). A decimal comma may mark the seconds' fraction. A zone
/// is applied (the result is UTC); a time of day is taken on one day, so a
/// record across midnight is refused as a time that does not increase.
/// None when `text` is none of these (every number is none: it has no `:`).
fn clock_time(text: &str) -> Option<chrono::NaiveDateTime> {
    use chrono::{DateTime, NaiveDate, NaiveDateTime, NaiveTime};
    if !text.contains(':') {
        return None;
    }
    let text = text.trim();
    let owned;
    let text = match text.rfind(',') {
        // The seconds' fraction written with a decimal comma.
        Some(at) if text[at + 1..].chars().all(|c| c.is_ascii_digit()) => {
            owned = format!("{}.{}", &text[..at], &text[at + 1..]);
            owned.as_str()
        }
        _ => text,
    };
    if let Ok(zoned) = DateTime::parse_from_rfc3339(&text.replacen(' ', "T", 1)) {
        return Some(zoned.naive_utc());
    }
    const DATE_TIMES: [&str; 4] = [
        "%Y-%m-%dT%H:%M:%S%.f",
        "%Y-%m-%d %H:%M:%S%.f",
        "%Y/%m/%d %H:%M:%S%.f",
        "%d.%m.%Y %H:%M:%S%.f",
    ];
    DATE_TIMES
        .iter()
        .find_map(|format| NaiveDateTime::parse_from_str(text, format).ok())
        .or_else(|| {
            let time = NaiveTime::parse_from_str(text, "%H:%M:%S%.f").ok()?;
            Some(NaiveDate::default().and_time(time))
        })
}

/// Whether `text` is a calendar date alone (`2026-11-25`, `2026/11/25`,
/// `25.11.2026`): a logger's date column beside its time-of-day column.
fn calendar_date(text: &str) -> bool {
    ["%Y-%m-%d", "%Y/%m/%d", "%d.%m.%Y"]
        .iter()
        .any(|format| chrono::NaiveDate::parse_from_str(text.trim(), format).is_ok())
}

/// What the header of a LabVIEW Measurement file (`.lvm`, written by
/// LabVIEW's "Write To Measurement File") says about its data. Such a file
/// opens with `LabVIEW Measurement`, a file header of `key<TAB>value` rows
/// (`Separator`, `Decimal_Separator`, `X_Columns`, ...) closed by
/// `***End_of_Header***`, then one segment header per segment (`Channels`,
/// `Samples`, `X_Dimension`, `Delta_X`, ...) closed the same way, then a row
/// of column names (`X_Value`, the channels' names, `Comment`) and the
/// samples. A header row's keys would otherwise be read as a bad data row.
#[derive(Clone, Debug, PartialEq)]
struct Labview {
    /// Lines 1..data_from hold the file and segment headers (1-based).
    data_from: usize,
    separator: Separator,
    /// The `X_Value` columns hold time in seconds (`X_Dimension Time`).
    x_is_time: bool,
    /// The first channel's sample step and the line that states it.
    delta_x: Option<(usize, f64)>,
}

/// The name LabVIEW gives its x (time) columns.
const LABVIEW_X_COLUMN: &str = "X_Value";

impl Labview {
    /// The layout of `text` if it is a LabVIEW Measurement file; an error
    /// (1-based line, problem) when its header is one this tool cannot read.
    fn of(text: &str) -> Result<Option<Labview>, (usize, Problem)> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        match lines.next() {
            Some((_, first)) if first.trim_start().starts_with("LabVIEW Measurement") => {}
            _ => return Ok(None),
        }
        let (mut separator, mut x_is_time, mut delta_x) = (Separator::Tab, false, None);
        let mut ends = 0;
        for (index, raw) in lines {
            let line = index + 1;
            let raw = raw.trim_end_matches('\r');
            // A decimal comma is possible only in a tab-separated header.
            let by = if raw.contains('\t') { '\t' } else { ',' };
            let mut fields = raw.split(by);
            let key = fields.next().unwrap_or("").trim();
            let value = fields.next().unwrap_or("").trim();
            match key {
                "***End_of_Header***" => {
                    ends += 1;
                    if ends == 2 {
                        return Ok(Some(Labview {
                            data_from: line + 1,
                            separator,
                            x_is_time,
                            delta_x,
                        }));
                    }
                }
                "Separator" => {
                    separator = match value {
                        "Tab" => Separator::Tab,
                        "Comma" => Separator::Comma,
                        other => {
                            return Err((
                                line,
                                Problem::LabviewSeparator {
                                    separator: other.to_owned(),
                                },
                            ));
                        }
                    }
                }
                "X_Dimension" => x_is_time = value == "Time",
                "Delta_X" if delta_x.is_none() => {
                    // The value may be written with the file's decimal comma.
                    delta_x = Separator::Tab.number(value).map(|(step, _)| (line, step));
                }
                _ => {}
            }
        }
        Err((text.lines().count().max(1), Problem::LabviewHeaderUnended))
    }

    /// Whether a line of the data part opens another segment's header.
    fn opens_a_segment(content: &str) -> bool {
        let first = content.split(['\t', ',']).next().unwrap_or("").trim();
        matches!(
            first,
            "Channels" | "***End_of_Header***" | "LabVIEW Measurement"
        )
    }
}

/// One column as it was used: its 0-based index, its header name, its unit
/// (from a units row) and the conversion its values were read with.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UsedColumn {
    pub index: usize,
    pub name: Option<String>,
    pub unit: Option<String>,
    pub converted: Option<Conversion>,
}

/// A length or voltage column written in another unit than the tool's (µm,
/// V), from its units row or its name (`Displacement [m]`), and read in the
/// tool's: every value times `factor`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Conversion {
    pub from: String,
    pub to: &'static str,
    pub factor: f64,
}

/// The tool's unit for a length or voltage unit, and the factor to it; None
/// for any other unit (a column in mdeg or % is read as written). With
/// `angles`, where the roles name no quantities (`decoupling`: a θ_z
/// demand beside lengths), an angle goes to µrad, the unit of the slope of
/// seed 000's D4: a demand in mrad read as written gave a slope 1000 times
/// too steep. A hysteresis record's command and displacement are no angles.
fn conversion_of(unit: &str, angles: bool) -> Option<(f64, &'static str)> {
    const DEGREE: f64 = std::f64::consts::PI / 180.0;
    if angles {
        match unit {
            "rad" => return Some((1e6, "urad")),
            "mrad" => return Some((1e3, "urad")),
            "urad" | "µrad" | "μrad" => return Some((1.0, "urad")),
            "deg" | "°" => return Some((DEGREE * 1e6, "urad")),
            "mdeg" => return Some((DEGREE * 1e3, "urad")),
            _ => {}
        }
    }
    Some(match unit {
        "m" => (1e6, "um"),
        "mm" => (1e3, "um"),
        "um" | "µm" | "μm" | "micron" | "microns" => (1.0, "um"),
        "nm" => (1e-3, "um"),
        "V" | "v" => (1.0, "V"),
        "mV" => (1e-3, "V"),
        "kV" => (1e3, "V"),
        _ => return None,
    })
}

/// The unit column `index` is written in: its field of the units row, else
/// the unit its header name ends with, in brackets (`Displacement [nm]`),
/// after a slash (`u/mV`) or as a last word that is a length or voltage unit
/// (`displacement_nm`, `Spannung mV`).
fn written_unit(
    index: usize,
    header: Option<&(usize, Vec<String>)>,
    units: Option<&(usize, Vec<String>)>,
) -> Option<String> {
    let from_row = units
        .and_then(|(_, row)| row.get(index))
        .map(|unit| bare_unit(unit))
        .filter(|unit| !unit.is_empty());
    let name = header.and_then(|(_, names)| names.get(index));
    from_row
        .or_else(|| name.and_then(|n| unit_in_name(n)).map(bare_unit))
        .or_else(|| name.and_then(|n| length_or_voltage_word(n)))
        .map(str::to_owned)
}

/// A length or voltage unit written as the last word of a column name
/// (`displacement_um`, `Weg nm`), case as written. Not `m` nor `v`: `y_m`
/// is as often y measured, `u_v` anything.
fn length_or_voltage_word(name: &str) -> Option<&str> {
    let name = name.trim_end();
    let separator = |c: char| c == '_' || c == ',' || c.is_whitespace();
    let at = name.rfind(separator)?;
    let word = name[at..].trim_start_matches(separator);
    let known = matches!(word, "mm" | "um" | "µm" | "μm" | "nm" | "V" | "mV" | "kV");
    (at > 0 && known).then_some(word)
}

/// What column `index` measures, as its header says: a length or voltage
/// unit ([`written_unit`]), else a word of its name (`Displacement`,
/// `Spannung`); None when the header says neither.
fn column_quantity(
    index: usize,
    header: Option<&(usize, Vec<String>)>,
    units: Option<&(usize, Vec<String>)>,
) -> Option<Quantity> {
    if let Some(unit) = written_unit(index, header, units) {
        return match conversion_of(&unit, false) {
            Some((_, "V")) => Some(Quantity::Voltage),
            Some(_) => Some(Quantity::Length),
            None => None,
        };
    }
    let name = header.and_then(|(_, names)| names.get(index))?;
    name.split(|c: char| !c.is_alphanumeric())
        .map(str::to_lowercase)
        .find_map(|word| match word.as_str() {
            "voltage" | "volt" | "volts" | "spannung" | "tension" => Some(Quantity::Voltage),
            "displacement" | "position" | "weg" | "auslenkung" | "distance" | "stroke"
            | "deflection" | "elongation" => Some(Quantity::Length),
            _ => None,
        })
}

/// Whether a header name is a row number's: empty (the index pandas writes
/// unnamed), or `Sample`, `Index`, `No.`, `#` and the like.
fn names_a_row_number(name: &str) -> bool {
    let name = name.trim().trim_end_matches('.').to_lowercase();
    matches!(
        name.as_str(),
        "" | "#"
            | "n"
            | "no"
            | "nr"
            | "index"
            | "idx"
            | "sample"
            | "samples"
            | "sample number"
            | "sample no"
            | "sample #"
            | "row"
            | "point"
            | "points"
            | "punkt"
            | "messpunkt"
    )
}

/// Whether a number is written with its digits grouped in thousands, by
/// commas before a decimal point (`-42,696.5`, `1,234,567`) or by points
/// before a decimal comma (`1.234,5`): groups of three digits after the
/// first separator of the kind.
fn grouped_by_thousands(text: &str) -> bool {
    let digits = text.trim_start_matches(['-', '+']);
    [(',', '.'), ('.', ',')]
        .into_iter()
        .any(|(group, decimal)| {
            let whole = digits.split(decimal).next().unwrap_or("");
            let mut groups = whole.split(group);
            let first = groups.next().unwrap_or("");
            let rest: Vec<&str> = groups.collect();
            digits.matches(decimal).count() <= 1
                && !rest.is_empty()
                && (1..=3).contains(&first.len())
                && !first.starts_with('0')
                && first.chars().all(|c| c.is_ascii_digit())
                && rest
                    .iter()
                    .all(|g| g.len() == 3 && g.chars().all(|c| c.is_ascii_digit()))
                && (rest.len() > 1 || digits.contains(decimal))
        })
}

/// How far --rate may be from the median step of a time column the file
/// also holds before the summary notes it: 2 %, more than any clock's drift
/// or a rounded rate (199.99 Hz given as 200), far less than a wrong rate.
const RATE_AGAINST_TIMES_TOLERANCE: f64 = 0.02;

/// Slowest sampling [s] a time column with no unit is read in seconds at:
/// ten samples a second, below what the loops of a 0.1-10 Hz drive need. A
/// record in milliseconds at the rates labs sample at, 1 to 10 kHz, steps
/// by 1 to 0.1 and is caught; at once a second, the bound before, a 1 kHz
/// record in ms was fitted as a 1 Hz one, its loops 1000 s long.
const SLOWEST_ASSUMED_PERIOD: f64 = 0.1;

/// Seconds per unit of a time column's unit (`ms`, `(ms)`, `[ms]`, ...);
/// None when it is not one of h, min, s, ms, us (µs) and ns.
fn seconds_per(unit: &str) -> Option<f64> {
    match bare_unit(unit).to_lowercase().as_str() {
        "h" | "hr" | "hrs" | "hour" | "hours" => Some(3600.0),
        "min" | "mins" | "minute" | "minutes" => Some(60.0),
        "s" | "sec" | "secs" | "second" | "seconds" => Some(1.0),
        "ms" | "msec" | "millisecond" | "milliseconds" => Some(1e-3),
        "us" | "µs" | "μs" | "usec" | "microsecond" | "microseconds" => Some(1e-6),
        "ns" | "nsec" | "nanosecond" | "nanoseconds" => Some(1e-9),
        _ => None,
    }
}

/// A time unit written as the last word of a column name (`time_ms`,
/// `Time ms`, `time in ms`, `Zeit, ms`): only a known time unit counts, so
/// `time_stamp` has none.
fn time_unit_word(name: &str) -> Option<&str> {
    let name = name.trim_end();
    let separator = |c: char| c == '_' || c == ',' || c == '-' || c.is_whitespace();
    let at = name.rfind(separator)?;
    // The separator may be wider than a byte (a Latin-1 no-break space).
    let word = name[at..].trim_start_matches(separator);
    (at > 0 && seconds_per(word).is_some()).then_some(word)
}

/// Whether a header name says its column is a time: a time unit in its
/// brackets or after a slash (`Time [s]`, `t/ms`), or a first word that
/// names time (`t`, `time`, `Zeit`, `timestamp`; a capital `T` is as often a
/// temperature, and a trailing `_s` or `_min` as often something else).
fn names_a_time(name: &str) -> bool {
    let first_word = name
        .split(|c: char| !c.is_alphanumeric())
        .find(|word| !word.is_empty())
        .unwrap_or("");
    unit_in_name(name).and_then(seconds_per).is_some()
        || first_word == "t"
        || matches!(
            first_word.to_lowercase().as_str(),
            "time" | "zeit" | "timestamp" | "temps" | "date" | "datetime" | "datum" | "zeitstempel"
        )
}

/// Whether a field of a row below the header reads as a unit (`V`, `(ms)`,
/// `um/s^2`, `%`): it starts with a letter, µ, %, or °, has digits only after
/// a `^`, and is not a missing-value marker (NA, NaN, null). A typo'd row of
/// numbers (`O.OO5`, `l.2`) is not a unit row, and is refused as data.
fn unit_like(field: &str) -> bool {
    let bare = bare_unit(field);
    let Some(first) = bare.chars().next() else {
        return false;
    };
    let digits_after_caret = bare
        .char_indices()
        .filter(|(_, c)| c.is_ascii_digit())
        .all(|(i, _)| bare[..i].contains('^'));
    (first.is_alphabetic() || "µμ%°".contains(first))
        && digits_after_caret
        && !matches!(
            bare.to_lowercase().as_str(),
            "na" | "nan" | "n/a" | "null" | "none" | "inf" | "infinity"
        )
}

/// A unit without the brackets it may be written in: `(ms)` is `ms`.
fn bare_unit(unit: &str) -> &str {
    unit.trim()
        .trim_start_matches(['(', '[', '{'])
        .trim_end_matches([')', ']', '}'])
        .trim()
}

/// The unit a column name ends with: in brackets (`Time (ms)`, `t [us]`)
/// or after a slash (`t/ms`, as ISO 80000 writes a quantity over its unit).
fn unit_in_name(name: &str) -> Option<&str> {
    let name = name.trim_end();
    let open = match name.chars().last()? {
        ')' => '(',
        ']' => '[',
        _ => return name.rfind('/').map(|at| &name[at + 1..]),
    };
    name.rfind(open).map(|at| &name[at..])
}

impl fmt::Display for UsedColumn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.name {
            Some(name) => write!(f, "column {} \"{name}\"", self.index)?,
            None => write!(f, "column {}", self.index)?,
        }
        if let Some(unit) = &self.unit {
            write!(f, " [{unit}]")?;
        }
        match &self.converted {
            Some(c) => write!(
                f,
                " (in {}, read as {}: x{})",
                c.from,
                c.to,
                Short(c.factor)
            ),
            None => Ok(()),
        }
    }
}

/// The columns a record was read from, for the report.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ColumnsUsed {
    pub input: UsedColumn,
    pub output: UsedColumn,
    pub time: Option<UsedColumn>,
    pub separator: Separator,
    /// Whether numbers were written with a decimal comma (module comment).
    pub decimal_comma: bool,
    /// Line of the header row, when there is one.
    pub header_line: Option<usize>,
    /// Line of the units row, when there is one.
    pub units_line: Option<usize>,
    /// The time column's unit, when there is a time column.
    pub time_unit: Option<TimeUnit>,
    /// The file was not UTF-8 and was read as Latin-1 (Windows exports).
    pub latin1: bool,
    /// A LabVIEW Measurement file: the last line of its headers.
    pub labview_header: Option<usize>,
    /// With --rate, the time column the header names with its unit, when
    /// its median step disagrees with the rate by more than 2 %.
    pub rate_disagreement: Option<RateDisagreement>,
}

/// A time column whose steps say another rate than --rate.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RateDisagreement {
    pub column: String,
    /// Its median step [s].
    pub step: f64,
}

/// Reads a record from a file.
/// The problem of a row of `fields` fields under a header of another width,
/// if any. LabVIEW names a last `Comment` column that its rows leave out
/// when they have no comment.
fn header_width(
    header: Option<&(usize, Vec<String>)>,
    comment_column: Option<usize>,
    fields: usize,
    separator: Separator,
) -> Option<Problem> {
    let (header_line, names) = header?;
    (names.len() != fields && !(comment_column.is_some() && names.len() == fields + 1)).then(|| {
        Problem::HeaderWidth {
            header_line: *header_line,
            names: names.len(),
            fields,
            separator: separator.name(),
        }
    })
}

/// The fraction fields (1, 3, 5, …) of a row of `fields` fields, as the
/// error message names them ("1 and 3").
fn fraction_fields(fields: usize) -> String {
    let odd: Vec<String> = (1..fields).step_by(2).map(|f| f.to_string()).collect();
    match odd.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
        None => String::new(),
    }
}

/// Whether a headerless comma-separated file is numbers written with a
/// decimal comma and split at it: `1,8000,17,8522` for 1.8 and 17.8522.
/// Read as written it is four whole numbers a row, and the fit would run on
/// integer parts and decimals (exit 0). The signature, checked over every
/// data row: an even number of fields, all whole numbers, every second field
/// unsigned with the same number of digits (at least two) in every row, and
/// somewhere one of them with a leading zero (`0350`). A real column of
/// whole numbers (ADC counts) is not written with leading zeros, and one
/// whose width never changes is not a fraction unless a zero pads it; a
/// single decimal (`1,5,2,3`) has no such trace and is not caught.
#[derive(Debug)]
struct SplitDecimalCommas {
    possible: bool,
    fields: usize,
    digits: Vec<usize>,
    leading_zero: Option<(usize, String)>,
}

impl SplitDecimalCommas {
    fn new() -> Self {
        SplitDecimalCommas {
            possible: true,
            fields: 0,
            digits: Vec::new(),
            leading_zero: None,
        }
    }

    fn row(&mut self, line: usize, fields: &[&str]) {
        if !self.possible {
            return;
        }
        let digits_only = |f: &str| !f.is_empty() && f.bytes().all(|b| b.is_ascii_digit());
        let whole = |f: &str| digits_only(f.strip_prefix(['-', '+']).unwrap_or(f));
        let pairs: Vec<(&str, &str)> = fields
            .chunks(2)
            .filter_map(|pair| match pair {
                [whole_part, fraction] => Some((whole_part.trim(), fraction.trim())),
                _ => None,
            })
            .collect();
        let digits: Vec<usize> = pairs.iter().map(|(_, fraction)| fraction.len()).collect();
        let shaped = fields.len() >= 2
            && fields.len().is_multiple_of(2)
            && pairs.iter().all(|&(w, f)| whole(w) && digits_only(f))
            && digits.iter().all(|&d| d >= 2)
            && (self.fields == 0 || (self.fields == fields.len() && self.digits == digits));
        if !shaped {
            self.possible = false;
            return;
        }
        self.fields = fields.len();
        self.digits = digits;
        if self.leading_zero.is_none()
            && let Some((_, fraction)) = pairs.iter().find(|(_, f)| f.starts_with('0'))
        {
            self.leading_zero = Some((line, (*fraction).to_owned()));
        }
    }

    /// The line and problem to refuse the file with, if it has the signature.
    fn verdict(self) -> Option<(usize, Problem)> {
        let (line, text) = self.leading_zero.filter(|_| self.possible)?;
        let digits: Vec<String> = self.digits.iter().map(|d| d.to_string()).collect();
        let digits = match digits.iter().all(|d| *d == digits[0]) {
            true => digits[0].clone(),
            false => digits.join(", "),
        };
        Some((
            line,
            Problem::SplitDecimalCommas {
                fields: self.fields,
                digits,
                text,
            },
        ))
    }
}

pub fn read_record(path: &Path, options: &ReadOptions) -> Result<Record, DataError> {
    read_record_with_columns(path, options).map(|(record, _)| record)
}

/// Reads a record from a file and says which columns it used.
pub fn read_record_with_columns(
    path: &Path,
    options: &ReadOptions,
) -> Result<(Record, ColumnsUsed), DataError> {
    let bytes = std::fs::read(path).map_err(|source| DataError::Io {
        path: path.to_owned(),
        source,
    })?;
    // Excel's "Unicode text" is UTF-16 with a byte-order mark.
    let utf16 = match bytes.as_slice() {
        [0xFF, 0xFE, rest @ ..] => Some((rest, u16::from_le_bytes as fn([u8; 2]) -> u16)),
        [0xFE, 0xFF, rest @ ..] => Some((rest, u16::from_be_bytes as fn([u8; 2]) -> u16)),
        _ => None,
    };
    // A Windows export in Latin-1 (or CP1252, the same for µ and °) is read
    // byte for byte: every byte is a Latin-1 character.
    let (text, latin1) = match utf16 {
        Some((rest, unit)) => {
            // An odd last byte is no character: it is left out.
            let units: Vec<u16> = rest.chunks_exact(2).map(|c| unit([c[0], c[1]])).collect();
            (String::from_utf16_lossy(&units), false)
        }
        None => match String::from_utf8(bytes) {
            Ok(text) => (text, false),
            Err(e) => (e.into_bytes().iter().map(|&b| b as char).collect(), true),
        },
    };
    let (record, mut used) = parse_record_with_columns(&text, path, options)?;
    used.latin1 = latin1;
    Ok((record, used))
}

/// Parses a record from text; `path` only names the source in errors.
pub fn parse_record(text: &str, path: &Path, options: &ReadOptions) -> Result<Record, DataError> {
    parse_record_with_columns(text, path, options).map(|(record, _)| record)
}

/// [`parse_record`], also saying which columns it used.
pub fn parse_record_with_columns(
    text: &str,
    path: &Path,
    options: &ReadOptions,
) -> Result<(Record, ColumnsUsed), DataError> {
    let malformed = |line: usize, problem: Problem| DataError::Malformed {
        path: path.to_owned(),
        line,
        problem,
    };
    if let Sampling::Rate(rate) = options.sampling
        && !(rate.is_finite() && rate > 0.0)
    {
        return Err(DataError::InvalidRate { rate });
    }

    // A byte-order mark (Excel's "CSV UTF-8") is no part of the first name;
    // a file whose lines end in a lone CR (classic Mac exports) has lines.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let lines_by_cr;
    let text = if text.contains('\r') && !text.contains('\n') {
        lines_by_cr = text.replace('\r', "\n");
        lines_by_cr.as_str()
    } else {
        text
    };
    let labview = Labview::of(text).map_err(|(line, problem)| malformed(line, problem))?;
    if let (
        Some(Labview {
            delta_x: Some((line, stated)),
            ..
        }),
        Sampling::Rate(rate),
    ) = (&labview, &options.sampling)
        && (1.0 / rate - stated).abs() > UNIFORM_SAMPLING_TOLERANCE * stated
    {
        return Err(malformed(
            *line,
            Problem::LabviewRate {
                rate: Short(*rate),
                given: Short(1.0 / rate),
                stated: Short(*stated),
                stated_rate: Short(1.0 / stated),
            },
        ));
    }
    let in_labview_header = |line: usize| {
        labview
            .as_ref()
            .is_some_and(|layout| line < layout.data_from)
    };
    let mut separator: Option<Separator> = None;
    let mut header: Option<(usize, Vec<String>)> = None;
    let mut resolved: Option<ResolvedColumns> = None;
    // With --rate, the one column whose header names a time, if any, its
    // seconds per unit, and its first and last numbers with their count:
    // a rate that disagrees with the times the file holds is refused.
    let mut rate_against: Option<(usize, f64)> = None;
    let mut rate_against_times: Vec<f64> = Vec::new();
    let mut input = Vec::new();
    let mut output = Vec::new();
    let mut times: Vec<(usize, f64)> = Vec::new();
    let mut decimal_comma = false;
    let mut last_line = 0;
    let mut split_decimal_commas = SplitDecimalCommas::new();
    // Line and width of the first data row of a file without a header.
    let mut first_row_width: Option<(usize, usize)> = None;

    // Only the line end and spaces are trimmed: a leading tab is an empty
    // first field.
    // A line starting with % is a comment too (MATLAB and Octave write them).
    let content_of = |raw: &str| -> String {
        if raw.trim_start().starts_with('%') {
            return String::new();
        }
        // A `#` inside double quotes (`"Sensor #2"`) is part of a name.
        let mut quoted = false;
        let end = raw
            .char_indices()
            .find(|&(_, c)| {
                quoted ^= c == '"';
                c == '#' && !quoted
            })
            .map_or(raw.len(), |(at, _)| at);
        raw[..end]
            .trim_end_matches(['\r', ' '])
            .trim_start_matches(' ')
            .to_owned()
    };
    // Excel's `sep=;` first line states the separator, and so does a
    // LabVIEW header (line 0: no line of the data part to skip).
    let stated = match &labview {
        Some(layout) => Some((0, layout.separator)),
        None => text
            .lines()
            .map(content_of)
            .enumerate()
            .find(|(_, content)| !content.trim().is_empty())
            .and_then(|(index, content)| Separator::stated(&content).map(|s| (index + 1, s))),
    };
    let mut first_lines = text
        .lines()
        .map(content_of)
        .enumerate()
        .filter(|(index, content)| {
            !content.trim().is_empty()
                && stated.is_none_or(|(line, _)| line != index + 1)
                && !in_labview_header(index + 1)
        })
        .map(|(_, content)| content);
    let first = first_lines.next();
    let next: Vec<String> = first_lines.take(2).collect();
    let mut units: Option<(usize, Vec<String>)> = None;
    // The time column's unit, once the columns are resolved.
    let mut time_unit: Option<TimeUnit> = None;
    // The first field of each decimal mark, to refuse a file that has both.
    let mut first_decimal_point: Option<usize> = None;
    let mut first_decimal_comma: Option<usize> = None;
    // The first date and time of a time column that holds them: its
    // times are seconds from this one.
    let mut clock_origin: Option<chrono::NaiveDateTime> = None;
    // A LabVIEW file's `Comment` column: text, never read.
    let mut comment_column: Option<usize> = None;
    // Whether the time column holds dates and times, from its first row.
    let mut time_is_clock: Option<bool> = None;
    // LabVIEW's X_Value columns are times in seconds.
    let x_is_time = labview.as_ref().is_some_and(|layout| layout.x_is_time);

    // The last line with anything but separators and spaces on it.
    let last_filled_line = text
        .lines()
        .map(content_of)
        .enumerate()
        .filter(|(_, content)| {
            content
                .chars()
                .any(|c| !(c.is_whitespace() || c == ',' || c == ';'))
        })
        .last()
        .map_or(0, |(index, _)| index + 1);
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        last_line = line;
        let content = content_of(raw);
        let content = content.as_str();
        if content.trim().is_empty()
            || stated.is_some_and(|(at, _)| at == line)
            || in_labview_header(line)
        {
            continue;
        }
        if labview.is_some() && header.is_some() && Labview::opens_a_segment(content) {
            return Err(malformed(line, Problem::LabviewSegment));
        }
        let first_content_row = separator.is_none();
        let row_separator = separator.unwrap_or_else(|| match stated {
            Some((_, stated)) => stated,
            None => Separator::detect(first.as_deref().unwrap_or(content), &next),
        });
        let fields = row_separator.split(content);
        // A row of separators alone before the first data row or after the
        // last (`;;`: Excel writes one for each row whose cells were
        // cleared) is a blank line. Between data rows it is a sample with
        // missing values, refused below: skipped, it would shift every later
        // sample's time by one period under --rate.
        if fields.iter().all(|f| f.trim().is_empty())
            && (resolved.is_none() || line > last_filled_line)
        {
            continue;
        }
        let separator = *separator.get_or_insert(row_separator);
        if first_content_row {
            let numeric = fields.iter().filter(|f| separator.value_like(f)).count();
            if numeric == 0 {
                header = Some((line, fields.iter().map(|f| (*f).to_owned()).collect()));
                // LabVIEW's last column holds free-text comments.
                if labview.is_some() && fields.last() == Some(&"Comment") {
                    comment_column = Some(fields.len() - 1);
                }
                continue;
            }
            // Mostly names with a number among them: a header with a typo, not
            // something to guess about. Mostly numbers: a data row, whose bad
            // field is reported below.
            if 2 * numeric < fields.len() {
                return Err(malformed(line, Problem::MixedHeader));
            }
        }
        if let Some((_, names)) = &header
            && units.is_none()
            && resolved.is_none()
            && fields.len() == names.len()
            && fields.iter().any(|f| !f.is_empty())
            && fields.iter().all(|f| f.is_empty() || unit_like(f))
        {
            units = Some((line, fields.iter().map(|f| (*f).to_owned()).collect()));
            continue;
        }
        if separator == Separator::Comma && header.is_none() {
            split_decimal_commas.row(line, &fields);
        }
        let columns = match &resolved {
            Some(columns) => *columns,
            None => {
                // Checked before the columns are resolved by the header's
                // names (and again after every row's fields, below).
                if let Some(problem) =
                    header_width(header.as_ref(), comment_column, fields.len(), separator)
                {
                    return Err(malformed(line, problem));
                }
                let columns = resolve_columns(options, header.as_ref(), units.as_ref(), x_is_time)
                    .map_err(|(at, problem)| malformed(at.unwrap_or(line), problem))?;
                if let Some(time) = columns.time {
                    time_unit = Some(
                        time_unit_of(time, header.as_ref(), units.as_ref(), x_is_time)
                            .map_err(|(at, problem)| malformed(at, problem))?,
                    );
                }
                if let (Sampling::Rate(_), Some((_, names))) = (&options.sampling, &header) {
                    let named: Vec<usize> = (0..names.len())
                        .filter(|&i| columns.names_time(i))
                        .collect();
                    // A unit the time cannot be read in leaves the check out,
                    // and so does none: a column "time" of 0, 1, 2, ... may
                    // count samples, which --rate then times.
                    if let [one] = named.as_slice()
                        && let Ok(unit) =
                            time_unit_of(*one, header.as_ref(), units.as_ref(), x_is_time)
                        && !unit.source.starts_with("assumed")
                    {
                        rate_against = Some((*one, unit.seconds_per_unit));
                    }
                }
                resolved = Some(columns);
                columns
            }
        };
        let needed = columns.largest();
        if fields.len() <= needed {
            return Err(malformed(
                line,
                Problem::TooFewColumns {
                    found: fields.len(),
                    needed,
                },
            ));
        }
        let mut values = vec![f64::NAN; fields.len()];
        // This row's time, when the time column holds dates and times.
        let mut clock_seconds = None;
        for (field, text) in fields.iter().enumerate() {
            if Some(field) == comment_column {
                continue;
            }
            let role = columns.role(field);
            if text.is_empty() {
                // An empty field in a column nobody reads (an unnamed index
                // column, a trailing separator) is no sign of corruption.
                match role {
                    Some(role) => {
                        return Err(malformed(line, Problem::EmptySelected { field, role }));
                    }
                    None => continue,
                }
            }
            if let Some(clock) = clock_time(text) {
                if Some(field) == columns.time {
                    let origin = *clock_origin.get_or_insert(clock);
                    let since = (clock - origin).num_nanoseconds().ok_or_else(|| {
                        malformed(
                            line,
                            Problem::NotANumber {
                                field,
                                text: (*text).to_owned(),
                            },
                        )
                    })?;
                    clock_seconds = Some(since as f64 * 1e-9);
                    continue;
                }
                // Dates in a column nobody reads, named as a time, are kept
                // out of the way; anywhere else they are a misread column.
                if role.is_none() && columns.names_time(field) {
                    continue;
                }
                return Err(malformed(
                    line,
                    Problem::DateTime {
                        field,
                        text: (*text).to_owned(),
                        role,
                    },
                ));
            }
            // A date alone (a logger's date column beside its time of day),
            // in a column named as a time that nothing reads.
            if role.is_none() && columns.names_time(field) && calendar_date(text) {
                continue;
            }
            let (value, comma) = separator.number(text).ok_or_else(|| {
                let text = (*text).to_owned();
                let quoted_comma = separator == Separator::Comma
                    && text.matches(',').count() == 1
                    && text.replacen(',', ".", 1).parse::<f64>().is_ok();
                malformed(
                    line,
                    if quoted_comma {
                        Problem::QuotedComma { field, text }
                    } else if grouped_by_thousands(&text) {
                        Problem::ThousandsSeparator { field, text }
                    } else {
                        Problem::NotANumber { field, text }
                    },
                )
            })?;
            if comma {
                first_decimal_comma.get_or_insert(line);
            } else if text.contains('.') {
                first_decimal_point.get_or_insert(line);
            }
            if let (Some(point_line), Some(comma_line)) = (first_decimal_point, first_decimal_comma)
            {
                return Err(malformed(
                    line,
                    Problem::TwoDecimalMarks {
                        field,
                        text: (*text).to_owned(),
                        comma_last: comma,
                        point_line,
                        comma_line,
                    },
                ));
            }
            decimal_comma |= comma;
            if !value.is_finite() {
                return Err(malformed(line, Problem::NotFinite { field, value }));
            }
            values[field] = value;
        }
        // Every row as wide as the header, or as the first row of a file
        // without one (checked after its fields, whose own faults say more):
        // a row with a field more or less (a decimal comma split off, a value
        // left out) would shift its columns and be read as another record's.
        match &header {
            Some(_) => {
                if let Some(problem) =
                    header_width(header.as_ref(), comment_column, fields.len(), separator)
                {
                    return Err(malformed(line, problem));
                }
            }
            None => {
                let (first_line, first_fields) =
                    *first_row_width.get_or_insert((line, fields.len()));
                if fields.len() != first_fields {
                    return Err(malformed(
                        line,
                        Problem::RowWidth {
                            first_line,
                            first_fields,
                            fields: fields.len(),
                            separator: separator.name(),
                        },
                    ));
                }
            }
        }
        for field in [columns.input, columns.output] {
            let value = values[field];
            if value.abs() > MAX_MEASURED_MAGNITUDE {
                return Err(malformed(line, Problem::TooLarge { field, value }));
            }
        }
        input.push(values[columns.input]);
        output.push(values[columns.output]);
        if let Some((column, _)) = rate_against {
            // A row without a number there (dates, an empty field) leaves
            // the check out: the times cannot be compared by their numbers.
            match values.get(column).copied() {
                Some(t) if t.is_finite() => rate_against_times.push(t),
                _ => rate_against = None,
            }
        }
        if let Some(time) = columns.time {
            // One time column is all dates and times, or all numbers.
            let row_is_clock = clock_seconds.is_some();
            if *time_is_clock.get_or_insert(row_is_clock) != row_is_clock {
                return Err(malformed(
                    line,
                    Problem::MixedTimes {
                        field: time,
                        text: fields[time].to_owned(),
                        first_line: times.first().map_or(line, |&(at, _)| at),
                    },
                ));
            }
            let t = clock_seconds.unwrap_or_else(|| {
                values[time] * time_unit.as_ref().map_or(1.0, |u| u.seconds_per_unit)
            });
            if let Some(&(_, previous)) = times.last()
                && t <= previous
            {
                return Err(malformed(
                    line,
                    Problem::TimeNotIncreasing { previous, time: t },
                ));
            }
            times.push((line, t));
        }
    }

    if clock_origin.is_some() {
        time_unit = Some(TimeUnit {
            seconds_per_unit: 1.0,
            unit: "s".to_owned(),
            source: "dates and times, from the first row's".to_owned(),
        });
    }
    let Some(separator) = separator else {
        return Err(DataError::Empty {
            path: path.to_owned(),
        });
    };
    if separator == Separator::Comma
        && header.is_none()
        && let Some((line, problem)) = split_decimal_commas.verdict()
    {
        return Err(malformed(line, problem));
    }
    // Columns named in the options must exist even in a file without data.
    let columns = match resolved {
        Some(columns) => columns,
        None => resolve_columns(options, header.as_ref(), units.as_ref(), x_is_time)
            .map_err(|(line, problem)| malformed(line.unwrap_or(last_line), problem))?,
    };
    if input.len() < MINIMUM_ROWS {
        return Err(malformed(
            last_line,
            Problem::TooFewRows {
                found: input.len(),
                minimum: MINIMUM_ROWS,
            },
        ));
    }
    // The median step, not each one nor the mean: --rate is also the way
    // past a time column whose steps jitter or have gaps, or whose header
    // names the wrong unit; so a disagreement is noted, not refused.
    let mut rate_disagreement = None;
    if let (&Sampling::Rate(rate), Some((column, seconds_per_unit))) =
        (&options.sampling, rate_against)
        && rate_against_times.len() == input.len()
        && rate_against_times.len() > 1
    {
        let stated = median_step(rate_against_times.iter().copied()) * seconds_per_unit;
        if stated <= 0.0 || (stated * rate - 1.0).abs() > RATE_AGAINST_TIMES_TOLERANCE {
            let name = header
                .as_ref()
                .and_then(|(_, names)| names.get(column))
                .cloned()
                .unwrap_or_default();
            rate_disagreement = Some(RateDisagreement {
                column: name,
                step: stated,
            });
        }
    }
    let sample_period = match options.sampling {
        Sampling::Rate(rate) => 1.0 / rate,
        Sampling::TimeColumn(_) => uniform_period(&times).map_err(|(l, p)| malformed(l, p))?,
        Sampling::Unspaced { .. } => 1.0,
    };
    // Times with no unit named are read as seconds; a hysteresis record
    // sampled more slowly than ten times a second is far likelier in
    // milliseconds.
    if let (Sampling::TimeColumn(_), Some(unit)) = (&options.sampling, &time_unit)
        && unit.source.starts_with("assumed")
        && sample_period >= SLOWEST_ASSUMED_PERIOD * (1.0 - 1e-9)
    {
        return Err(malformed(
            times[1].0,
            Problem::SlowInSeconds {
                step: Short(sample_period),
            },
        ));
    }
    let used = |index: usize| {
        let name = header
            .as_ref()
            .and_then(|(_, names)| names.get(index))
            .filter(|name| !name.is_empty())
            .cloned();
        let unit = units
            .as_ref()
            .and_then(|(_, row)| row.get(index))
            .map(|unit| bare_unit(unit))
            .filter(|unit| !unit.is_empty())
            .map(str::to_owned);
        let written_in = written_unit(index, header.as_ref(), units.as_ref());
        let converted = written_in.and_then(|from| {
            let (factor, to) = conversion_of(&from, options.roles.quantities.is_none())?;
            (factor != 1.0).then_some(Conversion { from, to, factor })
        });
        UsedColumn {
            index,
            name,
            unit,
            converted,
        }
    };
    let (input_used, output_used) = (used(columns.input), used(columns.output));
    for (samples, column) in [(&mut input, &input_used), (&mut output, &output_used)] {
        if let Some(conversion) = &column.converted {
            samples.iter_mut().for_each(|v| *v *= conversion.factor);
        }
    }
    let columns_used = ColumnsUsed {
        input: input_used,
        output: output_used,
        // Times are scaled by their time unit, never as a length or voltage.
        time: columns.time.map(|index| UsedColumn {
            converted: None,
            ..used(index)
        }),
        separator,
        decimal_comma,
        header_line: header.as_ref().map(|(line, _)| *line),
        units_line: units.as_ref().map(|(line, _)| *line),
        time_unit,
        latin1: false,
        labview_header: labview.map(|layout| layout.data_from - 1),
        rate_disagreement,
    };
    Ok((
        Record {
            input,
            output,
            sample_period,
        },
        columns_used,
    ))
}

/// Seconds per unit of time column `time`: its unit in the units row, else
/// a time unit in brackets at the end of its name, else 1 (seconds). A units
/// row that gives it a unit other than a time unit is refused.
fn time_unit_of(
    time: usize,
    header: Option<&(usize, Vec<String>)>,
    units: Option<&(usize, Vec<String>)>,
    x_is_time: bool,
) -> Result<TimeUnit, (usize, Problem)> {
    if x_is_time
        && header.is_some_and(|(_, names)| names.get(time).is_some_and(|n| n == LABVIEW_X_COLUMN))
    {
        return Ok(TimeUnit {
            seconds_per_unit: 1.0,
            unit: "s".to_owned(),
            source: "LabVIEW header: X_Dimension Time".to_owned(),
        });
    }
    let named = header.and_then(|(line, names)| {
        let name = names.get(time)?;
        let unit = unit_in_name(name).or_else(|| time_unit_word(name))?;
        Some((*line, unit.to_owned(), seconds_per(unit)))
    });
    if let Some((line, row)) = units
        && let Some(unit) = row.get(time).filter(|u| !u.is_empty())
    {
        let scale = seconds_per(unit).ok_or_else(|| {
            (
                *line,
                Problem::TimeUnit {
                    field: time,
                    unit: unit.clone(),
                },
            )
        })?;
        if let Some((_, name_unit, Some(name_scale))) = &named
            && *name_scale != scale
        {
            return Err((
                *line,
                Problem::TimeUnitsDisagree {
                    field: time,
                    unit: unit.clone(),
                    name_unit: name_unit.clone(),
                },
            ));
        }
        return Ok(TimeUnit {
            seconds_per_unit: scale,
            unit: bare_unit(unit).to_owned(),
            source: "units row".to_owned(),
        });
    }
    Ok(match named {
        Some((_, unit, Some(scale))) => TimeUnit {
            seconds_per_unit: scale,
            unit: bare_unit(&unit).to_owned(),
            source: "column name".to_owned(),
        },
        Some((_, unit, None)) => TimeUnit {
            seconds_per_unit: 1.0,
            unit: "s".to_owned(),
            source: format!("assumed: \"{unit}\" in its name is not a time unit"),
        },
        None => TimeUnit {
            seconds_per_unit: 1.0,
            unit: "s".to_owned(),
            source: "assumed: no time unit given".to_owned(),
        },
    })
}

/// The time column's unit as it was read.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TimeUnit {
    pub seconds_per_unit: f64,
    /// As written, without brackets (`ms`).
    pub unit: String,
    /// "units row", "column name", or "assumed: ..." and why.
    pub source: String,
}

#[derive(Clone, Copy, Debug)]
struct ResolvedColumns {
    input: usize,
    output: usize,
    time: Option<usize>,
    roles: Roles,
    /// Columns (of the first 64) whose header names a time.
    named_times: u64,
}

impl ResolvedColumns {
    fn names_time(&self, column: usize) -> bool {
        column < 64 && self.named_times & (1 << column) != 0
    }

    fn largest(&self) -> usize {
        self.input.max(self.output).max(self.time.unwrap_or(0))
    }

    /// What a column is read as, if anything.
    fn role(&self, column: usize) -> Option<&'static str> {
        if column == self.input {
            Some(self.roles.input)
        } else if column == self.output {
            Some(self.roles.output)
        } else if Some(column) == self.time {
            Some("time")
        } else {
            None
        }
    }
}

/// Turns the selected columns into indices; an error carries the header's
/// line when a name is not found there.
fn resolve_columns(
    options: &ReadOptions,
    header: Option<&(usize, Vec<String>)>,
    units: Option<&(usize, Vec<String>)>,
    x_is_time: bool,
) -> Result<ResolvedColumns, (Option<usize>, Problem)> {
    let time_named = |name: &String| names_a_time(name) || (x_is_time && name == LABVIEW_X_COLUMN);
    let resolve = |column: &Column| -> Result<usize, (Option<usize>, Problem)> {
        match column {
            Column::Index(i) => Ok(*i),
            Column::NamedTime => {
                let quoted = |names: &[String]| {
                    names
                        .iter()
                        .map(|n| format!("\"{n}\""))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let Some((line, names)) = header else {
                    return Err((None, Problem::NoSampling { names: None }));
                };
                let times: Vec<usize> = (0..names.len())
                    .filter(|&i| time_named(&names[i]))
                    .collect();
                // LabVIEW's X_Columns Multi gives every channel its own
                // X_Value, all the same times: the first stands for them.
                let all_x = times.iter().all(|&i| names[i] == LABVIEW_X_COLUMN);
                match times.as_slice() {
                    [one] => Ok(*one),
                    [first, ..] if x_is_time && all_x => Ok(*first),
                    [] => Err((
                        Some(*line),
                        Problem::NoSampling {
                            names: Some(quoted(names)),
                        },
                    )),
                    _ => {
                        let named: Vec<String> = times.iter().map(|&i| names[i].clone()).collect();
                        Err((
                            Some(*line),
                            Problem::TwoTimeColumns {
                                names: quoted(&named),
                            },
                        ))
                    }
                }
            }
            Column::Name(name) => match header {
                None => Err((None, Problem::NoHeader { name: name.clone() })),
                Some((line, names)) => {
                    let mut matches = names.iter().enumerate().filter(|(_, n)| *n == name);
                    let found = matches.next().map(|(i, _)| i);
                    let labview_x = x_is_time && name == LABVIEW_X_COLUMN;
                    if matches.next().is_some() && !labview_x {
                        return Err((Some(*line), Problem::DuplicateColumn { name: name.clone() }));
                    }
                    found.ok_or_else(|| {
                        (
                            Some(*line),
                            Problem::UnknownColumn {
                                name: name.clone(),
                                header: names
                                    .iter()
                                    .map(|n| format!("\"{n}\""))
                                    .collect::<Vec<_>>()
                                    .join(", "),
                            },
                        )
                    })
                }
            },
        }
    };
    let time = match &options.sampling {
        Sampling::TimeColumn(column) | Sampling::Unspaced { time: Some(column) } => {
            Some(resolve(column)?)
        }
        Sampling::Rate(_) | Sampling::Unspaced { time: None } => None,
    };
    // A column left to the default is the first one that no other role
    // takes, given or defaulted before it: `--time 0` with a header
    // "time,u,y" reads u and y, not time and u; `--output 0` alone reads the
    // input from column 1.
    let given_input = options.input.as_ref().map(&resolve).transpose()?;
    let given_output = options.output.as_ref().map(&resolve).transpose()?;
    let line = header.map(|(line, _)| *line);
    let width = header.map(|(_, names)| names.len());
    // A column whose header names a time (`Time [s]`) is no default input or
    // output either: with --rate given, it would be fitted as a voltage.
    let names_time =
        |i: usize| header.is_some_and(|(_, names)| names.get(i).is_some_and(time_named));
    // Nor is a row number (pandas' unnamed index, `Sample`, `Index`).
    let numbers_rows = |i: usize| {
        header.is_some_and(|(_, names)| names.get(i).is_some_and(|n| names_a_row_number(n)))
    };
    let measures = |i: usize| column_quantity(i, header, units);
    let free = |i: usize, taken: &[Option<usize>]| {
        !taken.contains(&Some(i)) && !names_time(i) && !numbers_rows(i)
    };
    // The free columns whose header says they measure `quantity`.
    let of_kind = |quantity: Quantity, taken: &[Option<usize>]| -> Vec<usize> {
        let count = width.unwrap_or(0);
        (0..count)
            .filter(|&i| free(i, taken) && measures(i) == Some(quantity))
            .collect()
    };
    let ambiguous = |role: &'static str, quantity: Quantity, several: &[usize]| {
        let names = header.map_or(String::new(), |(_, names)| {
            several
                .iter()
                .map(|&i| format!("\"{}\"", names[i]))
                .collect::<Vec<_>>()
                .join(", ")
        });
        (
            line,
            Problem::AmbiguousDefault {
                role,
                quantity: quantity.name(),
                count: several.len(),
                names,
            },
        )
    };
    // The first free column, passing over one whose header says it measures
    // `avoid` while another is left.
    let positional = |role: &'static str, taken: &[Option<usize>], avoid: Option<Quantity>| {
        let first = |passing: bool| {
            (0..)
                .find(|&i| free(i, taken) && !(passing && avoid.is_some() && measures(i) == avoid))
                .expect("a free column index")
        };
        let found = match width {
            Some(width) => Some(first(true))
                .filter(|&i| i < width)
                .unwrap_or_else(|| first(false)),
            None => first(false),
        };
        match width {
            Some(width) if found >= width => Err((line, Problem::NoDefaultColumn { role, width })),
            _ => Ok(found),
        }
    };
    // A length unit marks the displacement: a command is never one. A
    // voltage unit is weaker evidence (capacitive sensors and LVDTs read in
    // volts), so the input goes by it only in a header that also marks the
    // displacement by its length unit.
    let quantities = options.roles.quantities.is_some();
    let output_by_unit = match (given_output, quantities) {
        (None, true) => match of_kind(Quantity::Length, &[time, given_input]).as_slice() {
            [one] => Some(*one),
            [] => None,
            several => {
                return Err(ambiguous(options.roles.output, Quantity::Length, several));
            }
        },
        _ => None,
    };
    let output_known = given_output.or(output_by_unit);
    let marks_length =
        quantities && output_known.is_some_and(|o| measures(o) == Some(Quantity::Length));
    let avoid_in_input = quantities.then_some(Quantity::Length);
    let input = match given_input {
        Some(input) => input,
        None if marks_length => {
            match of_kind(Quantity::Voltage, &[time, output_known]).as_slice() {
                [one] => *one,
                [] => positional(options.roles.input, &[time, output_known], avoid_in_input)?,
                several => {
                    return Err(ambiguous(options.roles.input, Quantity::Voltage, several));
                }
            }
        }
        None => positional(options.roles.input, &[time, given_output], avoid_in_input)?,
    };
    let output = match output_known {
        Some(output) => output,
        // By place: a voltage here may be the sensor's reading.
        None => positional(options.roles.output, &[time, Some(input)], None)?,
    };
    let roles = [
        (options.roles.input, Some(input)),
        (options.roles.output, Some(output)),
        ("time", time),
    ];
    for (i, (first, a)) in roles.iter().enumerate() {
        for (second, b) in &roles[i + 1..] {
            if let (Some(field), true) = (*a, a == b) {
                return Err((
                    line,
                    Problem::SameColumn {
                        field,
                        first,
                        second,
                    },
                ));
            }
        }
    }
    Ok(ResolvedColumns {
        input,
        output,
        time,
        roles: options.roles,
        named_times: (0..64)
            .filter(|&i| names_time(i))
            .fold(0, |bits, i| bits | 1 << i),
    })
}

/// The mean period of a strictly increasing time column, refusing a step that
/// deviates from the usual (median) step by more than
/// [`UNIFORM_SAMPLING_TOLERANCE`]: a gap is named at the row after it (the
/// The median step between consecutive `times` (at least two): the usual
/// step, which a gap or jitter does not move as it moves the mean.
fn median_step(times: impl Iterator<Item = f64>) -> f64 {
    let times: Vec<f64> = times.collect();
    let mut steps: Vec<f64> = times.windows(2).map(|pair| pair[1] - pair[0]).collect();
    let middle = steps.len() / 2;
    *steps.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// median, unlike the mean, is not moved by the gap itself).
fn uniform_period(times: &[(usize, f64)]) -> Result<f64, (usize, Problem)> {
    let (first, last) = (times[0].1, times[times.len() - 1].1);
    let mean = (last - first) / (times.len() - 1) as f64;
    let usual = median_step(times.iter().map(|&(_, t)| t));
    for pair in times.windows(2) {
        let step = pair[1].1 - pair[0].1;
        if step > GAP_STEPS * usual {
            return Err((
                pair[1].0,
                Problem::TimeGap {
                    step: Short(step),
                    usual: Short(usual),
                    steps: Short(step / usual),
                },
            ));
        }
        if (step - usual).abs() > UNIFORM_SAMPLING_TOLERANCE * usual {
            return Err((
                pair[1].0,
                Problem::NonUniformSampling {
                    step: Short(step),
                    usual: Short(usual),
                },
            ));
        }
    }
    Ok(mean)
}

/// A step this many times the usual one is a gap (samples missing), not
/// jitter: half a sample more than a whole one.
const GAP_STEPS: f64 = 1.5;

#[cfg(test)]
mod tests {
    use super::*;

    fn options(input: Column, output: Column, sampling: Sampling) -> ReadOptions {
        ReadOptions {
            input: Some(input),
            output: Some(output),
            sampling,
            roles: Roles::INPUT_OUTPUT,
        }
    }

    fn by_index() -> ReadOptions {
        options(Column::Index(0), Column::Index(1), Sampling::Rate(100.0))
    }

    /// `rows` data rows "u y" (whitespace separated) after `prefix`.
    fn rows(prefix: &str, count: usize) -> String {
        let mut text = prefix.to_owned();
        for n in 0..count {
            text.push_str(&format!("{} {}\n", n as f64 * 0.1, n as f64 * 0.2));
        }
        text
    }

    fn message(text: &str, options: &ReadOptions) -> String {
        parse_record(text, Path::new("data.txt"), options)
            .expect_err("the record must be refused")
            .to_string()
    }

    #[test]
    fn reads_whitespace_columns_with_comments_and_blank_lines() {
        let text = rows("# a comment\n\n", MINIMUM_ROWS) + "  # trailing comment line\n";
        let record = parse_record(&text, Path::new("data.txt"), &by_index()).unwrap();
        assert_eq!(record.input.len(), MINIMUM_ROWS);
        assert_eq!(record.input[3], 0.30000000000000004);
        assert_eq!(record.output[3], 0.6000000000000001);
        assert_eq!(record.sample_period, 0.01);
    }

    #[test]
    fn reads_comma_columns_by_header_name_with_a_time_column() {
        let mut text = String::from("time, volts, um # units: s, V, um\n");
        for n in 0..40 {
            text.push_str(&format!("{}, {}, {} # row\n", n as f64 * 0.005, n, 2 * n));
        }
        let options = options(
            Column::Name("volts".into()),
            Column::Name("um".into()),
            Sampling::TimeColumn(Column::Name("time".into())),
        );
        let record = parse_record(&text, Path::new("data.csv"), &options).unwrap();
        assert_eq!(record.input[39], 39.0);
        assert_eq!(record.output[39], 78.0);
        assert!((record.sample_period - 0.005).abs() < 1e-15);
    }

    /// Numbers written with a decimal comma in a comma-separated file
    /// (`0,5123,10,2371`: 0.5123 and 10.2371) read as four whole numbers a
    /// row, and the fit ran on integer parts and decimals (exit 0). Refused
    /// at the first decimal with a leading zero, which no column of counts
    /// has.
    #[test]
    fn decimal_commas_split_by_the_comma_separator_are_refused() {
        let write = |v: f64| format!("{v:.4}").replace('.', ",");
        let rows: Vec<(String, String)> = (0..40)
            .map(|n| {
                (
                    write(0.5 + 0.0123 * n as f64),
                    write(10.2 + 0.0371 * n as f64),
                )
            })
            .collect();
        let commas: String = rows.iter().map(|(u, y)| format!("{u},{y}\n")).collect();
        // Line 23 holds the first decimal with a leading zero: 11.0162.
        assert_eq!(commas.lines().nth(22), Some("0,7706,11,0162"));
        assert_eq!(
            message(&commas, &by_index()),
            "data.txt:23: every value is a whole number and fields 1 and 3 have 4 digits in \
             every row, some with a leading zero (\"0162\" here): these read as the decimals of \
             numbers written with a decimal comma, split at it by the comma separator; export \
             with a point as the decimal mark, or separate the fields with semicolons or tabs"
        );
        // Separated by semicolons, the same numbers are read as written.
        let semicolons: String = rows.iter().map(|(u, y)| format!("{u};{y}\n")).collect();
        let record = parse_record(&semicolons, Path::new("data.txt"), &by_index()).unwrap();
        assert_eq!((record.input[22], record.output[22]), (0.7706, 11.0162));
    }

    /// Whole numbers as a column of counts holds them, of any width, or of
    /// one width that no zero pads, are read as written.
    #[test]
    fn comma_separated_whole_numbers_are_read() {
        let varying: String = (0..40)
            .map(|n| format!("{},{}\n", 5 * n, 1000 + 7 * n))
            .collect();
        let record = parse_record(&varying, Path::new("data.txt"), &by_index()).unwrap();
        assert_eq!((record.input[39], record.output[39]), (195.0, 1273.0));
        let fixed: String = (0..40)
            .map(|n| format!("{},{},{},{}\n", n, 1000 + n, -n, 2000 + n))
            .collect();
        let record = parse_record(&fixed, Path::new("data.txt"), &by_index()).unwrap();
        assert_eq!((record.input[39], record.output[39]), (39.0, 1039.0));
    }

    #[test]
    fn column_parse_reads_indices_and_names() {
        assert_eq!(Column::parse("4"), Column::Index(4));
        assert_eq!(Column::parse("volts"), Column::Name("volts".into()));
    }

    #[test]
    fn refuses_a_field_that_is_not_a_number() {
        let text = rows("", 5) + "0.5 1.o\n" + &rows("", 40);
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:6: field 1 (\"1.o\") is not a number"
        );
    }

    #[test]
    fn refuses_an_empty_field_in_a_column_it_reads() {
        let text = "1,2\n3,,4\n";
        assert_eq!(
            message(text, &by_index()),
            "data.txt:2: field 1 is empty, and it is the output column"
        );
    }

    /// pandas' `to_csv` writes its index as an unnamed first column; with
    /// `sep="\t"` the header starts with a tab. Read by name, the columns must
    /// be the named ones, not shifted by the index.
    #[test]
    fn reads_a_pandas_export_with_an_unnamed_index_column() {
        for separator in [",", "\t"] {
            let mut text = format!("{separator}volts{separator}um\n");
            for n in 0..40 {
                text.push_str(&format!(
                    "{n}{separator}{}{separator}{}\n",
                    0.5 * n as f64,
                    2 * n
                ));
            }
            let options = options(
                Column::Name("volts".into()),
                Column::Name("um".into()),
                Sampling::Rate(10.0),
            );
            let (record, used) =
                parse_record_with_columns(&text, Path::new("pd.csv"), &options).unwrap();
            assert_eq!(record.input[3], 1.5, "separator {separator:?}");
            assert_eq!(record.output[3], 6.0);
            assert_eq!(used.input.to_string(), "column 1 \"volts\"");
            assert_eq!(used.output.index, 2);
        }
    }

    /// An index column left empty in every row (",1.5,3" or "\t1.5\t3") is
    /// not corruption: it is not read.
    #[test]
    fn accepts_an_empty_column_it_does_not_read() {
        for separator in [",", "\t"] {
            let mut text = String::new();
            for n in 0..40 {
                text.push_str(&format!("{separator}{}{separator}{}\n", n, 2 * n));
            }
            let options = options(Column::Index(1), Column::Index(2), Sampling::Rate(10.0));
            let record = parse_record(&text, Path::new("e.csv"), &options).unwrap();
            assert_eq!(record.output[5], 10.0, "separator {separator:?}");
        }
    }

    /// A tab-separated export whose names contain spaces: the names are the
    /// tab-separated ones, and a word of a name is not a column.
    #[test]
    fn tab_separated_names_may_contain_spaces() {
        let mut text = String::from("Time (s)\tMoment (Nm)\tAngle (deg)\n");
        for n in 0..40 {
            text.push_str(&format!("{}\t{}\t{}\n", n as f64 * 0.01, n, 3 * n));
        }
        let by_name = |output: &str| {
            options(
                Column::Name("Angle (deg)".into()),
                Column::Name(output.into()),
                Sampling::TimeColumn(Column::Name("Time (s)".into())),
            )
        };
        let (record, used) =
            parse_record_with_columns(&text, Path::new("t.tsv"), &by_name("Moment (Nm)")).unwrap();
        assert_eq!(record.output[4], 4.0);
        assert_eq!(record.input[4], 12.0);
        assert_eq!(used.separator, Separator::Tab);
        assert_eq!(
            message(&text, &by_name("Moment")),
            "data.txt:1: column \"Moment\" is not in the header (columns: \"Time (s)\", \"Moment (Nm)\", \"Angle (deg)\")"
        );
    }

    /// A European spreadsheet's export: semicolons, decimal commas, with or
    /// without a header; and a LabVIEW one: tabs, decimal commas. Each reads
    /// the same numbers as the same record written with decimal points, and
    /// says it read decimal commas.
    #[test]
    fn reads_decimal_commas_in_semicolon_tab_and_space_separated_files() {
        let samples: Vec<(f64, f64, f64)> = (0..40)
            .map(|n| {
                (
                    n as f64 * 0.005,
                    1.8 + 0.25 * n as f64,
                    -123.059139 + 0.5 * n as f64,
                )
            })
            .collect();
        let written = |separator: &str, header: &str, comma: bool| {
            let mut text = header.to_owned();
            for (t, u, y) in &samples {
                let row = format!("{t:.3}{separator}{u:.6}{separator}{y:.6}\n");
                text.push_str(&if comma { row.replace('.', ",") } else { row });
            }
            text
        };
        let time_column = options(
            Column::Index(1),
            Column::Index(2),
            Sampling::TimeColumn(Column::Index(0)),
        );
        let read = |text: &str| {
            parse_record_with_columns(text, Path::new("export.csv"), &time_column).unwrap()
        };
        let (reference, used) = read(&written(";", "", false));
        assert!(!used.decimal_comma);
        assert_eq!(reference.output[1], -122.559139);
        for (separator, header) in [
            (";", "Zeit [s];Spannung [V];Weg [um]\n"),
            (";", ""),
            ("\t", "Zeit [s]\tSpannung [V]\tWeg [um]\n"),
            ("\t", ""),
            (" ", "Zeit Spannung Weg\n"),
            (" ", ""),
        ] {
            let (record, used) = read(&written(separator, header, true));
            assert_eq!(record, reference, "{separator:?} {header:?}");
            assert!(used.decimal_comma);
            assert_eq!(used.header_line.is_some(), !header.is_empty());
            assert_eq!(
                used.separator,
                match separator {
                    ";" => Separator::Semicolon,
                    "\t" => Separator::Tab,
                    _ => Separator::Whitespace,
                }
            );
        }
        // In a comma-separated file a comma separates: "1,5" is two fields.
        let mut text = String::from("volts,microns\n");
        for n in 0..40 {
            text.push_str(&format!("{n},5\n"));
        }
        let (record, used) =
            parse_record_with_columns(&text, Path::new("c.csv"), &by_index()).unwrap();
        assert_eq!((record.input[3], record.output[3]), (3.0, 5.0));
        assert!(!used.decimal_comma);
        // Neither a field with two commas nor one with a comma and a point is
        // a decimal-comma number; neither is a number.
        let odd = |field: &str| {
            let text = format!("u;y\n{field};1\n") + &"1;2\n".repeat(40);
            message(&text, &by_index())
        };
        assert_eq!(
            odd("1,2,3"),
            "data.txt:2: field 0 (\"1,2,3\") is not a number"
        );
        // A comma and a point in thousands and decimals: named as such.
        for grouped in ["1,234.5", "-42,696.5", "1.234,5", "1,234,567"] {
            assert_eq!(
                odd(grouped),
                format!(
                    "data.txt:2: field 0 (\"{grouped}\") groups its digits with a thousands \
                     separator, which is not read: export the numbers without one"
                )
            );
        }
        assert_eq!(
            odd("12,34.5"),
            "data.txt:2: field 0 (\"12,34.5\") is not a number"
        );
        assert_eq!(
            odd("0.001,5"),
            "data.txt:2: field 0 (\"0.001,5\") is not a number"
        );
        // In quotes, a comma-separated file's comma may be a US thousands
        // separator ("5,000") or a decimal comma: refused, saying so.
        let mut text = String::from("Voltage,Displacement\n");
        for n in 0..40 {
            text.push_str(&format!("{n},\"5,000\"\n"));
        }
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:2: field 1 (\"5,000\") has a comma in quotes, which in a comma-separated \
             file is a thousands separator (US) or a decimal comma, and nothing tells which: \
             export with a point as the decimal mark and no thousands separator, or separate \
             the fields with semicolons"
        );
    }

    /// The separator is the one under which the first line is numbers, or
    /// names above as many numbers: a comma-separated file whose header has a
    /// semicolon in a name, and a semicolon-separated one whose names have
    /// commas in them, are both read by their names.
    #[test]
    fn the_separator_is_the_one_the_header_and_first_row_agree_on() {
        let by_names = options(
            Column::Name("u [V; amp in]".into()),
            Column::Name("y".into()),
            Sampling::Rate(100.0),
        );
        let text = (0..40).fold(String::from("time,u [V; amp in],y\n"), |t, n| {
            t + &format!("{},{},{}\n", n, 0.5 * n as f64, n)
        });
        let (record, used) =
            parse_record_with_columns(&text, Path::new("c.csv"), &by_names).unwrap();
        assert_eq!(used.separator, Separator::Comma);
        assert_eq!((record.input[3], record.output[3]), (1.5, 3.0));

        let by_names = options(
            Column::Name("Spannung, V".into()),
            Column::Name("Weg, um".into()),
            // As the time column says: one sample a second.
            Sampling::Rate(1.0),
        );
        let text = (0..40).fold(String::from("Zeit, s;Spannung, V;Weg, um\n"), |t, n| {
            t + &format!("{n};{n},5;-{n},25\n")
        });
        let (record, used) =
            parse_record_with_columns(&text, Path::new("s.csv"), &by_names).unwrap();
        assert_eq!(used.separator, Separator::Semicolon);
        assert!(used.decimal_comma);
        assert_eq!((record.input[3], record.output[3]), (3.5, -3.25));
    }

    /// A PicoScope-style export: a units row below the header, a blank line,
    /// time in ms. The same record with its time in seconds, in µs by a name
    /// like `t [us]`, and in a semicolon file whose units row says `s`, reads
    /// the same; a units row that gives the time column no time unit is
    /// refused, naming it.
    #[test]
    fn reads_a_units_row_and_the_time_columns_unit() {
        let rows = |scale: f64, separator: &str| -> String {
            (0..40)
                .map(|n| {
                    let t = n as f64 * 0.005 / scale;
                    format!(
                        "{t}{separator}{}{separator}{}\n",
                        0.1 * n as f64,
                        0.2 * n as f64
                    )
                })
                .collect()
        };
        let by_index = options(
            Column::Index(1),
            Column::Index(2),
            Sampling::TimeColumn(Column::Index(0)),
        );
        let read = |text: &str| parse_record_with_columns(text, Path::new("p.csv"), &by_index);
        let (reference, plain) =
            read(&("Time,Channel A,Channel B\n".to_owned() + &rows(1.0, ","))).unwrap();
        assert_eq!(reference.sample_period, 0.005);
        assert_eq!(plain.units_line, None);
        assert_eq!(
            plain.time_unit.unwrap().source,
            "assumed: no time unit given"
        );

        let pico = "Time,Channel A,Channel B\n(ms),(V),(um)\n\n".to_owned() + &rows(1e-3, ",");
        let (record, used) = read(&pico).unwrap();
        assert!((record.sample_period - 0.005).abs() < 1e-15);
        assert_eq!(
            (record.input.clone(), record.output.clone()),
            (reference.input.clone(), reference.output.clone())
        );
        assert_eq!(
            (used.separator, used.units_line),
            (Separator::Comma, Some(2))
        );
        let unit = used.time_unit.clone().unwrap();
        assert_eq!(
            (
                unit.seconds_per_unit,
                unit.unit.as_str(),
                unit.source.as_str()
            ),
            (1e-3, "ms", "units row")
        );
        assert_eq!(used.output.to_string(), "column 2 \"Channel B\" [um]");

        let by_name = "t [us]\tu\ty\n".to_owned() + &rows(1e-6, "\t");
        let (record, used) = read(&by_name).unwrap();
        assert!((record.sample_period - 0.005).abs() < 1e-15);
        assert_eq!(used.units_line, None);
        let unit = used.time_unit.unwrap();
        assert_eq!(
            (unit.seconds_per_unit, unit.source.as_str()),
            (1e-6, "column name")
        );
        // Spelled otherwise: upper case, and ISO's quantity/unit.
        for head in ["Time (MS);u;y\n", "t/msec;u;y\n"] {
            let (record, _) = read(&(head.to_owned() + &rows(1e-3, ";"))).unwrap();
            assert!((record.sample_period - 0.005).abs() < 1e-15, "{head}");
        }
        // Brackets that are not a time unit: seconds, and the summary says why.
        let (record, used) = read(&("Time (abs);u;y\n".to_owned() + &rows(1.0, ";"))).unwrap();
        assert_eq!(record.sample_period, 0.005);
        assert_eq!(
            used.time_unit.unwrap().source,
            "assumed: \"(abs)\" in its name is not a time unit"
        );
        // A name and a units row that disagree.
        let both = "Time (ms);u;y\ns;V;um\n".to_owned() + &rows(1.0, ";");
        assert_eq!(
            message(&both, &by_index),
            "data.txt:2: field 0, the time column, is in \"s\" by the units row but in \"(ms)\" by its name"
        );

        let seconds = "Zeit;Spannung;Weg\ns;V;um\n".to_owned() + &rows(1.0, ";");
        let (record, used) = read(&seconds).unwrap();
        assert_eq!(record.sample_period, 0.005);
        assert_eq!(
            (used.separator, used.units_line),
            (Separator::Semicolon, Some(2))
        );

        let samples = "n;u;y\nsample;V;um\n".to_owned() + &rows(1.0, ";");
        assert_eq!(
            message(&samples, &by_index),
            "data.txt:2: field 0, the time column, is in \"sample\"; give it in s, ms, us or ns, or give --rate instead"
        );
        // A row of typos or of missing values below the header is a bad
        // data row, not units, even when no time column is read; one of
        // separators alone there, before any data, is blank (Excel's cleared
        // row), and between data rows a sample with missing values.
        let by_rate = options(Column::Index(1), Column::Index(2), Sampling::Rate(200.0));
        for (row, problem) in [
            ("O.OO5,l.2,-4Z.7", "field 0 (\"O.OO5\") is not a number"),
            ("NA,NA,NA", "field 0 (\"NA\") is not a number"),
        ] {
            let text = format!("Time,Channel A,Channel B\n{row}\n") + &rows(1.0, ",");
            assert_eq!(message(&text, &by_rate), format!("data.txt:2: {problem}"));
        }
        let plain = "Time,Channel A,Channel B\n".to_owned() + &rows(1.0, ",");
        let cleared = "Time,Channel A,Channel B\n,,\n".to_owned() + &rows(1.0, ",");
        let read_by_rate = |text: &str| parse_record(text, Path::new("data.txt"), &by_rate);
        assert_eq!(
            read_by_rate(&cleared).unwrap(),
            read_by_rate(&plain).unwrap()
        );
        let (head, tail) = plain.split_at(plain.find("0.05,").unwrap());
        assert_eq!(
            message(&format!("{head},,\n{tail}"), &by_rate),
            "data.txt:12: field 1 is empty, and it is the input column"
        );
    }

    /// A comma beside decimal points is a thousands separator (a US export
    /// separated by tabs), as a point beside decimal commas is (a German
    /// one): refused, with both lines named, not read as a decimal.
    #[test]
    fn refuses_decimal_commas_beside_decimal_points() {
        let mut text = String::from("time\tnm\tV\n");
        for n in 0..40 {
            text.push_str(&format!("{}\t{}\t1.5\n", n as f64 * 0.01, 14 + n));
        }
        text.push_str("0.41\t4,089\t1.5\n");
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:42: field 1 (\"4,089\"): the file writes decimals with a point (line 2) and with a comma (line 42); a comma beside decimal points is a thousands separator, which is not read"
        );
        // And the other way: a German export's point in a thousand, after
        // decimal commas.
        let mut text = String::from("Zeit;Weg;Spannung\n");
        for n in 0..40 {
            text.push_str(&format!("{n};{},5;1,5\n", 14 + n));
        }
        text.push_str("40;-42.697;1,5\n");
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:42: field 1 (\"-42.697\"): the file writes decimals with a point (line 42) and with a comma (line 2); a point beside decimal commas is a thousands separator, which is not read"
        );
    }

    /// A header that splits into more names than the rows have fields (names
    /// with spaces in a space-separated file) would put every name on the
    /// wrong column: refused.
    #[test]
    fn refuses_a_header_wider_than_its_rows() {
        let text = rows("time moment Nm angle\n", 40);
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:2: the header (line 1) has 4 space-separated names but this row has 2 fields"
        );
    }

    #[test]
    fn names_an_empty_file() {
        for text in ["", "\n\n# only a comment\n"] {
            assert_eq!(
                message(text, &by_index()),
                "data.txt: the file is empty (no header and no data rows)"
            );
        }
    }

    #[test]
    fn refuses_nan_and_infinity() {
        let text = rows("", 3) + "NaN 1\n";
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:4: field 0 is NaN, not a finite number"
        );
        let text = rows("", 2) + "1 -2e31\n";
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:3: field 1 is -2e31, beyond ±1e30: no displacement or voltage is that \
             large in any unit, and the fits' sums of powers of it would overflow; scale the column"
        );
        let text = rows("", 2) + "1 -inf\n";
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:3: field 1 is -inf, not a finite number"
        );
    }

    /// A row with a field more than the header (a decimal comma splitting
    /// `0.503` into `0,503` in a comma-separated file) or fewer shifts the
    /// columns after it: refused at that row, not only at the first, and
    /// in a file without a header against its first row.
    #[test]
    fn refuses_a_later_row_wider_or_narrower_than_the_first() {
        let mut text = String::from("demand,error,time\n");
        for n in 0..40 {
            text.push_str(&format!("{},{},{}\n", n, 0.1 * n as f64, n as f64 * 0.005));
        }
        let options = options(
            Column::Name("demand".into()),
            Column::Name("error".into()),
            Sampling::Rate(200.0),
        );
        let mut split: Vec<&str> = text.lines().collect();
        split[20] = "19,1,9,0.095";
        assert_eq!(
            message(&(split.join("\n") + "\n"), &options),
            "data.txt:21: the header (line 1) has 3 comma-separated names but this row has 4 fields"
        );
        // The time, which --rate leaves unread, left out.
        split[20] = "19,1.9";
        assert_eq!(
            message(&(split.join("\n") + "\n"), &options),
            "data.txt:21: the header (line 1) has 3 comma-separated names but this row has 2 fields"
        );
        let headerless = rows("# u y\n", 20) + "0.5 1.5 2.5\n" + &rows("", 20);
        assert_eq!(
            message(&headerless, &by_index()),
            "data.txt:22: this row has 3 space-separated fields but the first row (line 2) has 2"
        );
    }

    #[test]
    fn refuses_a_row_with_too_few_columns() {
        let text = rows("", 7) + "0.5\n";
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:8: row has 1 columns, column 1 (0-based) is needed"
        );
        let options = options(Column::Index(0), Column::Index(4), Sampling::Rate(200.0));
        assert_eq!(
            message(&rows("", 40), &options),
            "data.txt:1: row has 2 columns, column 4 (0-based) is needed"
        );
    }

    #[test]
    fn refuses_a_column_name_not_in_the_header() {
        let text = rows("# header follows\nvolts um\n", 40);
        let options = options(
            Column::Name("volts".into()),
            Column::Name("displacement".into()),
            Sampling::Rate(100.0),
        );
        assert_eq!(
            message(&text, &options),
            "data.txt:2: column \"displacement\" is not in the header (columns: \"volts\", \"um\")"
        );
    }

    /// `header` above 40 comma-separated rows: time n·0.01 s, u = n, y = 2n
    /// in the order `order` gives ("tuy" is time, u, y).
    fn time_u_y(header: &str, order: &str) -> String {
        let mut text = format!("{header}\n");
        for n in 0..40 {
            let field = |c| match c {
                't' => n as f64 * 0.01,
                'u' => n as f64,
                _ => 2.0 * n as f64,
            };
            let row: Vec<String> = order.chars().map(|c| field(c).to_string()).collect();
            text.push_str(&(row.join(",") + "\n"));
        }
        text
    }

    #[test]
    fn columns_left_to_the_default_skip_the_time_column() {
        let text = time_u_y("time,u,y", "tuy");
        let defaults = |time: Column| ReadOptions {
            input: None,
            output: None,
            sampling: Sampling::TimeColumn(time),
            roles: Roles::INPUT_OUTPUT,
        };
        for time in [Column::Index(0), Column::Name("time".into())] {
            let (record, used) =
                parse_record_with_columns(&text, Path::new("data.txt"), &defaults(time))
                    .expect("a record with a time column first");
            assert_eq!((used.input.index, used.output.index), (1, 2));
            assert_eq!((record.input[3], record.output[3]), (3.0, 6.0));
            assert!((record.sample_period - 0.01).abs() < 1e-12);
        }
        // The time column last: the defaults are the first two columns.
        let last = ReadOptions {
            sampling: Sampling::TimeColumn(Column::Index(2)),
            roles: Roles::INPUT_OUTPUT,
            ..defaults(Column::Index(0))
        };
        let text = time_u_y("u,y,time", "uyt");
        let (_, used) = parse_record_with_columns(&text, Path::new("data.txt"), &last).unwrap();
        assert_eq!((used.input.index, used.output.index), (0, 1));
    }

    #[test]
    fn a_default_column_skips_a_given_one_and_says_when_none_is_left() {
        let text = time_u_y("time,y,u", "tyu");
        let output_given = ReadOptions {
            input: None,
            output: Some(Column::Name("y".into())),
            sampling: Sampling::TimeColumn(Column::Index(0)),
            roles: Roles::INPUT_OUTPUT,
        };
        let (_, used) =
            parse_record_with_columns(&text, Path::new("data.txt"), &output_given).unwrap();
        assert_eq!((used.input.index, used.output.index), (2, 1));
        let narrow: String = text
            .lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_owned() + "\n")
            .collect();
        let defaults = ReadOptions {
            input: None,
            output: None,
            sampling: Sampling::TimeColumn(Column::Index(0)),
            roles: Roles::INPUT_OUTPUT,
        };
        assert_eq!(
            message(&narrow, &defaults),
            "data.txt:1: no column is left for the output: the header names 2, and the others \
             are taken or name a time (give --output)"
        );
    }

    #[test]
    fn refuses_one_column_in_two_roles() {
        let header = format!("time,u,y\n{}", rows("", 40).replace(' ', ",0,"));
        let given = |input: usize, output: usize| ReadOptions {
            input: Some(Column::Index(input)),
            output: Some(Column::Index(output)),
            sampling: Sampling::TimeColumn(Column::Name("time".into())),
            roles: Roles::INPUT_OUTPUT,
        };
        assert_eq!(
            message(&header, &given(0, 2)),
            "data.txt:1: field 0 is both the input and the time column"
        );
        assert_eq!(
            message(&header, &given(2, 2)),
            "data.txt:1: field 2 is both the input and the output column"
        );
        let by_rate = options(Column::Index(1), Column::Index(1), Sampling::Rate(100.0));
        assert_eq!(
            message(&rows("", 40), &by_rate),
            "data.txt:1: field 1 is both the input and the output column"
        );
    }

    #[test]
    fn refuses_a_column_name_without_a_header() {
        let options = options(
            Column::Name("volts".into()),
            Column::Index(1),
            Sampling::Rate(100.0),
        );
        assert_eq!(
            message(&rows("", 40), &options),
            "data.txt:1: column \"volts\" is named but the file has no header row"
        );
    }

    #[test]
    fn refuses_a_header_mixing_names_and_numbers() {
        let text = rows("volts um x 3\n", 40);
        assert_eq!(
            message(&text, &by_index()),
            "data.txt:1: header has fields that are numbers and fields that are not"
        );
    }

    #[test]
    fn refuses_time_that_does_not_increase() {
        let mut text = String::new();
        for n in 0..40 {
            let t = if n == 12 { 0.10 } else { n as f64 * 0.01 };
            text.push_str(&format!("{t} {n} {n}\n"));
        }
        let options = options(
            Column::Index(1),
            Column::Index(2),
            Sampling::TimeColumn(Column::Index(0)),
        );
        assert_eq!(
            message(&text, &options),
            "data.txt:13: time 0.1 s does not increase (previous row: 0.11 s)"
        );
    }

    #[test]
    fn refuses_non_uniform_sampling() {
        let mut text = String::new();
        for n in 0..40 {
            // Row 21 (line 21) comes 2 % late, the next one back on the grid.
            let t = n as f64 * 0.01 + if n == 20 { 0.0002 } else { 0.0 };
            text.push_str(&format!("{t} {n} {n}\n"));
        }
        let options = options(
            Column::Index(1),
            Column::Index(2),
            Sampling::TimeColumn(Column::Index(0)),
        );
        let message = message(&text, &options);
        assert!(
            message.starts_with("data.txt:21: time step 0.0102"),
            "{message}"
        );
        assert_eq!(
            message,
            "data.txt:21: time step 0.0102 s differs from the usual step 0.01 s by more than 1 % \
             (non-uniform sampling: resample the record, or give --rate instead of --time to \
             take its rows as evenly spaced)"
        );
    }

    /// A gap is named at the row after it, whatever its length: the median
    /// step is not moved by the gap, as the mean was (a gap of 2 % of the
    /// record was reported at line 2, a correct step).
    #[test]
    fn a_gap_is_named_where_it_is() {
        for missing in [1usize, 10, 100] {
            let mut text = String::new();
            for n in 0..400 {
                let t = 0.005 * (n + if n >= 240 { missing } else { 0 }) as f64;
                text.push_str(&format!("{t} {n} {n}\n"));
            }
            let options = options(
                Column::Index(1),
                Column::Index(2),
                Sampling::TimeColumn(Column::Index(0)),
            );
            let step = 0.005 * (missing + 1) as f64;
            assert_eq!(
                message(&text, &options),
                format!(
                    "data.txt:241: the time jumps by {} s, {} times the usual step of 0.005 s: \
                     samples are missing, and the record is not continuous here (fit the part \
                     before or after the gap, each as its own file)",
                    Short(step),
                    missing + 1
                )
            );
        }
    }

    #[test]
    fn short_numbers_keep_six_significant_digits() {
        let text = |v: f64| Short(v).to_string();
        assert_eq!(text(0.010000000000001563), "0.01");
        assert_eq!(text(0.0050847601), "0.00508476");
        assert_eq!(text(200.0), "200");
        assert_eq!(text(1e6), "1.00000e6");
        assert_eq!(text(-2.5e-7), "-2.50000e-7");
        assert_eq!(text(0.0), "0");
    }

    #[test]
    fn refuses_too_few_rows() {
        let text = rows("u y\n", 5) + "\n# end\n";
        assert_eq!(
            message(&text, &by_index()),
            format!("data.txt:8: only 5 data rows, at least {MINIMUM_ROWS} are needed")
        );
    }

    #[test]
    fn refuses_an_invalid_rate() {
        let options = options(Column::Index(0), Column::Index(1), Sampling::Rate(0.0));
        assert_eq!(
            message(&rows("", 40), &options),
            "sample rate 0 Hz is not a positive finite number"
        );
    }

    #[test]
    fn names_a_missing_file() {
        let error = read_record(Path::new("/nonexistent/record.dat"), &by_index()).unwrap_err();
        assert!(error.problem().is_none());
        assert!(
            error.to_string().starts_with("/nonexistent/record.dat: "),
            "{error}"
        );
    }
    fn time_u_y_rows(header: &str, step: f64, separator: &str) -> String {
        let mut text = format!("{header}\n");
        for n in 0..50 {
            let t = n as f64 * step;
            text.push_str(&format!(
                "{t}{separator}{}{separator}{}\n",
                0.1 * n as f64,
                0.3 * n as f64
            ));
        }
        text
    }

    fn timed_defaults() -> ReadOptions {
        ReadOptions {
            input: None,
            output: None,
            sampling: Sampling::TimeColumn(Column::Index(0)),
            roles: Roles::INPUT_OUTPUT,
        }
    }

    /// A time unit written as the name's last word, or in minutes or hours,
    /// scales the time column; a word that is no unit is not taken for one.
    #[test]
    fn a_time_unit_as_the_names_last_word_scales_the_times() {
        for (name, step, period) in [
            ("time_ms", 5.0, 0.005),
            ("t_ms", 5.0, 0.005),
            ("Time ms", 5.0, 0.005),
            ("time in ms", 5.0, 0.005),
            ("Zeit, ms", 5.0, 0.005),
            ("Time [min]", 5.0 / 60_000.0, 0.005),
            ("Time [h]", 0.005 / 3600.0, 0.005),
            ("time_us", 200.0, 2e-4),
        ] {
            let text = time_u_y_rows(&format!("{name};u;y"), step, ";");
            let (record, used) =
                parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults())
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(
                (record.sample_period - period).abs() < 1e-9 * period,
                "{name}"
            );
            assert!(
                !used.time_unit.unwrap().source.starts_with("assumed"),
                "{name}"
            );
        }
        // No unit in the name and ten samples a second or fewer in seconds:
        // refused, as a record in ms at 200 Hz, 1 kHz and 10 kHz is.
        for (step, shown) in [(5.0, "5"), (1.0, "1"), (0.1, "0.1")] {
            let text = time_u_y_rows("time_stamp;u;y", step, ";");
            assert_eq!(
                message(&text, &timed_defaults()),
                format!(
                    "data.txt:3: the time column steps by {shown} per row and names no unit, so \
                     it would be read in seconds: ten samples a second or fewer, too few for a \
                     hysteresis record; name its unit in the header (\"time [ms]\", \
                     \"time_ms\") or give --rate"
                )
            );
        }
        for step in [0.005, 0.099] {
            let text = time_u_y_rows("time_stamp;u;y", step, ";");
            assert!(parse_record(&text, Path::new("d.csv"), &timed_defaults()).is_ok());
        }
    }

    /// With --rate, a column whose name says it is a time is not taken as
    /// the default input or output.
    #[test]
    fn a_time_named_column_is_no_default_input() {
        for name in ["Time [s]", "t", "time_ms", "Zeit, s", "timestamp"] {
            // 200 Hz, as --rate says: a time column that says otherwise is refused.
            let step = if name == "time_ms" { 5.0 } else { 0.005 };
            let text = time_u_y_rows(&format!("{name};Voltage [V];Displacement [um]"), step, ";");
            let (_, used) =
                parse_record_with_columns(&text, Path::new("d.csv"), &by_rate_defaults()).unwrap();
            assert_eq!((used.input.index, used.output.index), (1, 2), "{name}");
        }
        // Not times: a temperature, a quantity with a unit-like suffix.
        for header in ["tension;u;y", "T [°C];u;y", "u_s;y_min;y"] {
            let text = time_u_y_rows(header, 0.005, ";");
            let (_, used) =
                parse_record_with_columns(&text, Path::new("d.csv"), &by_rate_defaults()).unwrap();
            assert_eq!((used.input.index, used.output.index), (0, 1), "{header}");
        }
        // A no-break space (a Latin-1 export's 0xA0) before a unit word.
        let text = time_u_y_rows("Zeit\u{a0}ms;Spannung\u{a0}(V);Weg\u{a0}(µm)", 5.0, ";");
        let (record, _) =
            parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults()).unwrap();
        assert!((record.sample_period - 0.005).abs() < 1e-12);
    }

    /// A column left to the default goes by what the header says it
    /// measures: a voltage is the input and a length the output wherever
    /// they stand, a row number is neither, and two columns that could take
    /// a role are refused rather than one fitted silently.
    #[test]
    fn default_columns_follow_the_units_and_names_of_the_header() {
        for (header, columns) in [
            ("Displacement [um];Voltage [V];Temperature", (1, 0)),
            ("Sample;Voltage [V];Displacement [um]", (1, 2)),
            (";voltage_V;displacement_um", (1, 2)),
            ("Index;Weg nm;Spannung mV", (2, 1)),
            ("Displacement;Voltage;Temperature", (1, 0)),
            ("Position (mm);u;y", (1, 0)),
            ("u;y;Temperature", (0, 1)),
            // A voltage without a displacement marked by its length unit
            // is no sign of the command: a sensor may read in volts.
            ("Time [s];Command;Sensor [V]", (1, 2)),
            ("Channel A [V];Channel B [V];Temperature", (0, 1)),
        ] {
            let text = time_u_y_rows(header, 0.005, ";");
            let (_, used) =
                parse_record_with_columns(&text, Path::new("d.csv"), &by_rate_defaults())
                    .unwrap_or_else(|e| panic!("{header}: {e}"));
            assert_eq!((used.input.index, used.output.index), columns, "{header}");
        }
        // A unit written as the name's last word converts as one in brackets.
        let text = time_u_y_rows("Zeit [s];Spannung mV;Weg nm", 0.005, ";");
        let (record, used) =
            parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults()).unwrap();
        assert_eq!(
            used.output.to_string(),
            "column 2 \"Weg nm\" (in nm, read as um: x0.001)"
        );
        assert!((record.input[10] - 0.1 * 10.0 * 1e-3).abs() < 1e-15);
        let text: String = time_u_y_rows("Time [s];Setpoint [um];Displacement [um]", 0.005, ";")
            .lines()
            .enumerate()
            .map(|(n, line)| match n {
                0 => format!("{line};Voltage [V]\n"),
                n => format!("{line};{}\n", 0.2 * n as f64),
            })
            .collect();
        assert_eq!(
            parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults())
                .unwrap_err()
                .to_string(),
            "d.csv:1: the header names 2 columns of a length that could be the output \
             (\"Setpoint [um]\", \"Displacement [um]\"): give --output"
        );
        // Given, a column is read whatever its header says.
        let given = ReadOptions {
            output: Some(Column::Name("Setpoint [um]".into())),
            ..timed_defaults()
        };
        let (_, used) = parse_record_with_columns(&text, Path::new("d.csv"), &given).unwrap();
        assert_eq!((used.input.index, used.output.index), (3, 1));
    }

    /// --rate against a time column the header names with its unit: the
    /// rate is used, and a median step more than 2 % off it is noted in the
    /// summary (gaps and jitter move the median no more than a wrong unit
    /// would be hidden); two time columns, or one with no unit (it may count
    /// samples), are not compared.
    #[test]
    fn a_rate_that_disagrees_with_the_time_column_is_noted() {
        let read = |text: &str, rate: f64| {
            let options = ReadOptions {
                sampling: Sampling::Rate(rate),
                ..by_rate_defaults()
            };
            let (record, used) = parse_record_with_columns(text, Path::new("d.csv"), &options)
                .unwrap_or_else(|e| panic!("{rate}: {e}"));
            assert_eq!(record.sample_period, 1.0 / rate);
            used.rate_disagreement
        };
        let text = time_u_y_rows("time_s;Voltage [V];Displacement [um]", 0.001, ";");
        for rate in [1000.0, 990.0, 1010.0] {
            assert_eq!(read(&text, rate), None, "{rate}");
        }
        let noted = read(&text, 500.0).expect("500 Hz against 1 ms steps");
        assert_eq!(noted.column, "time_s");
        assert!((noted.step - 0.001).abs() < 1e-12, "{}", noted.step);
        // Rows missing (a gap) leave the median step where it was.
        let gapped: String = text
            .lines()
            .enumerate()
            .filter(|(n, _)| !(20..28).contains(n))
            .map(|(_, line)| format!("{line}\n"))
            .collect();
        assert_eq!(read(&gapped, 1000.0), None);
        // In ms by its name: 5 ms steps are 200 Hz.
        let text = time_u_y_rows("Time [ms];Voltage [V];Displacement [um]", 5.0, ";");
        assert_eq!(read(&text, 200.0), None);
        assert!(read(&text, 1000.0).is_some());
        // Two columns named as times (a logger's clock beside the samples'
        // times): which one the rate stands for is not known.
        let text: String = time_u_y_rows("t;Voltage [V];Displacement [um]", 0.001, ";")
            .lines()
            .enumerate()
            .map(|(n, line)| match n {
                0 => format!("{line};time\n"),
                n => format!("{line};{}\n", 3600 + n),
            })
            .collect();
        assert_eq!(read(&text, 500.0), None);
        let text = time_u_y_rows("time;Voltage [V];Displacement [um]", 1.0, ";");
        assert_eq!(read(&text, 500.0), None);
    }

    fn by_rate_defaults() -> ReadOptions {
        ReadOptions {
            input: None,
            output: None,
            sampling: Sampling::Rate(200.0),
            roles: Roles::INPUT_OUTPUT,
        }
    }

    /// A byte-order mark, UTF-16, lone-CR line ends, % comments, Excel's
    /// sep= line and cleared rows and quoted fields all read as the plain
    /// file does.
    #[test]
    fn lab_export_variants_read_as_the_plain_file() {
        let plain = time_u_y_rows("time,u,y", 0.005, ",");
        let options = |time: Column| ReadOptions {
            input: Some(Column::Name("u".into())),
            output: Some(Column::Name("y".into())),
            sampling: Sampling::TimeColumn(time),
            roles: Roles::INPUT_OUTPUT,
        };
        let expected = parse_record(
            &plain,
            Path::new("d.csv"),
            &options(Column::Name("time".into())),
        )
        .unwrap();
        let quoted: String = {
            let mut text = String::from("\"\",\"time\",\"u\",\"y\"\n");
            for (n, line) in plain.lines().skip(1).enumerate() {
                text.push_str(&format!("\"{}\",{line}\n", n + 1));
            }
            text
        };
        let variants = [
            ("bom", format!("\u{feff}{plain}")),
            ("cr", plain.replace('\n', "\r")),
            (
                "percent",
                format!("% Lab C, fs = 200 Hz\n%\tcolumns: t u y\n{plain}"),
            ),
            ("sep", format!("sep=,\n{plain}")),
            // Rows of separators alone: Excel's cleared rows, before the
            // header and at the end.
            ("cleared rows", format!(",,\n{plain},,\r\n,,\n")),
            ("quoted", quoted),
            (
                "quoted name",
                plain.replacen("time,u,y", "\"time, s\",u,y", 1),
            ),
            (
                "quoted hash",
                plain.replacen("time,u,y", "time,\"u #2\",y # a comment", 1),
            ),
        ];
        for (what, text) in variants {
            let time = if what == "quoted name" {
                "time, s"
            } else {
                "time"
            };
            let mut read = options(Column::Name(time.into()));
            if what == "quoted hash" {
                read.input = Some(Column::Name("u #2".into()));
            }
            let record = parse_record(&text, Path::new("d.csv"), &read)
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(record, expected, "{what}");
        }
        let dir = tempfile::tempdir().unwrap();
        for (what, bytes) in [
            (
                "utf-16le",
                [
                    vec![0xFF, 0xFE],
                    plain.encode_utf16().flat_map(u16::to_le_bytes).collect(),
                ]
                .concat(),
            ),
            (
                "utf-16be",
                [
                    vec![0xFE, 0xFF],
                    plain.encode_utf16().flat_map(u16::to_be_bytes).collect(),
                ]
                .concat(),
            ),
        ] {
            let path = dir.path().join(what);
            std::fs::write(&path, bytes).unwrap();
            let record = read_record(&path, &options(Column::Name("time".into())))
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(record, expected, "{what}");
        }
    }

    /// A displacement in m, mm or nm and a voltage in mV are read in um and
    /// V, and the columns say so; other units are read as written.
    #[test]
    fn lengths_and_voltages_are_read_in_um_and_volts() {
        let plain = time_u_y_rows("time;u;y", 0.005, ";");
        let expected = parse_record(&plain, Path::new("d.csv"), &timed_defaults()).unwrap();
        for (header, input_factor, output_factor) in [
            ("time;u [V];y [m]", 1.0, 1e-6),
            ("time;u (mV);y (mm)", 1e3, 1e-3),
            ("time;u/kV;y/nm", 1e-3, 1e3),
            ("time;u [%];y [mdeg]", 1.0, 1.0),
        ] {
            let text = plain.replacen("time;u;y", header, 1);
            let scaled: String = text
                .lines()
                .enumerate()
                .map(|(i, line)| {
                    if i == 0 {
                        return format!("{line}\n");
                    }
                    let f: Vec<f64> = line.split(';').map(|v| v.parse().unwrap()).collect();
                    format!(
                        "{};{};{}\n",
                        f[0],
                        f[1] * input_factor,
                        f[2] * output_factor
                    )
                })
                .collect();
            let (record, used) =
                parse_record_with_columns(&scaled, Path::new("d.csv"), &timed_defaults()).unwrap();
            for (got, want) in record.output.iter().zip(&expected.output) {
                assert!((got - want).abs() < 1e-9 * want.abs().max(1.0), "{header}");
            }
            for (got, want) in record.input.iter().zip(&expected.input) {
                assert!((got - want).abs() < 1e-9 * want.abs().max(1.0), "{header}");
            }
            assert_eq!(
                used.output.converted.is_some(),
                output_factor != 1.0,
                "{header}"
            );
        }
        let text = plain.replacen("time;u;y", "time;u;Displacement [m]", 1);
        let (_, used) =
            parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults()).unwrap();
        assert_eq!(
            used.output.to_string(),
            "column 2 \"Displacement [m]\" (in m, read as um: x1.00000e6)"
        );
    }

    /// A LabVIEW Measurement file as "Write To Measurement File" writes it:
    /// a file header, a segment header, `X_Value ... Comment` names.
    fn labview_file(decimal: &str, rows: usize) -> String {
        let mut text = format!(
            "LabVIEW Measurement\t\nWriter_Version\t2\nReader_Version\t2\nSeparator\tTab\n\
             Decimal_Separator\t{decimal}\nMulti_Headings\tNo\nX_Columns\tOne\n\
             Time_Pref\tRelative\nOperator\tlab\nDate\t2026/11/25\nTime\t10:00:00.1234\n\
             ***End_of_Header***\t\n\t\nChannels\t2\t\nSamples\t{rows}\t{rows}\t\n\
             Date\t2026/11/25\t2026/11/25\t\nY_Unit_Label\tVolts\tum\t\n\
             X_Dimension\tTime\tTime\t\nX0\t0{decimal}0\t0{decimal}0\t\n\
             Delta_X\t0{decimal}005\t0{decimal}005\t\n***End_of_Header***\t\n\
             X_Value\tVoltage\tDisplacement\tComment\n"
        );
        for n in 0..rows {
            let row = format!(
                "{:.6}\t{:.6}\t{:.6}\n",
                n as f64 * 0.005,
                0.1 * n as f64,
                0.3 * n as f64
            );
            text.push_str(&row.replace('.', decimal));
        }
        text
    }

    fn rate_defaults(rate: f64) -> ReadOptions {
        ReadOptions {
            sampling: Sampling::Rate(rate),
            ..timed_defaults()
        }
    }

    /// The headers are skipped, X_Value is the time (and no default input),
    /// the `Comment` name its rows leave out is dropped, a decimal comma is
    /// read, and the summary names the file's kind.
    #[test]
    fn reads_a_labview_measurement_file() {
        for decimal in [".", ","] {
            let text = labview_file(decimal, 40);
            for options in [
                ReadOptions {
                    sampling: Sampling::TimeColumn(Column::Name("X_Value".into())),
                    ..timed_defaults()
                },
                rate_defaults(200.0),
            ] {
                let (record, used) = parse_record_with_columns(&text, Path::new("r.lvm"), &options)
                    .unwrap_or_else(|e| panic!("decimal {decimal}: {e}"));
                assert_eq!(record.input.len(), 40);
                assert!((record.input[39] - 3.9).abs() < 1e-12);
                assert!((record.output[39] - 11.7).abs() < 1e-12);
                assert!((record.sample_period - 0.005).abs() < 1e-12);
                assert_eq!(used.input.name.as_deref(), Some("Voltage"));
                assert_eq!(used.output.name.as_deref(), Some("Displacement"));
                assert_eq!(used.labview_header, Some(21));
                assert_eq!(used.header_line, Some(22));
                assert_eq!(used.decimal_comma, decimal == ",");
                let timed = matches!(options.sampling, Sampling::TimeColumn(_));
                assert_eq!(
                    used.time_unit.as_ref().map(|unit| unit.source.as_str()),
                    timed.then_some("LabVIEW header: X_Dimension Time")
                );
            }
        }
    }

    #[test]
    fn refuses_what_a_labview_file_cannot_be_read_as() {
        let text = labview_file(".", 40);
        assert_eq!(
            message(&text, &rate_defaults(100.0)),
            "data.txt:20: --rate 100 Hz is a step of 0.01 s, but the LabVIEW header's Delta_X is 0.005 s (give --rate 200, or --time X_Value)"
        );
        let second = text.clone() + &text.lines().skip(13).collect::<Vec<_>>().join("\n");
        assert_eq!(
            message(&second, &rate_defaults(200.0)),
            "data.txt:63: a second LabVIEW segment starts here; this tool reads one continuous record: save each segment to its own file (or write the measurement without segment headers)"
        );
        let unended: String = text.lines().take(20).map(|l| format!("{l}\n")).collect();
        assert_eq!(
            message(&unended, &rate_defaults(200.0)),
            "data.txt:20: the LabVIEW measurement file's header does not end: no second ***End_of_Header*** (the file header's, then the segment's)"
        );
        let spaced = text.replacen("Separator\tTab", "Separator\tSpace", 1);
        assert_eq!(
            message(&spaced, &rate_defaults(200.0)),
            "data.txt:4: the LabVIEW header states the separator \"Space\"; this tool reads Tab and Comma"
        );
    }

    /// Dates and times in the time column, with a zone, across midnight, a
    /// time of day with a decimal comma: seconds from the first row's.
    #[test]
    fn reads_dates_and_times_in_the_time_column() {
        type Stamp = fn(u32) -> String;
        let stamps: [(&str, Stamp); 4] = [
            ("Date,u,y", |ms| {
                let (s, ms) = (50 + ms / 1000, ms % 1000);
                match s {
                    s if s < 60 => format!("2026-11-25 23:59:{s:02}.{ms:03}"),
                    s => format!("2026-11-26 00:00:{:02}.{ms:03}", s - 60),
                }
            }),
            ("time,u,y", |ms| {
                format!("2026-11-25T10:00:{:02}.{:03}+01:00", ms / 1000, ms % 1000)
            }),
            ("Zeit;u;y", |ms| {
                format!("10:00:{:02},{:03}", ms / 1000, ms % 1000)
            }),
            ("Datum;u;y", |ms| {
                format!("25.11.2026 10:00:{:02},{:03}", ms / 1000, ms % 1000)
            }),
        ];
        for (header, stamp) in stamps {
            let separator = if header.contains(';') { ";" } else { "," };
            let mut text = format!("{header}\n");
            for n in 0..50u32 {
                let u = format!("{}", 0.5 * n as f64);
                let u = if separator == ";" {
                    u.replace('.', ",")
                } else {
                    u
                };
                text.push_str(&format!("{}{separator}{u}{separator}{n}\n", stamp(5 * n)));
            }
            let (record, used) =
                parse_record_with_columns(&text, Path::new("d.csv"), &timed_defaults())
                    .unwrap_or_else(|e| panic!("{header}: {e}"));
            assert!((record.sample_period - 0.005).abs() < 1e-12, "{header}");
            assert_eq!(record.input[49], 24.5, "{header}");
            assert_eq!(record.output[49], 49.0, "{header}");
            assert_eq!(
                used.time_unit.unwrap().source,
                "dates and times, from the first row's",
                "{header}"
            );
            // With --rate, a column of dates named as a time is no input.
            let record = parse_record(&text, Path::new("d.csv"), &rate_defaults(200.0)).unwrap();
            assert_eq!(record.input[49], 24.5, "{header}");
        }
    }

    #[test]
    fn refuses_dates_where_numbers_are_read_and_a_half_dated_time_column() {
        let mut text = String::from("stamp,u,y\n");
        for n in 0..40 {
            text.push_str(&format!(
                "2026-11-25 10:00:{:06.3},{n},{n}\n",
                n as f64 * 0.005
            ));
        }
        assert_eq!(
            message(&text, &rate_defaults(200.0)),
            "data.txt:2: field 0 (\"2026-11-25 10:00:00.000\") is a date and time in the input column; give it as the time column (--time 0), or give --rate and a header that names it a time (\"Date\", \"Time\")"
        );
        let mixed = text.replacen("2026-11-25 10:00:00.010", "0.01", 1);
        assert_eq!(
            message(&mixed, &timed_defaults()),
            "data.txt:4: field 0, the time column, is \"0.01\", but it holds dates and times from line 2: one time column is all dates and times or all numbers"
        );
    }

    /// A `Comment` column with text in some rows, rows with and without it,
    /// and X_Columns Multi (an X_Value before every channel): read by name
    /// and by the named-time default alike.
    #[test]
    fn reads_labview_comments_and_one_x_column_per_channel() {
        let plain = labview_file(".", 40);
        let mut text = String::new();
        for (n, line) in plain.lines().enumerate() {
            let row = match n {
                21 => "X_Value\tVoltage\tX_Value\tDisplacement\tComment".to_owned(),
                n if n > 21 => {
                    let f: Vec<&str> = line.split('\t').collect();
                    let comment = if n == 30 {
                        "\tstep here, µ"
                    } else if n % 2 == 0 {
                        "\t"
                    } else {
                        ""
                    };
                    format!("{}\t{}\t{}\t{}{comment}", f[0], f[1], f[0], f[2])
                }
                _ => line.to_owned(),
            };
            text.push_str(&row);
            text.push('\n');
        }
        for sampling in [
            Sampling::TimeColumn(Column::Name("X_Value".into())),
            Sampling::TimeColumn(Column::NamedTime),
        ] {
            let options = ReadOptions {
                sampling,
                ..timed_defaults()
            };
            let (record, used) = parse_record_with_columns(&text, Path::new("m.lvm"), &options)
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(record.input.len(), 40);
            assert!((record.output[39] - 11.7).abs() < 1e-12);
            assert!((record.sample_period - 0.005).abs() < 1e-12);
            assert_eq!(used.time.unwrap().index, 0);
            assert_eq!(used.output.name.as_deref(), Some("Displacement"));
            assert_eq!(
                used.time_unit.unwrap().source,
                "LabVIEW header: X_Dimension Time"
            );
        }
    }

    /// A logger's date and time of day in two columns: the time column is
    /// the time of day, the date column is passed over.
    #[test]
    fn a_date_column_beside_a_time_of_day_is_passed_over() {
        let mut text = String::from("Date\tTime\tu\ty\n");
        for n in 0..40 {
            text.push_str(&format!(
                "2026-11-25\t10:00:{:06.3}\t{}\t{}\n",
                n as f64 * 0.005,
                0.5 * n as f64,
                n
            ));
        }
        let options = ReadOptions {
            sampling: Sampling::TimeColumn(Column::Name("Time".into())),
            ..timed_defaults()
        };
        let (record, used) =
            parse_record_with_columns(&text, Path::new("d.txt"), &options).unwrap();
        assert!((record.sample_period - 0.005).abs() < 1e-12);
        assert_eq!((used.input.index, used.output.index), (2, 3));
        assert_eq!(record.input[39], 19.5);
        // With no sampling given, two columns named as times are a question.
        let options = ReadOptions {
            sampling: Sampling::TimeColumn(Column::NamedTime),
            ..timed_defaults()
        };
        assert_eq!(
            message(&text, &options),
            "data.txt:1: give the sampling: --time COLUMN or --rate HZ (the header names \"Date\", \"Time\" as times)"
        );
    }
}
