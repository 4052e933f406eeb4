"""The FlexureStage defaults reproduce seed 000's stage (issue: fingerprint
table), measured through the packaged FMU.

The procedures and seed 000's targets are written once, in
piezo-models/src/fingerprint.rs; `plant-fingerprints` (piezo-identify) runs
them on dist/FlexureStage.fmu through the FMI 2.0 C ABI (the importer crate
fmi2-import), and this test checks what it reports. `pytest -s` prints every
row beside its target.
"""

from __future__ import annotations

import json
import subprocess

import pytest

from tests.conftest import REPO_ROOT, require_fmu

BINARY = REPO_ROOT / "target" / "release" / "plant-fingerprints"


def require_binary():
    if not BINARY.is_file():
        pytest.fail(f"{BINARY} is missing: run `make fingerprints-tool` (or `make test`)",
                    pytrace=False)
    return BINARY


def run_tool(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(require_binary()), *args], capture_output=True, text=True,
                          timeout=1200)


@pytest.fixture(scope="module")
def measured():
    done = run_tool("--fmu", str(require_fmu()), "--json")
    # 0: every check holds, 1: one fails (still a full report); 2: no report.
    assert done.returncode in (0, 1), done.stderr
    return json.loads(done.stdout), done.returncode


def test_every_fingerprint_is_within_its_tolerance(measured):
    document, returncode = measured
    checks = document["checks"]
    for check in checks:
        error = check["relative_error"]
        paper = check["rule"] if check["paper"] is None else f"{check['paper']:.5g} {check['unit']}"
        print(f"\n{check['name']}: measured {check['measured']:.5g} {check['unit']}, paper "
              f"{paper}" + ("" if error is None else f" ({error:+.1%}, tolerance {check['rule']})"))
    failing = [f"{c['name']}: {c['measured']:.5g} {c['unit']} ({c['paper']}, {c['rule']})"
               for c in checks if not c["within"]]
    assert not failing, "\n".join(failing)
    assert returncode == 0


def test_the_verdicts_follow_from_the_reported_numbers(measured):
    """The tool's verdict of each target row is its own numbers' (the
    relative error of measured to paper against the tolerance), so a
    mislabelled row cannot pass."""
    checks = [c for c in measured[0]["checks"] if c["relative_tolerance"] is not None]
    assert checks
    for check in checks:
        error = check["measured"] / check["paper"] - 1.0
        assert check["relative_error"] == pytest.approx(error, rel=1e-9, abs=1e-12), check
        assert check["within"] == (abs(error) <= check["relative_tolerance"]), check


def test_the_report_covers_the_printed_stage(measured):
    """Strokes and rotation range (§2), the 790 Hz mode, Table 3's four
    couplings, the Ziegler-Nichols gains of §3.2, and the loop shapes."""
    keys = {c["key"] for c in measured[0]["checks"]}
    for prefix, count in (("stroke_", 2), ("rotation_", 2), ("theta_resonance", 1),
                          ("ultimate_gain_", 3), ("ultimate_period_", 2), ("loop_", 4)):
        assert sum(k.startswith(prefix) for k in keys) == count, (prefix, sorted(keys))
    for coupling in ("s2_from_y", "s3_from_y", "y_from_x", "y_from_rotation"):
        assert {coupling, f"{coupling}_width_ratio"} <= keys, coupling


def test_a_malformed_parameter_set_is_refused_by_file_and_line(tmp_path):
    bad = tmp_path / "preset.json"
    bad.write_text('{\n  "pzt[1].A": 0.02,\n  "L": oops\n}\n')
    done = run_tool("--fmu", str(require_fmu()), "--parameters", str(bad))
    assert done.returncode == 2, done
    assert f"{bad}:3:" in done.stderr, done.stderr
    unknown = tmp_path / "unknown.json"
    unknown.write_text('{"no_such_parameter": 1.0}')
    done = run_tool("--fmu", str(require_fmu()), "--parameters", str(unknown))
    assert done.returncode == 2 and "no parameter no_such_parameter" in done.stderr, done
