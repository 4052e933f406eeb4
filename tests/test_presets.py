"""Parameter sets by FMI name (dist/presets/*.json, written by `make fmus` from
the Rust variable tables): each loads into its FMU through fmpy, the default
sets equal the FMUs' start values, and the XY200S set turns FlexureStage into
seed 001's stage (its strokes, seed 001 §5.1). docs/presets.md's script runs
as printed and its tables are the ones the document shows."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from demo.cosim import Fmu
from tests.conftest import REPO_ROOT
from tests.docs_figures import DOCS, doc_rows, stale_rows, table_rows

DIST = REPO_ROOT / "dist"
PRESETS = DIST / "presets"


def load(name: str) -> dict:
    path = PRESETS / name
    if not path.is_file():
        pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    return json.loads(path.read_text())


@pytest.mark.parametrize(
    "fmu, preset",
    [
        ("FlexureStage", "FlexureStage.3dof.json"),
        ("PiezoController", "PiezoController.stage.json"),
    ],
)
def test_the_default_sets_are_the_start_values(fmu, preset):
    values = load(preset)
    with Fmu(DIST / f"{fmu}.fmu") as f:
        parameters = {v.name: v for v in f.description.modelVariables if v.causality == "parameter"}
        assert set(values) == set(parameters)
        for name, value in values.items():
            start = parameters[name].start
            if parameters[name].type == "Boolean":
                assert value == (start in (True, "true", "1")), name
            else:
                assert float(value) == float(start), name


@pytest.mark.parametrize(
    "fmu, preset",
    [
        ("FlexureStage", "FlexureStage.xy200s.json"),
        ("FlexureStage", "FlexureStage.3dof_memory.json"),
        ("FlexureStage", "FlexureStage.3dof_no_memory.json"),
        ("PiezoController", "PiezoController.paper.json"),
        ("PiezoController", "PiezoController.stage_memory.json"),
        ("PiezoController", "PiezoController.stage_memory_once.json"),
        ("PiezoController", "PiezoController.stage_no_memory.json"),
        ("PiezoController", "PiezoController.stage_no_memory_once.json"),
    ],
)
def test_every_set_loads_into_its_fmu(fmu, preset):
    with Fmu(DIST / f"{fmu}.fmu") as f:
        f.instance("preset", load(preset)).free()


def ramp_to_full_command(plant: Fmu, parameters: dict, channels: list[int]) -> np.ndarray:
    """s1..s3 after ramping the given channels from 0 to 10 V over 1 s at
    10 kHz from rest (the stroke measurement of seed 000's fingerprint)."""
    slave = plant.instance("stroke", parameters)
    try:
        u = slave.real_port(("u1", "u2", "u3"))
        s = slave.real_port(("s1", "s2", "s3"))
        command = np.zeros(3)
        for k in range(10_000):
            command[channels] = 10.0 * (k + 1) / 10_000
            u.set(command)
            slave.do_step(1e-4)
        return s.get()
    finally:
        slave.free()


def test_the_xy200s_set_gives_the_printed_strokes():
    parameters = load("FlexureStage.xy200s.json")
    with Fmu(DIST / "FlexureStage.fmu") as plant:
        y = ramp_to_full_command(plant, parameters, [0])[0]
        s = ramp_to_full_command(plant, parameters, [1, 2])
        x = 0.5 * (s[1] + s[2])
    print(f"XY200S through FlexureStage.fmu: x stroke {x:.3f} um (144.37), y stroke {y:.3f} um (149.27)")
    assert x == pytest.approx(144.37, rel=0.005)
    assert y == pytest.approx(149.27, rel=0.005)


def test_the_presets_document_prints_what_its_script_measures():
    """docs/presets.md's one Python block, run from the repository's root as
    the document says, prints the tables of the `paper` and `stage` presets on
    the plant; every figure of them must be the one the document prints
    (tests/docs_figures.py says within what), and every row the document
    prints must be one the script prints."""
    blocks = re.findall(r"^```python\n(.*?)^```$", (DOCS / "presets.md").read_text(encoding="utf-8"),
                        re.MULTILINE | re.DOTALL)
    assert len(blocks) == 1, f"docs/presets.md: {len(blocks)} python blocks, one expected"
    for fmu in ("FlexureStage", "PiezoController"):
        if not (DIST / f"{fmu}.fmu").is_file():
            pytest.fail(f"dist/{fmu}.fmu is missing: run `make fmus` first", pytrace=False)
    done = subprocess.run([sys.executable, "-c", blocks[0]], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    assert done.returncode == 0, f"docs/presets.md's script failed:\n{done.stdout}\n{done.stderr}"
    print(done.stdout)
    measured, documented = table_rows(done.stdout.splitlines()), doc_rows("presets.md")
    problems = stale_rows(documented, measured, 2, "docs/presets.md")
    measured_keys = {tuple(row[:2]) for row in measured}
    problems += [f"docs/presets.md: {' | '.join(row[:2])!r} is printed but not measured"
                 for row in documented if tuple(row[:2]) not in measured_keys]
    assert not problems, (
        "docs/presets.md does not print what its script measures: run it again, as the document "
        "says, and print its tables with the commit\n" + "\n".join(problems))
