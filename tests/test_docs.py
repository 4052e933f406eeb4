"""README.md and docs/*.md hold together: every relative link leads to a file
of the repository and every #anchor to a heading of it, and every document
of measurements says when they were measured (a commit of this repository)
and how (a command block).

The figures themselves are checked by the tests that measure them again
(tests/docs_figures.py: docs/seed000.md in test_closed_loop.py,
docs/seed001.md in test_seed001_controller.py)."""

from __future__ import annotations

import re
import subprocess

import pytest

from tests.conftest import REPO_ROOT

DOCUMENTS = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
#: A command block, or a command in backticks.
COMMAND = re.compile(r"^```(?:sh|python)$|`(?:make|cargo|python3?|\.venv/bin/|target/release/|"
                     r"piezo-identify/benches/|farm-bench|PYTHONPATH=)[^`]*`", re.MULTILINE)
COMMIT = re.compile(r"`(?=[0-9a-f]*[a-f])([0-9a-f]{7,40})`")


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
