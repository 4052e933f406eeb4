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


def test_model_md_prints_what_the_tool_measures(measured):
    """piezo-models/MODEL.md's fingerprint table prints each measured figure
    of the packaged FMU: every row's "measured" cell must be what the tool
    reports now, within one unit of the last printed digit (the run is
    deterministic; the table prints up to six decimals), so a recalibration
    that moves one leaves no stale row."""
    from tests.docs_figures import NUMBER, same_numbers, table_rows

    m = {c["key"]: c["measured"] for c in measured[0]["checks"]}

    def loop(axis):
        return f"{100 * m[f'loop_{axis}_width_ratio']:.2f} %, {m[f'loop_{axis}_asymmetry']:.3f}"

    def span(key):
        return f"{m[key]:.6f} µm (loop width {100 * m[f'{key}_width_ratio']:.1f} %)"

    expected = {
        "x stroke at 10 V": f"{m['stroke_x']:.6f} µm",
        "y stroke at 10 V": f"{m['stroke_y']:.6f} µm",
        "rotation, anticlockwise": f"{m['rotation_anticlockwise']:.6f}°",
        "rotation, clockwise": f"{m['rotation_clockwise']:.6f}°",
        "θ resonance (spectral peak)": f"{m['theta_resonance']:.1f} Hz",
        "x major loop: width / span, asymmetry": loop("x"),
        "y major loop: width / span, asymmetry": loop("y"),
        "s2 span from y sweep": span("s2_from_y"),
        "s3 span from y sweep": span("s3_from_y"),
        "y span from x sweep": span("y_from_x"),
        "y span from rotation sweep": span("y_from_rotation"),
        "ultimate gain x, y (ZN: kp 0.05 / 0.45)":
            f"{m['ultimate_gain_x']:.4f}, {m['ultimate_gain_y']:.4f} V/µm",
        "ultimate period x, y (ZN: 1.2·kp/ki)":
            f"{1e3 * m['ultimate_period_x']:.3f}, {1e3 * m['ultimate_period_y']:.3f} ms",
        # The θ row also prints T_u and the ZN ki, which the tool's checks
        # do not report: its first figure, the gain, is compared.
        "ultimate gain θ (ZN: kp 0.06 / 0.45)": f"{m['ultimate_gain_theta']:.4f}",
    }
    text = (REPO_ROOT / "piezo-models" / "MODEL.md").read_text(encoding="utf-8")
    rows = {row[0]: row[2] for row in table_rows(text.splitlines())
            if len(row) == 4 and row[0] in expected}
    assert rows.keys() == expected.keys(), sorted(set(expected) - set(rows))
    problems = []
    for name, printed in rows.items():
        if name.startswith("ultimate gain θ"):
            printed = NUMBER.findall(printed)[0]
        if not same_numbers(printed, expected[name], relative=0.0):
            problems.append(f"MODEL.md, {name}: printed {printed!r}, measured {expected[name]!r}")
    assert not problems, "\n".join(problems)
