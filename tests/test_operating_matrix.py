"""The reachable range demo.matrix bounds its cases by, against the stage.

demo.matrix runs seed 000's single-axis experiment off the paper's operating
point and bounds only the cases whose demands the stage can reach inside the
controller's command range (REACHABLE). That range must be inside what
FlexureStage (its default parameters, sensor noise off) reaches when the
commands sit at the ends of the range, approached from rest, the other
stacks at 0 V (for theta, the x pair at the two ends, one each way).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demo.cosim import Fmu
from demo.matrix import REACHABLE
from tests.conftest import REPO_ROOT

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
STEP = 1e-4
RAMP_TIME = 0.5
HOLD_TIME = 0.5


def held_pose(plant: Fmu, commands) -> dict:
    """Noise-free pose after the commands ramp from 0 to `commands` (raised
    cosine, 0.5 s) and hold 0.5 s."""
    slave = plant.instance("reach")
    try:
        inputs = slave.real_port(("u1", "u2", "u3"))
        outputs = slave.real_port(("x", "y", "theta_z"))
        target = np.asarray(commands, dtype=float)
        steps = round((RAMP_TIME + HOLD_TIME) / STEP)
        for k in range(steps):
            t = k * STEP
            blend = 0.5 * (1 - math.cos(math.pi * min(t / RAMP_TIME, 1.0)))
            inputs.set(blend * target)
            slave.do_step_at(t, STEP)
        x, y, theta = outputs.get()
        return {"x": x, "y": y, "theta": theta}
    finally:
        slave.free()


@pytest.fixture(scope="module")
def ranges():
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    with Fmu(CONTROLLER) as controller:
        low = float(controller.variables["command_min"].start)
        high = float(controller.variables["command_max"].start)
    with Fmu(PLANT) as plant:
        return {
            "y": (held_pose(plant, (low, 0, 0))["y"], held_pose(plant, (high, 0, 0))["y"]),
            "x": (held_pose(plant, (0, low, low))["x"], held_pose(plant, (0, high, high))["x"]),
            "theta": tuple(sorted((
                math.degrees(held_pose(plant, (0, low, high))["theta"]),
                math.degrees(held_pose(plant, (0, high, low))["theta"]),
            ))),
        }


@pytest.mark.parametrize("axis", ["y", "x", "theta"])
def test_the_matrix_bounds_only_demands_the_stage_reaches(ranges, axis):
    reached_low, reached_high = ranges[axis]
    bound_low, bound_high = REACHABLE[axis]
    print(f"{axis}: reaches {reached_low:.4g}..{reached_high:.4g}, "
          f"the matrix bounds {bound_low:g}..{bound_high:g}")
    assert reached_low < bound_low < bound_high < reached_high


def test_the_documented_minor_loop_of_a_2_um_drive_is_what_the_script_prints(tmp_path):
    """docs/seed000.md explains the 2 um drives' misses with a script and its
    output: the script runs as the document gives it, and every figure it
    prints must be the one the document shows (within one unit of the last
    printed digit), so a stale explanation fails."""
    import os
    import re
    import subprocess
    import sys

    text = (REPO_ROOT / "docs" / "seed000.md").read_text(encoding="utf-8")
    section = text[text.index("## Off the paper's operating point"):]
    python = re.findall(r"^```python\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)
    printed = re.findall(r"^```text\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)
    assert len(python) == 1 and len(printed) == 1, "one script and one output in the section"
    script = tmp_path / "minor_loop.py"
    script.write_text(python[0])
    measured = subprocess.run([sys.executable, str(script)], cwd=REPO_ROOT, capture_output=True,
                              text=True, check=True,
                              env={**os.environ, "PYTHONPATH": str(REPO_ROOT)}).stdout
    print(measured)
    number = re.compile(r"[-+]?\d+(?:\.\d+)?")
    lines = list(zip(measured.splitlines(), printed[0].splitlines()))
    assert len(measured.splitlines()) == len(printed[0].splitlines()), (measured, printed[0])
    for got, shown in lines:
        assert number.sub("#", got) == number.sub("#", shown), (got, shown)
        for m, d in zip(number.findall(got), number.findall(shown)):
            unit = 10.0 ** -len(d.split(".")[1]) if "." in d else 1.0
            assert abs(float(m) - float(d)) <= unit * 1.01, (got, shown)
