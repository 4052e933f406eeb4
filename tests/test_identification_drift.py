"""docs/identification.md's drift of the P-885 test record: its commands run
from the repository's root as the document gives them (the identification
with `--predictions`, then its Python block), and every figure printed must
be the one the document shows (within one unit of the last printed digit),
so a stale trace fails. The run also checks `--predictions` against the
scoring: its scored part's RMS is the scored RMS the identification prints."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO_ROOT

DOC = REPO_ROOT / "docs" / "identification.md"
BINARY = REPO_ROOT / "target" / "release" / "piezo-identify"
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?")


def section() -> str:
    text = DOC.read_text(encoding="utf-8")
    start = text.index("### The drift of the P-885 test record")
    return text[start:text.index("\n### ", start + 1)]


def block(text: str, language: str) -> str:
    found = re.findall(rf"^```{language}\n(.*?)^```$", text, re.MULTILINE | re.DOTALL)
    assert len(found) == 1, f"docs/identification.md's drift section: {len(found)} {language} blocks"
    return found[0]


def test_the_documented_drift_is_what_the_commands_print(tmp_path):
    if not BINARY.is_file():
        pytest.fail(f"{BINARY} is missing: build the workspace", pytrace=False)
    text = section()
    lines = block(text, "sh").splitlines()
    assert lines[0] == "mkdir -p out/identify", lines[0]
    (REPO_ROOT / "out" / "identify").mkdir(parents=True, exist_ok=True)
    identification = " ".join(line.rstrip("\\").strip() for line in lines[1:4])
    assert identification.startswith("target/release/piezo-identify inverse-pi "), identification
    done = subprocess.run(identification.split(), cwd=REPO_ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    script = tmp_path / "drift.py"
    script.write_text(block(text, "python"))
    traced = subprocess.run([sys.executable, str(script)], cwd=REPO_ROOT, capture_output=True,
                            text=True, check=True).stdout
    print(traced)
    printed = block(text, "text")
    assert len(traced.splitlines()) == len(printed.splitlines()), \
        f"measured:\n{traced}\ndocumented:\n{printed}"
    for measured, documented in zip(traced.splitlines(), printed.splitlines()):
        assert NUMBER.sub("#", measured) == NUMBER.sub("#", documented), (measured, documented)
        for m, d in zip(NUMBER.findall(measured), NUMBER.findall(documented)):
            unit = 10.0 ** -len(d.split(".")[1]) if "." in d else 1.0
            assert abs(float(m) - float(d)) <= unit * 1.01, (measured, documented)
    scored = re.search(r"scored part \(not seen by the fit\).*\n\s+proposed\s+RMS \S+ V \(([0-9.]+) %\)",
                       done.stdout)
    assert scored, done.stdout
    assert f"RMS {scored.group(1)} %" in traced, (scored.group(1), traced)


def test_the_documented_halves_of_the_test_record_are_what_the_script_prints(tmp_path):
    """docs/identification.md says what each half of `--split 0.5` holds
    (a plain sine drive, then a drive shaped to make the displacement a sine):
    its script runs as printed and every figure must be the one shown."""
    from tests.docs_figures import stale_script_output

    measured, problems = stale_script_output(
        "identification.md", "### What the two halves of the P-885 test record hold", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)
