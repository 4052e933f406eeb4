"""README.md and docs/*.md hold together: every relative link leads to a file
of the repository and every #anchor to a heading of it, and every document
of measurements says when they were measured (a commit of this repository)
and how (a command block).

Every table of figures in docs/ says, above it in its section (or in the
document's opening paragraphs), the commit it was measured at: "measured at
commit `abc1234`"; a table whose nearest such statement says "measured
before" fails.

The figures themselves are checked by the tests that measure them again
(tests/docs_figures.py and tests/docs_figures.rs: docs/seed000.md in
test_closed_loop.py, docs/seed001.md in test_seed001_controller.py, the fmpy
table of docs/fmi.md in test_model_exchange.py; the Rust table of docs/fmi.md
in fmu-plant/tests/model_exchange.rs, the fuzz and memory tables of
docs/robustness.md in the fmi_fuzz tests and fmi2-conformance/tests/memory.rs,
the P-885 rows of docs/identification.md in
piezo-identify/tests/quality_bars.rs, the FMU-state restores of docs/fmi.md
in the FMU crates' abi_conformance tests, the table of docs/presets.md in
test_presets.py, the binaries' and importers' figures of docs/platforms.md in
test_linux_binaries.py, test_windows_binaries.py and test_importers.py); the counts of tests/test_parameter_ranges.py that
docs/robustness.md prints are checked here, and so are the README's
headlines: each number of its Figures section is one its document prints."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO_ROOT

DOCUMENTS = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
#: A command block, or a command in backticks.
COMMAND = re.compile(r"^```(?:sh|python)$|`(?:make|cargo|python3?|\.venv/bin/|target/release/|"
                     r"piezo-identify/benches/|farm-bench|PYTHONPATH=)[^`]*`", re.MULTILINE)
COMMIT = re.compile(r"`(?=[0-9a-f]*[a-f])([0-9a-f]{7,40})`")
#: When a block of figures was measured: at a commit, or (stale) before one.
MEASURED = re.compile(r"[Mm]easured (?:again )?(at|before) (?:commit )?`[0-9a-f]{7,40}`")
#: Tables of figures waiting to be measured again at a commit, by (document,
#: section heading): the speed figures, which are measured on a quiet machine
#: (docs/speed.md says how), still carry the commit they were measured
#: before.
AWAITING_MEASUREMENT: set[tuple[str, str]] = set()


def prose(text: str) -> list[str]:
    """The lines outside fenced code blocks."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line)
    return lines


def anchors(path) -> set[str]:
    """GitHub's anchors of a Markdown file's headings: lower case, punctuation
    dropped, spaces to hyphens, a repeated one numbered."""
    found, counts = set(), {}
    for line in prose(path.read_text(encoding="utf-8")):
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not heading:
            continue
        slug = re.sub(r"[^\w\- ]", "", heading.group(1).lower()).replace(" ", "-")
        repeats = counts.get(slug, 0)
        counts[slug] = repeats + 1
        found.add(slug if repeats == 0 else f"{slug}-{repeats}")
    return found


@pytest.mark.parametrize("document", [*DOCUMENTS, REPO_ROOT / "ARCHITECTURE.md"],
                         ids=lambda p: p.relative_to(REPO_ROOT).as_posix())
def test_every_link_resolves(document):
    broken = []
    for number, line in enumerate(document.read_text(encoding="utf-8").splitlines(), 1):
        for target in LINK.findall(line):
            if re.match(r"^[a-z]+://|^mailto:", target):
                continue
            path_part, _, anchor = target.partition("#")
            path = (document.parent / path_part).resolve() if path_part else document
            if not path.exists():
                broken.append(f"{document.name}:{number}: {target}: no such file")
            elif anchor and path.suffix == ".md" and anchor not in anchors(path):
                broken.append(f"{document.name}:{number}: {target}: no such heading")
    assert not broken, "\n".join(broken)


def _in_history(commit: str) -> bool | None:
    """Whether `commit` is an object of this repository (None: no git here)."""
    try:
        done = subprocess.run(["git", "-C", str(REPO_ROOT), "cat-file", "-e", f"{commit}^{{commit}}"],
                              capture_output=True)
    except FileNotFoundError:
        return None
    shallow = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "--is-shallow-repository"],
                             capture_output=True, text=True)
    if shallow.returncode != 0 or shallow.stdout.strip() != "false":
        return None
    return done.returncode == 0


@pytest.mark.parametrize("document", DOCUMENTS[1:], ids=lambda p: p.relative_to(REPO_ROOT).as_posix())
def test_every_document_of_figures_says_when_and_how(document):
    text = document.read_text(encoding="utf-8")
    assert COMMAND.search(text), f"{document.name}: names no command that measures its figures"
    commits = set(COMMIT.findall(text))
    assert commits, f"{document.name}: names no commit the figures were measured at"
    unknown = [c for c in sorted(commits) if _in_history(c) is False]
    assert not unknown, f"{document.name}: not commits of this repository: {unknown}"


