"""The figures of docs/*.md against the ones a test measures again.

A document's table is the record of a measurement; the tests that run the
same measurement anyway (the closed loop of seed 000's experiments, seed 001's
runs) compare each row they produce with the row the document prints, so a
figure left stale after a change of the models or presets fails the test that
measured it.

Rows are matched by their leading label cells; every other cell must hold
the same numbers. A number matches when it is within 1 % of the printed one
or within one unit of its last printed digit, whichever is wider: the runs
are deterministic, so only a real change, or a last-bit difference of a C
library's exp/pow between machines, moves them.
"""

from __future__ import annotations

import math
import pathlib
import re

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = REPO_ROOT / "docs"

#: A number as the documents print it: `-1.4e-13`, `−2.3e-13` (a minus sign),
#: `0.19`, `1,000,011` (thousands separated by commas). tests/docs_figures.rs
#: reads them the same way for the Rust tests.
NUMBER = re.compile(r"[-+−]?(?:\d{1,3}(?:,\d{3})+(?!\d)(?:\.\d*)?|\d+\.\d*|\.\d+|\d+)(?:[eE][-+−]?\d+)?")
RELATIVE = 0.01


def table_rows(lines) -> list[list[str]]:
    """The cells of every row of every Markdown table in `lines` (header and
    separator rows left out)."""
    rows = []
    for line in lines:
        line = line.strip()
        if not (line.startswith("|") and line.endswith("|")):
            continue
        cells = [cell.strip() for cell in line[1:-1].split("|")]
        if all(re.fullmatch(r":?-{3,}:?", cell) for cell in cells):
            rows.pop()  # the header row just read
        else:
            rows.append(cells)
    return rows


def doc_rows(name: str) -> list[list[str]]:
    path = DOCS / name
    return table_rows(path.read_text(encoding="utf-8").splitlines())


def numbers(text: str) -> list[tuple[float, float]]:
    """(value, unit of the last printed digit) of every number in `text`."""
    found = []
    for literal in NUMBER.findall(text):
        literal = literal.replace("−", "-").replace(",", "")
        mantissa, _, exponent = literal.lower().partition("e")
        decimals = len(mantissa.partition(".")[2])
        unit = 10.0 ** (-decimals + (int(exponent) if exponent else 0))
        found.append((float(literal), unit))
    return found


def same_numbers(printed: str, measured: str, relative: float = RELATIVE) -> bool:
    """The rule above; `relative` = 0 for figures a deterministic run
    reproduces to the last printed digit."""
    a, b = numbers(printed), numbers(measured)
    if len(a) != len(b):
        return False
    return all(
        math.isclose(p, m, rel_tol=relative, abs_tol=unit * (1 + 1e-9))
        for (p, unit), (m, _) in zip(a, b)
    )


def stale_rows(documented: list[list[str]], measured: list[list[str]], key_cells: int,
               document: str) -> list[str]:
    """What differs between the document's rows and the measured ones, matched
    by their first `key_cells` cells; every measured row must be documented."""
    by_key = {tuple(row[:key_cells]): row for row in documented}
    problems = []
    for row in measured:
        key = tuple(row[:key_cells])
        printed = by_key.get(key)
        if printed is None:
            problems.append(f"{document}: no row {' | '.join(key)!r}; measured: {' | '.join(row)}")
            continue
        for index, (p, m) in enumerate(zip(printed, row)):
            if index >= key_cells and not same_numbers(p, m):
                problems.append(f"{document}: {' | '.join(key)}: printed {p!r}, measured {m!r}")
    return problems


#: Powers of ten as the documents print them in prose (`2.1·10⁻¹⁵`).
SUPERSCRIPTS = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")
POWER_OF_TEN = re.compile(r"\s*[·×]\s*10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)")


def plain_powers(text: str) -> str:
    """`2.1·10⁻¹⁵` as `2.1e-15`, so that numbers() reads it as one number."""
    return POWER_OF_TEN.sub(lambda m: "e" + m.group(1).translate(SUPERSCRIPTS), text)


def stale_prose(document: str, pattern: str, measured: str, figure: str,
                exact: bool = False) -> list[str]:
    """What differs between a figure a document prints in its text and the
    one measured: `pattern` (a regular expression with one group, the
    printed figure) is searched in docs/<document> with its line breaks read
    as spaces, and every occurrence must hold the measured numbers (the rule
    above; `exact`: the same text, for a list of names). A pattern that no
    longer matches is a problem too: the sentence was rewritten without its
    figure."""
    text = " ".join((DOCS / document).read_text(encoding="utf-8").split())
    printed = re.findall(pattern, text)
    if not printed:
        return [f"docs/{document}: {figure}: not found (pattern {pattern!r}); measured: {measured}"]
    problems = []
    for figure_text in printed:
        same = (figure_text == measured if exact
                else same_numbers(plain_powers(figure_text), plain_powers(measured)))
        if not same:
            problems.append(f"docs/{document}: {figure}: printed {figure_text!r}, measured {measured!r}")
    return problems


def section_of(document: str, heading: str) -> str:
    """The text of docs/<document> from the line `heading` (a Markdown
    heading, e.g. "### Why ...") to the next heading of its level or above,
    headings inside fenced blocks (a shell comment) not counted."""
    text = (DOCS / document).read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    level = len(heading) - len(heading.lstrip("#"))
    try:
        first = next(i for i, line in enumerate(lines) if line.rstrip("\n") == heading)
    except StopIteration:
        raise AssertionError(f"docs/{document}: no heading {heading!r}") from None
    fenced = False
    for end in range(first + 1, len(lines)):
        if lines[end].startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"#{1,%d} " % level, lines[end]):
            return "".join(lines[first:end])
    return "".join(lines[first:])


def stale_script_output(document: str, heading: str, scratch: pathlib.Path) -> tuple[str, list[str]]:
    """(what it printed, what differs) when the one ```python script of the
    section `heading` of docs/<document> runs as printed, from the
    repository's root, against the one ```text block of the section (its
    output as the document shows it): every line the same but for its
    numbers; a number with decimals or an exponent within one unit of its
    last printed digit (a last-bit difference of libm may move it), an
    integer (a count, a label) exactly."""
    import os
    import subprocess
    import sys

    section = section_of(document, heading)
    python = re.findall(r"^```python\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)
    printed = re.findall(r"^```text\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)
    if len(python) != 1 or len(printed) != 1:
        return "", [f"docs/{document}, {heading}: {len(python)} scripts and {len(printed)} "
                    "outputs, one of each expected"]
    script = scratch / "documented_script.py"
    script.write_text(python[0], encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], cwd=REPO_ROOT, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    if done.returncode != 0:
        return done.stdout, [f"docs/{document}, {heading}: the script exited with "
                             f"{done.returncode}:\n{done.stderr[-3000:]}"]
    got, shown = done.stdout.splitlines(), printed[0].splitlines()
    if len(got) != len(shown):
        return done.stdout, [f"docs/{document}, {heading}: {len(shown)} lines shown, "
                             f"{len(got)} printed"]
    problems = []
    for line, doc_line in zip(got, shown):
        measured, documented = numbers(line), numbers(doc_line)
        same = (NUMBER.sub("#", line) == NUMBER.sub("#", doc_line)
                and len(measured) == len(documented)
                and all(abs(m - d) <= (unit * (1 + 1e-9) if re.search(r"[.eE]", literal) else 0.0)
                        for (m, _), (d, unit), literal
                        in zip(measured, documented, NUMBER.findall(doc_line))))
        if not same:
            problems.append(f"docs/{document}, {heading}: shown {doc_line!r}, printed {line!r}")
    return done.stdout, problems
