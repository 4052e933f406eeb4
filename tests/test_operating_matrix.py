"""demo.matrix: seed 000's single-axis experiment off the paper's operating
point (item 4 of the issue "Seed 000's experiments as printed").

- The reachable range it bounds its cases by: inside what FlexureStage (its
  default parameters, sensor noise off) reaches when the commands sit at the
  ends of the controller's range, approached from rest, the other stacks at
  0 V (for theta, the x pair at the two ends, one each way).
- Its runs go through the compiled master: a case run there gives the row
  demo.cosim's fmpy master gives.
- The whole matrix, with what holds asserted and docs/seed000.md's figures
  checked against it. What does not hold (the couplings of the 2 um drives)
  is printed and documented, not asserted.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demo.cosim import Fmu, simulate
from demo.matrix import COUPLING_REDUCTION, REACHABLE, Case, cases, evaluate, run
from tests.conftest import REPO_ROOT
from tests.docs_figures import stale_prose, stale_script_output

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
    measured, problems = stale_script_output(
        "seed000.md", "### A 2 um drive: the law's line and the held stacks' answer", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)


def test_the_documented_settling_of_the_held_stacks_is_what_the_script_prints(tmp_path):
    """docs/seed000.md measures how much of a 2 um drive's miss is the held
    stacks settling onto their minor loop (spans after 3 and after 13
    cycles) and that no other slope of the law reaches 4x in the matrix's
    window: the script runs as printed and every figure must be the one the
    document shows (within one unit of the last printed digit)."""
    measured, problems = stale_script_output(
        "seed000.md", "### A 2 um drive: the held stacks' minor loops", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("case", [Case("y", 3.0, 5.0, 2.0), Case("theta", 3.0, 2.0, 2.0)],
                         ids=lambda case: case.key)
def test_a_case_through_the_master_is_the_fmpy_masters_row(case):
    """The same case through demo.cosim (fmpy, couplings from the recorded
    pose) and through the compiled master (its `pose` metrics): every figure
    of the row within 1e-9 relative (the masters agree to 1e-12 um on every
    signal, tests/test_master.py)."""
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        runs = []
        for decoupling in (False, True):
            experiment = case.experiment(decoupling)
            runs.append(simulate(plant, controller, experiment.reference(), experiment.duration,
                                 plant_parameters=experiment.plant,
                                 controller_parameters=experiment.controller))
    expected = evaluate(case, *runs, spacing_um)
    got = run(PLANT, CONTROLLER, selected=[case], workers=1)[0]
    for part in ("rms", "couplings_without", "couplings_with", "reductions"):
        assert got[part].keys() == expected[part].keys(), part
        for name, value in expected[part].items():
            assert got[part][name] == pytest.approx(value, rel=1e-9, abs=1e-15), (part, name)


@pytest.fixture(scope="module")
def matrix_rows():
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    return run(PLANT, CONTROLLER)


def test_every_bounded_case_tracks_within_3x_of_the_papers_rms(matrix_rows):
    checked = [row for row in matrix_rows if row["checked"]]
    assert len(checked) == 81, "every bounded case is inside the reachable range"
    assert all(row["rms_ok"] for row in checked), [row["case"].key for row in checked
                                                   if not row["rms_ok"]]


def test_decoupling_cuts_every_coupling_of_a_5_or_10_um_drive_4x(matrix_rows):
    """The bound holds for the 5 and 10 um drives at every held demand and
    frequency (reported ones too). The 2 um drives miss it (docs/seed000.md
    says why); they are printed here."""
    for row in matrix_rows:
        if row["case"].amplitude == 2.0:
            print(row["case"].key, {k: round(v, 2) for k, v in row["reductions"].items()})
    weak = {row["case"].key: row["reductions"] for row in matrix_rows
            if row["case"].amplitude >= 5.0 and min(row["reductions"].values()) < COUPLING_REDUCTION}
    assert not weak, weak


def test_docs_seed000_prints_this_matrix(matrix_rows):
    """docs/seed000.md's account of the matrix is this run: the counts of
    cases and runs, of bounded cases, of those met and missed, the range of each coupling's reduction at 2 um and
    of every reduction at 5 and 10 um (bounded frequencies)."""
    bounded = [row for row in matrix_rows if row["checked"]]
    met = sum(row["rms_ok"] and row["coupling_ok"] for row in bounded)
    problems = stale_prose("seed000.md", r"ran: (\d+ met, \d+ missed)",
                           f"{met} met, {len(bounded) - met} missed", "matrix: met, missed")
    problems += stale_prose("seed000.md", r"(\d+ cases, \d+ runs) in",
                            f"{len(matrix_rows)} cases, {2 * len(matrix_rows)} runs",
                            "matrix: cases and runs (each case without and with decoupling)")
    problems += stale_prose("seed000.md", r"All (\d+) bounded cases", f"{len(bounded)}",
                            "matrix: bounded cases")

    def spread(values) -> str:
        return f"{min(values):.1f}-{max(values):.1f}x"

    for name in ("x2 from y", "x3 from y", "y from x", "y from rotation"):
        values = [row["reductions"][name] for row in bounded
                  if row["case"].amplitude == 2.0 and name in row["reductions"]]
        problems += stale_prose("seed000.md", rf"coupling: .*?{name} ([0-9.]+-[0-9.]+x)",
                                spread(values), f"matrix: {name} at 2 um")
    large = [value for row in bounded if row["case"].amplitude >= 5.0
             for value in row["reductions"].values()]
    problems += stale_prose("seed000.md", r"every coupling falls ([0-9.]+-[0-9.]+x)", spread(large),
                            "matrix: reductions at 5 and 10 um")
    assert not problems, "\n".join(problems)