def figure_tables(text: str) -> list[tuple[int, str, str, str]]:
    """(line, section heading, the section's text above the table, the
    document's text above its first section) of every table with a number in
    its body; a section is what follows a heading of level 1 or 2."""
    lines = text.splitlines()
    first_section = next((i for i, line in enumerate(lines) if line.startswith("## ")), len(lines))
    preamble = " ".join(lines[:first_section])
    found, fenced, heading, section_start, in_table = [], False, "", 0, False
    for number, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
        if fenced:
            continue
        level = re.match(r"^(#{1,6})\s+(.*?)\s*$", line)
        if level and len(level.group(1)) <= 2:
            heading, section_start = level.group(2), number
        is_row = line.strip().startswith("|")
        if is_row and not in_table:
            table_end = number  # index of the first line after the table
            while table_end < len(lines) and lines[table_end].strip().startswith("|"):
                table_end += 1
            # lines[number] is the separator row; the body follows it.
            if any(re.search(r"\d", row) for row in lines[number + 1:table_end]):
                found.append((number, heading, " ".join(lines[section_start:number - 1]), preamble))
        in_table = is_row
    return found


def unmeasured_tables(name: str, text: str) -> list[str]:
    """The tables of figures of a document that say no commit they were
    measured at (see the module's docstring)."""
    problems = []
    for line, heading, above, preamble in figure_tables(text):
        if (name, heading) in AWAITING_MEASUREMENT:
            continue
        statements = MEASURED.findall(above) or MEASURED.findall(preamble)
        if not statements:
            problems.append(f"{name}:{line}: a table of figures with no \"measured at commit `...`\" "
                            f"above it in its section ({heading!r}) or at the top of the document")
        elif statements[-1] == "before":
            problems.append(f"{name}:{line}: the figures of {heading!r} were measured before a commit, "
                            f"not at one: measure them again and say the commit")
    return problems


@pytest.mark.parametrize("document", sorted((REPO_ROOT / "docs").glob("*.md")),
                         ids=lambda p: p.relative_to(REPO_ROOT).as_posix())
def test_every_table_of_figures_says_the_commit_it_was_measured_at(document):
    problems = unmeasured_tables(document.name, document.read_text(encoding="utf-8"))
    assert not problems, "\n".join(problems)


def test_a_table_without_its_commit_is_found():
    """The rule above catches a table left without its commit, and one
    measured before a commit."""
    table = ["| what | value |", "|---|---|", "| speed | 12 ms |"]
    measured = ["# Figures", "", "## Speed", "", "Measured at commit `abc1234`:", "", *table]
    assert not unmeasured_tables("x.md", "\n".join(measured))
    at_top = ["# Figures", "", "Every figure was measured at commit `abc1234`.", "", "## Speed", *table]
    assert not unmeasured_tables("x.md", "\n".join(at_top))
    missing = ["# Figures", "", "## Speed", "", *table]
    assert unmeasured_tables("x.md", "\n".join(missing))
    stale = ["# Figures", "", "## Speed", "", "Measured before commit `abc1234`:", "", *table]
    assert unmeasured_tables("x.md", "\n".join(stale))
    elsewhere = ["# Figures", "", "## Other", "Measured at `abc1234`.", "## Speed", "", *table]
    assert unmeasured_tables("x.md", "\n".join(elsewhere))


def section_text(document: str, heading: str) -> str:
    """The prose of the `## heading` section of docs/<document>, as one line."""
    lines = prose((REPO_ROOT / "docs" / document).read_text(encoding="utf-8"))
    start = lines.index(f"## {heading}") + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("## ")), len(lines))
    return " ".join(" ".join(lines[start:end]).split())


#: What docs/robustness.md says tests/test_parameter_ranges.py checks: the
#: phrase holding each count, by what is counted.
PARAMETER_RANGE_COUNTS = {
    "values outside a declared range": r"sets (\d+) values outside a declared range",
    "parameters that declare a range": r"on the (\d+) parameters of both FMUs that declare one",
    "physical-range cases": r"(\d+) physical-range cases",
    "sample periods": r"(\d+) sample periods that are not a positive finite number",
    "diverging Bouc-Wen states": r"(\d+) diverging Bouc-Wen states",
    "overflowing controller outputs": r"(\d+) controller outputs? that overflows?",
    "tests": r"tests/test_parameter_ranges\.py`: (\d+) tests",
}


