"""Every code block of README.md that can run here runs, from the
repository's root, as a user would paste it: so the README cannot drift from
the FMUs, the files `make fmus` writes and the APIs it shows.

A ```python or ```sh block runs unless the line right above its fence says
`<!-- readme-test: not run (why) -->`, with the reason; blocks without a
language (logs, output) are text. The test fails on a block that raises or
exits non-zero, and on a marker without a reason.
"""

from __future__ import annotations

import pathlib
import re
import subprocess
import sys

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
README = REPO_ROOT / "README.md"
RUNNERS = {"python": [sys.executable, "-c"], "sh": ["bash", "-euo", "pipefail", "-c"]}
NOT_RUN = re.compile(r"^<!-- readme-test: not run \((?P<why>[^)]+)\) -->$")


def blocks() -> list[tuple[int, str, str, str | None]]:
    """(line of the opening fence, language, code, reason not run) of each
    fenced block."""
    lines = README.read_text(encoding="utf-8").splitlines()
    found = []
    i = 0
    while i < len(lines):
        fence = re.match(r"^```(\w*)\s*$", lines[i])
        if not fence:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        marker = NOT_RUN.match(lines[i - 1]) if i > 0 else None
        if i > 0 and lines[i - 1].startswith("<!-- readme-test") and not marker:
            pytest.fail(f"README.md:{i}: malformed marker {lines[i - 1]!r}", pytrace=False)
        found.append((i + 1, fence.group(1), "\n".join(lines[i + 1:end]),
                      marker.group("why") if marker else None))
        i = end + 1
    return found


def runnable() -> list[tuple[int, str, str]]:
    return [(line, language, code) for line, language, code, why in blocks()
            if language in RUNNERS and why is None]


def test_every_block_runs_or_says_why_not():
    kinds = {language for _, language, _, _ in blocks()}
    assert kinds <= set(RUNNERS) | {"", "lua"}, f"a block in a language nobody runs: {kinds}"
    for line, language, _, why in blocks():
        if language and language not in RUNNERS:
            assert why, f"README.md:{line}: a ```{language} block needs a not-run marker"
    # The fmpy, Model Exchange, container and libcosim snippets at least.
    assert len([b for b in runnable() if b[1] == "python"]) >= 4


@pytest.mark.parametrize(("line", "language", "code"), runnable(),
                         ids=[f"README.md:{b[0]}" for b in runnable()])
def test_block_runs(line, language, code):
    for path in re.findall(r"dist/[\w.]+\.(?:fmu|ssp)", code):
        if not (REPO_ROOT / path).is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    for path in re.findall(r"target/release/[\w-]+", code):
        if not (REPO_ROOT / path).is_file():
            pytest.fail(f"{path} is missing: run `cargo build --release --locked` first",
                        pytrace=False)
    done = subprocess.run([*RUNNERS[language], code], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, (
        f"README.md:{line} ({language}) exited with {done.returncode}:\n"
        f"{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    )
