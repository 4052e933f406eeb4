"""Parameter sets by FMI name (dist/presets/*.json, written by `make fmus` from
the Rust variable tables): each loads into its FMU through fmpy, the default
sets equal the FMUs' start values, and the XY200S set turns FlexureStage into
seed 001's stage (its strokes, seed 001 §5.1)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from demo.cosim import Fmu
from tests.conftest import REPO_ROOT

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
        ("PiezoController", "PiezoController.paper.json"),
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