def printed_number(text: str) -> float:
    """A value as the documents print it: `0`, `−1e-4`, `NaN`, `∞`."""
    return float(text.strip().replace("−", "-").replace("∞", "inf"))


def test_parameter_range_counts_are_the_ones_the_tests_run():
    """docs/robustness.md counts what tests/test_parameter_ranges.py checks;
    the counts are taken again from what pytest collects in that module and
    from the declared ranges of dist/*.fmu, through the module's own
    functions, so a case added or a range declared there without the text
    following fails here."""
    from types import SimpleNamespace

    import fmpy

    from tests import test_parameter_ranges as ranges

    collected = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
         "tests/test_parameter_ranges.py"], cwd=REPO_ROOT, capture_output=True, text=True)
    assert collected.returncode == 0, collected.stdout + collected.stderr
    tests = [line.partition("::")[2] for line in collected.stdout.splitlines()
             if line.startswith("tests/test_parameter_ranges.py::")]

    def run(prefix: str) -> int:
        return sum(1 for test in tests if test.startswith(prefix))

    declared = []
    for name in ranges.MODELS:
        path = REPO_ROOT / "dist" / f"{name}.fmu"
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
        declared += ranges.declared_ranges(SimpleNamespace(md=fmpy.read_model_description(str(path))))
    measured = {
        "values outside a declared range": sum(len(ranges.outside(v)) for v in declared),
        "parameters that declare a range": len(declared),
        "physical-range cases": run("test_parameters_out_of_physical_range_are_refused["),
        "sample periods": run("test_controller_sample_period_must_be_positive["),
        "diverging Bouc-Wen states": run("test_diverging_hysteresis_"),
        "overflowing controller outputs": run("test_overflowing_controller_output"),
        "tests": len(tests),
    }
    heading = "Parameters out of range and diverging states"
    text = section_text("robustness.md", heading)
    problems = []
    for what, phrase in PARAMETER_RANGE_COUNTS.items():
        printed = re.search(phrase, text)
        if not printed:
            problems.append(f"no longer says /{phrase}/ (measured: {measured[what]} {what})")
        elif int(printed.group(1)) != measured[what]:
            problems.append(f"prints {printed.group(0)!r}; tests/test_parameter_ranges.py has "
                            f"{measured[what]} {what}")
    periods = re.search(r"not a positive finite number \(([^)]*)\)", text)
    if not periods or [repr(printed_number(p)) for p in periods.group(1).split(",")] != [
            repr(float(p)) for p in ranges.SAMPLE_PERIODS]:
        problems.append(f"prints the sample periods {periods and periods.group(1)!r}; the test "
                        f"sets {ranges.SAMPLE_PERIODS}")
    assert not problems, (
        f"docs/robustness.md ({heading!r}) does not count what tests/test_parameter_ranges.py "
        "runs: count again with the commands it gives and print the counts with the commit\n"
        + "\n".join(problems))


def headline_figures() -> list[tuple[str, str]]:
    """(document, text) of each bullet of README.md's Figures section: a
    headline of one document of docs/, linked at its start."""
    text = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("\n## Figures\n") + len("\n## Figures\n"):]
    following = re.search(r"^#{1,2} ", section, re.MULTILINE)
    section = section[:following.start()] if following else section
    bullets = re.split(r"^- ", section, flags=re.MULTILINE)[1:]
    headlines = []
    for bullet in bullets:
        linked = re.match(r"\[[^\]]*\]\((docs/[^)#]+)[^)]*\):(.*)", bullet, re.DOTALL)
        assert linked, f"README.md, Figures: a bullet that does not start [Name](docs/X.md): {bullet!r}"
        headlines.append((linked.group(1), " ".join(linked.group(2).split())))
    return headlines


def test_readme_headlines_are_figures_of_their_documents():
    """The README gives each document's headline figures only: every number
    of a Figures bullet must be printed in the document it links to (read as
    docs_figures reads numbers; without their signs, which the README may
    put in words: "cuts by 96.6 %" for "-96.6 %"). This finds a figure no
    document holds, or one its document no longer prints; it cannot tell a
    current figure from an older one the document keeps with its commit."""
    from tests.docs_figures import NUMBER, plain_powers

    def values(text: str) -> set[str]:
        return {literal.lstrip("+-−").replace(",", "")
                for literal in NUMBER.findall(plain_powers(text))}

    bullets = headline_figures()
    assert len(bullets) >= 8, f"the README's Figures section lost its bullets: {bullets}"
    problems = []
    for document, body in bullets:
        printed = values((REPO_ROOT / document).read_text(encoding="utf-8"))
        for figure in sorted(values(body) - printed):
            problems.append(f"README.md, Figures, {document}: {figure} is not in {document}")
    assert not problems, "\n".join(problems)
