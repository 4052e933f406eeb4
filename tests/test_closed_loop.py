"""PiezoController beside FlexureStage in closed loop: seed 000's experiments
with the demands as the paper prints them (demo.experiments), every numbered
figure judged against the paper's own number (demo.paper), and PiezoController
under fmpy's validator.

The runs are deterministic: the sensor noise is seeded and both FMUs are
stepped by the same fixed-step master, so the figures repeat to the last
digits on one machine. Each figure is asserted at or under the paper's value,
the same rule and the same table `make demo`'s report.md prints its verdicts
from: the tolerance is the paper's number.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from demo import experiments as ex
from demo.cosim import Fmu, simulate
from demo.paper import (
    CIRCLE,
    DECOUPLED,
    TABLE_3,
    TRACKING,
    Y_THETA,
    refined_rows,
    rows,
)
from tests.conftest import REPO_ROOT
from tests.docs_figures import doc_rows, stale_prose, stale_rows, table_rows

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"

#: The runs demo.paper's rows are measured on.
RUNS = (
    set(TRACKING) | set(CIRCLE) | set(Y_THETA)
    | {f"fig7_{axis}_ffpi" for _, axis, _, _ in TABLE_3}
    | {f"fig10_{axis}_decoupled" for _, axis, _, _ in TABLE_3}
    | {key + ex.REFINED for key in DECOUPLED}
)


@pytest.fixture(scope="module")
def results():
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    chosen = [e for e in ex.experiments() if e.key in RUNS]
    assert {e.key for e in chosen} == RUNS, "a figure's run is missing from the demo"
    out = {}
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        for experiment in chosen:
            run = simulate(
                plant, controller, experiment.reference(), experiment.duration,
                plant_parameters=experiment.plant, controller_parameters=experiment.controller,
            )
            out[experiment.key] = ex.metrics(experiment, run, spacing_um)
    return out


def test_controller_fmu_passes_fmpy_validation():
    problems = validate_fmu(str(CONTROLLER))
    assert problems == [], "\n".join(problems)
    done = subprocess.run([sys.executable, "-m", "fmpy", "validate", str(CONTROLLER)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_numbered_figure_is_at_or_under_the_papers(results):
    """Fig. 6, 7a/b/c, 11 (max and RMS), Table 3 (spans with decoupling and
    the 7x ratio), Fig. 12 (error bounds, contour 2-norm) and Fig. 13 (error
    ranges), without and with decoupling: 17 rows, every one met with the
    decoupling law fitted once, as seed 000 §4 does; and with the law the
    start values refine over three rounds on the same runs (in-sample), every
    decoupled row. (The 3dof_no_memory pair, the default until the stacks
    closed their minor loops, misses three of Table 3's: docs/seed000.md.)"""
    table = rows(results)
    assert len(table) == 17
    missed = [r.what for r in table if not r.met]
    assert not missed, "\n".join(
        f"{r.where} {r.what}: {r.simulated} against {r.paper} ({r.rule}): "
        f"{'met' if r.met else 'missed'}" for r in table)
    refined = refined_rows(results)
    assert len(refined) == 9
    missed = [f"{r.where} {r.what}: {r.simulated} against {r.paper} ({r.rule})"
              for r in refined if not r.met]
    assert not missed, "\n".join(missed)


def test_docs_seed000_prints_these_figures(results):
    """docs/seed000.md's table is this measurement: every number of every row
    as measured here (tests/docs_figures.py says within what), so a figure
    left stale after a change of the models or presets fails."""
    measured = table_rows(
        f"| {r.what} | {r.paper} | {r.simulated} | {r.rule} | {'met' if r.met else 'missed'} "
        f"| {r.where} |" for r in rows(results) + refined_rows(results))
    problems = stale_rows(doc_rows("seed000.md"), measured, 1, "docs/seed000.md")
    # The runs it counts: the table's, and every run of `make demo`.
    problems += stale_prose("seed000.md", r"\(the (\d+) runs the table needs", str(len(RUNS)),
                            "runs behind the table", exact=True)
    problems += stale_prose("seed000.md", r"`python -m demo --out out/demo`, (\d+) runs",
                            str(len(ex.experiments())), "runs of make demo", exact=True)
    assert not problems, "\n".join(problems)


def test_the_single_axis_runs_start_from_rest_with_the_held_axes_at_zero(results):
    """The paper's protocol, literally: the driven translation starts at 0,
    the others are demanded at 0 (§5), and the coupling the decoupling works
    on is the paper's size (Table 3 without decoupling: 1.2-2.7 um)."""
    for axis in ("x", "y"):
        start = ex.single_axis(axis)(np.zeros(1))[0]
        assert tuple(start) == (0.0, 0.0, 0.0), (axis, start)
        top = ex.single_axis(axis)(np.array([0.5 / ex.SINE_HZ]))[0]
        assert max(top) == pytest.approx(ex.TRANSLATION_SPAN_UM), (axis, top)
    for name, axis, key, (paper_without, _) in TABLE_3:
        without = results[f"fig7_{axis}_ffpi"][key]
        assert 0.5 * paper_without <= without <= 1.5 * paper_without, (name, without)


@pytest.mark.parametrize("key", ["fig7_x_ffpi", "fig7_theta_ffpi"])
def test_the_papers_gains_sit_at_the_memory_plants_limit_while_tracking(key):
    """docs/seed000.md, "Why Fig. 7 is a draw there": on the plant calibrated
    with the memory (`3dof_memory` with its own controller) the error the
    sensor noise makes bursts over the quarter cycle before a reversal, where
    the driven stack is steepest (largest twentieth of the cycle 10.9x (x) and
    9.5x (theta) its median), and not at 0.9 of the paper's gains (1.4x,
    1.3x) nor on the default stage, calibrated to the Ziegler-Nichols figures
    of the moving stage (1.0x): a loop at its stability limit there, which a
    filter of the noise would not be. Bounds 5x and 2x sit between the two
    kinds of run by a factor of 2 or more either way."""
    experiment = next(e for e in ex.experiments() if e.key == key)
    default = ex.preset("PiezoController.stage.json")
    own = {k: v for k, v in experiment.controller.items() if default.get(k) != v}
    memory = {k: v for k, v in ex.preset("FlexureStage.3dof_memory.json").items()
              if not k.startswith("noise.")}
    memory_controller = ex.preset("PiezoController.stage_memory.json")
    detuned = {"translation.kp": 0.9 * 0.05, "translation.ki": 0.9 * 50.0,
               "rotation.kp": 0.9 * 0.06, "rotation.ki": 0.9 * 70.0}
    cases = {"memory": (memory, memory_controller),
             "memory, 0.9 of the gains": (memory, memory_controller | detuned),
             "default": ({}, default)}
    found = {}
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        for name, (plant_set, controller_set) in cases.items():
            noisy, clean = (
                simulate(plant, controller, experiment.reference(), experiment.duration,
                         plant_parameters=experiment.plant | plant_set | {"noise.enabled": noise},
                         controller_parameters=controller_set | own)
                for noise in (True, False))
            found[name] = ex.noise_error_by_phase(
                experiment, noisy, clean, float(controller_set["L"]) * 1e3)
    bursts = {name: rms.max() / np.median(rms) for name, (rms, _) in found.items()}
    assert bursts["memory"] >= 5.0, bursts
    assert bursts["memory, 0.9 of the gains"] <= 2.0, bursts
    assert bursts["default"] <= 2.0, bursts
    # Where: the bin of the largest burst is where the default run's stack is
    # within 10 % of its steepest (the memory run's own slopes there are its
    # ringing's).
    worst = int(np.argmax(found["memory"][0]))
    slope = found["default"][1]
    assert slope[worst] >= 0.9 * slope.max(), (worst, slope)


@pytest.mark.parametrize("parameters, logged", [
    ({"controller_parameters": {"translation.kp": -1.0}},
     "[fmi2Error|logStatusError|controller] fmi2ExitInitializationMode: parameter "
     "translation.kp = -1 is outside its allowed range [0, inf]"),
    # A coupling that runs away at 2130 V of travel (beta + gamma < 0, n = 2),
    # past the 1 kV the plant's build checks, behind a 10 kV amplifier: the
    # run's first commands reach it.
    ({"plant_parameters": {"amplifier.gain": 1000.0, "amplifier.v_max": 1e4,
                           "coupling.x_from_pzt1.beta": -5.5e-5,
                           "coupling.x_from_pzt1.gamma": -1.3e-5,
                           "coupling.x_from_pzt1.delta": 0.0}},
     ("[fmi2Error|logStatusError|plant] fmi2DoStep: at t = ",
      "the stage diverged", "coupling x from PZT1", "likely cause: a Bouc-Wen model")),
], ids=["refused parameter", "diverging plant"])
def test_a_failed_run_raises_with_what_the_fmu_logged(parameters, logged):
    """demo.cosim.simulate, the master the README recommends, raises the FMU's
    own reason (its log) with the failed call, and nothing after it: an
    instance that returned fmi2Error is freed without fmi2Terminate, which it
    would refuse."""
    from demo.cosim import FmuCallError

    def reference(t):
        return np.column_stack([5 + 5 * np.sin(2 * np.pi * t), np.zeros_like(t), np.zeros_like(t)])

    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        with pytest.raises(FmuCallError) as raised:
            simulate(plant, controller, reference, 0.2, **parameters)
    for fragment in (logged,) if isinstance(logged, str) else logged:
        assert fragment in str(raised.value), str(raised.value)
    assert "fmi2Terminate" not in str(raised.value)
