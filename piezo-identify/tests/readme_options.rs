//! The README's option tables are the options `--help` lists, subcommand by
//! subcommand: an option added, renamed or dropped without the README (or a
//! table listing options a subcommand refuses, as it once listed `--starts`
//! for `bouc-wen`) fails here.

use std::collections::BTreeSet;
use std::process::Command;

const SUBCOMMANDS: [&str; 7] = [
    "inverse-pi",
    "bouc-wen",
    "compare",
    "stage",
    "decoupling",
    "xy200s-preset",
    "lab-record",
];

/// The long options of `piezo-identify SUBCOMMAND --help` (without --help).
fn help_options(subcommand: &str) -> BTreeSet<String> {
    let output = Command::new(env!("CARGO_BIN_EXE_piezo-identify"))
        .args([subcommand, "--help"])
        .output()
        .expect("the binary runs");
    assert!(output.status.success());
    let help = String::from_utf8(output.stdout).unwrap();
    let options = help
        .split("Options:")
        .nth(1)
        .unwrap_or_else(|| panic!("{subcommand} --help has an Options section:\n{help}"));
    options
        .lines()
        .map(str::trim_start)
        // An option line starts with "-x, --name" or "--name"; wrapped
        // descriptions do not start with a dash.
        .filter(|line| line.starts_with('-'))
        .filter_map(|line| {
            let long = &line[line.find("--")? + 2..];
            let name: String = long
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                .collect();
            (name != "help" && name != "version").then_some(name)
        })
        .collect()
}

/// The options in the README's table under "#### `SUBCOMMAND` options".
fn readme_options(readme: &str, subcommand: &str) -> BTreeSet<String> {
    let heading = format!("#### `{subcommand}` options");
    let section = readme
        .split(&heading)
        .nth(1)
        .unwrap_or_else(|| panic!("README.md has no \"{heading}\""));
    let section = section.split("\n#").next().unwrap();
    section
        .lines()
        .filter_map(|line| line.strip_prefix("| `--"))
        .map(|rest| {
            rest.split(|c: char| !(c.is_alphanumeric() || c == '-'))
                .next()
                .unwrap()
                .to_owned()
        })
        .collect()
}

#[test]
fn readme_tables_list_exactly_the_options_of_help() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"))
        .expect("README.md beside Cargo.toml");
    let mut problems = Vec::new();
    for subcommand in SUBCOMMANDS {
        let help = help_options(subcommand);
        let table = readme_options(&readme, subcommand);
        assert!(!help.is_empty(), "{subcommand}: no option found in --help");
        let missing: Vec<_> = help.difference(&table).collect();
        let extra: Vec<_> = table.difference(&help).collect();
        if !missing.is_empty() || !extra.is_empty() {
            problems.push(format!(
                "{subcommand}: README lacks {missing:?}; README lists options --help does not have: {extra:?}"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The subcommands of `piezo-identify --help` are the tables' subcommands.
#[test]
fn every_subcommand_has_a_table() {
    let output = Command::new(env!("CARGO_BIN_EXE_piezo-identify"))
        .arg("--help")
        .output()
        .unwrap();
    let help = String::from_utf8(output.stdout).unwrap();
    let listed: BTreeSet<&str> = help
        .split("Commands:")
        .nth(1)
        .unwrap()
        .split("Options:")
        .next()
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .collect();
    assert_eq!(listed, SUBCOMMANDS.iter().copied().collect());
}
