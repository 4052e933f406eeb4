//! The figures of `docs/*.md` against the ones a Rust test measures again:
//! the Rust side of `tests/docs_figures.py`, with the same rule, so that a
//! figure left stale after a change of a model, the layer or the fuzzer
//! fails the test that measured it.
//!
//! A test includes this file (`#[path = "../../tests/docs_figures.rs"] mod
//! docs_figures;`), builds the table rows it measured in the document's
//! format, and [`assert_documented`] finds the table that follows a marker
//! line of the document and compares the rows, matched by their leading label
//! cells. A number matches when it is within 1 % of the printed one or within
//! one unit of its last printed digit, whichever is wider: the runs are
//! deterministic, so only a real change, or a last-bit difference of a C
//! library's exp/pow between machines, moves them. A cell measured as `None`
//! (a time, which varies from run to run) is not compared.
#![allow(dead_code)] // each test uses what it needs

use std::path::PathBuf;

/// Relative tolerance of a printed figure.
pub const RELATIVE: f64 = 0.01;

/// `docs/<name>` of the repository the including crate belongs to.
pub fn document_path(name: &str) -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let root = manifest
        .ancestors()
        .find(|dir| dir.join("docs").is_dir() && dir.join("Cargo.lock").is_file())
        .unwrap_or_else(|| panic!("no docs/ above {}", manifest.display()));
    root.join("docs").join(name)
}

/// The cells of every row of the first Markdown table after the first line
/// of `text` that contains `marker` (its header and separator rows left out).
pub fn table_after(text: &str, marker: &str) -> Option<Vec<Vec<String>>> {
    let mut lines = text.lines().skip_while(|line| !line.contains(marker));
    lines.next()?;
    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut started = false;
    for line in lines {
        let line = line.trim();
        if !(line.starts_with('|') && line.ends_with('|') && line.len() > 1) {
            if started {
                break;
            }
            continue;
        }
        started = true;
        let cells: Vec<String> = line[1..line.len() - 1]
            .split('|')
            .map(|cell| cell.trim().to_owned())
            .collect();
        let separator = cells.iter().all(|cell| {
            let dashes = cell.trim_start_matches(':').trim_end_matches(':');
            dashes.len() >= 3 && dashes.chars().all(|c| c == '-')
        });
        if separator {
            rows.pop(); // the header row just read
        } else {
            rows.push(cells);
        }
    }
    started.then_some(rows)
}

/// (value, unit of the last printed digit) of every number in `text`:
/// `-1.4e-13`, `−2.3e-13` (a minus sign), `0.19`, `1,000,011` (thousands
/// separated by commas) and `790` each count as one.
pub fn numbers(text: &str) -> Vec<(f64, f64)> {
    let chars: Vec<char> = text.chars().collect();
    let digits_from = |mut i: usize| {
        while i < chars.len() && chars[i].is_ascii_digit() {
            i += 1;
        }
        i
    };
    let mut found = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let starts_number = chars[i].is_ascii_digit()
            || (chars[i] == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit));
        if !starts_number {
            i += 1;
            continue;
        }
        let negative = i > 0 && matches!(chars[i - 1], '-' | '−');
        let mut end = digits_from(i);
        // Thousands: after at most three digits, each comma followed by
        // exactly three.
        if end - i <= 3 {
            while chars.get(end) == Some(&',') && digits_from(end + 1) == end + 4 {
                end += 4;
            }
        }
        let mut mantissa: String = chars[i..end].iter().filter(|&&c| c != ',').collect();
        let mut decimals = 0i32;
        if chars.get(end) == Some(&'.') {
            let fraction_end = digits_from(end + 1);
            decimals = (fraction_end - end - 1) as i32;
            mantissa.push('.');
            mantissa.extend(&chars[end + 1..fraction_end]);
            end = fraction_end;
        }
        let mut exponent = 0i32;
        if matches!(chars.get(end), Some('e' | 'E')) {
            let sign_at = end + 1;
            let (negative_exponent, digits_at) = match chars.get(sign_at) {
                Some('-' | '−') => (true, sign_at + 1),
                Some('+') => (false, sign_at + 1),
                _ => (false, sign_at),
            };
            let exponent_end = digits_from(digits_at);
            if exponent_end > digits_at {
                let digits: String = chars[digits_at..exponent_end].iter().collect();
                exponent = digits.parse::<i32>().expect("digits");
                if negative_exponent {
                    exponent = -exponent;
                }
                end = exponent_end;
            }
        }
        let magnitude: f64 = format!("{mantissa}e{exponent}").parse().expect("a number");
        let value = if negative { -magnitude } else { magnitude };
        found.push((value, 10f64.powi(exponent - decimals)));
        i = end;
    }
    found
}

/// Whether `printed` and `measured` hold the same numbers, within the rule.
pub fn same_numbers(printed: &str, measured: &str) -> bool {
    same_numbers_within(printed, measured, RELATIVE)
}

/// [`same_numbers`] with another relative tolerance than 1 %.
pub fn same_numbers_within(printed: &str, measured: &str, relative: f64) -> bool {
    let (a, b) = (numbers(printed), numbers(measured));
    a.len() == b.len()
        && a.iter().zip(&b).all(|(&(p, unit), &(m, _))| {
            let tolerance = (relative * p.abs().max(m.abs())).max(unit * (1.0 + 1e-9));
            (p - m).abs() <= tolerance
        })
}

/// A measured row: `label`, then `cells`, those at the indices `uncompared`
/// (of `cells`) left out of the comparison.
pub fn row(label: &str, cells: Vec<String>, uncompared: &[usize]) -> Vec<Option<String>> {
    std::iter::once(Some(label.to_owned()))
        .chain(
            cells
                .into_iter()
                .enumerate()
                .map(|(i, cell)| (!uncompared.contains(&i)).then_some(cell)),
        )
        .collect()
}

/// What differs between the table after `marker` in `docs/<document>` and
/// the `measured` rows, matched by their first `key_cells` cells; every
/// measured row must be printed there.
pub fn stale_rows(
    document: &str,
    marker: &str,
    key_cells: usize,
    measured: &[Vec<Option<String>>],
    relative: f64,
) -> Vec<String> {
    let path = document_path(document);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let Some(documented) = table_after(&text, marker) else {
        return vec![format!("docs/{document}: no table after {marker:?}")];
    };
    let mut problems = Vec::new();
    for row in measured {
        let key: Vec<&str> = row[..key_cells]
            .iter()
            .map(|cell| cell.as_deref().expect("a label cell"))
            .collect();
        let Some(printed) = documented
            .iter()
            .find(|printed| printed.len() >= key_cells && printed[..key_cells] == key[..])
        else {
            problems.push(format!(
                "docs/{document}: no row {:?} after {marker:?}; measured: {row:?}",
                key.join(" | ")
            ));
            continue;
        };
        if printed.len() != row.len() {
            problems.push(format!(
                "docs/{document}: {}: {} cells printed, {} measured",
                key.join(" | "),
                printed.len(),
                row.len()
            ));
            continue;
        }
        for (p, m) in printed.iter().zip(row).skip(key_cells) {
            if m.as_deref()
                .is_some_and(|m| !same_numbers_within(p, m, relative))
            {
                problems.push(format!(
                    "docs/{document}: {}: printed {p:?}, measured {:?}",
                    key.join(" | "),
                    m.as_deref().unwrap_or_default()
                ));
            }
        }
    }
    problems
}

/// Panics, naming every stale figure, unless `docs/<document>` prints the
/// `measured` rows in the table after `marker` (see [`stale_rows`]).
pub fn assert_documented(
    document: &str,
    marker: &str,
    key_cells: usize,
    measured: &[Vec<Option<String>>],
) {
    assert_documented_within(document, marker, key_cells, measured, RELATIVE);
}

/// [`assert_documented`] with another relative tolerance than 1 %, for a
/// figure that varies a little from run to run (the document says so).
pub fn assert_documented_within(
    document: &str,
    marker: &str,
    key_cells: usize,
    measured: &[Vec<Option<String>>],
    relative: f64,
) {
    let problems = stale_rows(document, marker, key_cells, measured, relative);
    assert!(
        problems.is_empty(),
        "the figures in docs/{document} are not the ones measured (within {} % or one unit \
         of the last printed digit): measure them again with the command the document gives \
         and print them with the commit\n{}",
        relative * 100.0,
        problems.join("\n")
    );
}

/// `text` with every run of white space (a line break included) as one
/// space, so that a phrase can be found across the lines it is wrapped over.
fn one_line(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The prose of `docs/<document>` between the first `after` and the last
/// `before` ahead of it, read as one line (see [`one_line`]); `None` when the
/// document does not say them.
pub fn text_between(document: &str, before: &str, after: &str) -> Option<String> {
    let path = document_path(document);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let text = one_line(&text);
    let (before, after) = (one_line(before), one_line(after));
    let end = text.find(&after)?;
    let start = text[..end].rfind(&before)? + before.len();
    Some(text[start..end].trim().to_owned())
}

/// Panics, naming the document, the figure printed and the one measured,
/// unless the text between `before` and `after` in `docs/<document>` holds
/// exactly the numbers of `measured`: for counts, which a run makes exactly
/// (a case more or less is a change, not a rounding).
pub fn assert_count_documented(document: &str, before: &str, after: &str, measured: &str) {
    let Some(printed) = text_between(document, before, after) else {
        panic!("docs/{document} no longer says {before:?} ... {after:?}; measured: {measured:?}")
    };
    let values = |text: &str| {
        numbers(text)
            .into_iter()
            .map(|(value, _)| value)
            .collect::<Vec<_>>()
    };
    assert!(
        values(&printed) == values(measured),
        "docs/{document} prints {printed:?} (between {before:?} and {after:?}), the run \
         counted {measured:?}: measure it again with the command the document gives and print \
         it with the commit"
    );
}

#[cfg(test)]
mod rule {
    use super::*;

    #[test]
    fn numbers_are_read_as_printed() {
        let read = |text: &str| {
            numbers(text)
                .into_iter()
                .map(|(v, _)| v)
                .collect::<Vec<_>>()
        };
        assert_eq!(read("span −1.4e-13, width 1.4e-11 µm"), [-1.4e-13, 1.4e-11]);
        assert_eq!(
            read("1,000,011 calls, 7,195 / 677"),
            [1_000_011.0, 7195.0, 677.0]
        );
        assert_eq!(read("790 Hz in both"), [790.0]);
        assert_eq!(read("3,608 / 3,668 kB"), [3608.0, 3668.0]);
        assert!(same_numbers("2.2e-9 µm", "2.3e-9 µm"));
        assert!(!same_numbers("2.2e-9 µm", "2.4e-9 µm"));
        assert!(same_numbers("172,618", "173,000"));
        assert!(!same_numbers("172,618", "175,000"));
        assert!(!same_numbers("236", "240"));
        assert!(same_numbers("0 / 0", "0 / 1"));
    }
}
