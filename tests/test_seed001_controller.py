"""Seed 001's paths of PiezoController through the FMU, beside FlexureStage:
the inverse Bouc-Wen feedforward (hysteresis_model = 2) and the model-based
decoupling (decoupling_model = 2), selected by Integer parameters, with the
stage preset's Bouc-Wen models (identified on FlexureStage by
`piezo-identify stage`).

Seed 001 §5.3's experiment on seed 000's stage: y follows a 2 Hz sine of
2 um amplitude by feedforward alone while x is held at its home (the demo's
seed 001 protocol, which the XY200S's 0..150 V amplifier needs), no feedback. The x displacement the y motion causes is the coupling.
"""

from __future__ import annotations

import numpy as np
import pytest

from demo.cosim import Fmu, simulate
from demo.experiments import ABW_XY_HOME, ABW_XY_HZ, pose, trajectory
from tests.conftest import REPO_ROOT
from tests.docs_figures import doc_rows, stale_prose, stale_rows, stale_script_output, table_rows

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
HOME_X, HOME_Y, _ = ABW_XY_HOME

#: Raised-cosine approach to the home, hold, then the 2 Hz, 2 um sine on y
#: (the demo's approach and timing, demo/experiment_conditions.json).
reference = trajectory(pose(x=HOME_X, y=lambda tau: HOME_Y + 2.0 * np.sin(2 * np.pi * ABW_XY_HZ * tau)))


def inverse_bouc_wen_model_based_parameters(decoupling: bool) -> dict:
    return {
        "feedforward": True,
        "feedback_x": False,
        "feedback_y": False,
        "feedback_theta": False,
        "hysteresis_model": 2,
        "decoupling_model": 2,
        "decoupling": decoupling,
    }


@pytest.fixture(scope="module")
def fmus():
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        yield plant, controller


def coupling_and_tracking(run):
    """x span and y RMS error over the last period (t >= 2 s)."""
    last = run.t >= 2.0
    x = 0.5 * (run["s2"] + run["s3"])[last]
    y_error = (run["s1"] - run.references[:, 1])[last]
    return float(np.ptp(x)), float(np.sqrt(np.mean(y_error**2)))


def test_an_unknown_selector_code_is_refused_at_initialization(fmus):
    _, controller = fmus
    for name in ("hysteresis_model", "decoupling_model"):
        with pytest.raises(Exception):
            controller.instance("refused", {name: 3}).free()


def test_model_based_decoupling_shrinks_the_coupling_seed_001_measured(fmus):
    plant, controller = fmus
    without = simulate(plant, controller, reference, 2.5, controller_parameters=inverse_bouc_wen_model_based_parameters(False))
    with_ = simulate(plant, controller, reference, 2.5, controller_parameters=inverse_bouc_wen_model_based_parameters(True))
    span_without, _ = coupling_and_tracking(without)
    span_with, y_rms = coupling_and_tracking(with_)
    reduction = 100 * (1 - span_with / span_without)
    print(
        f"x coupling span {span_without:.4f} um without, {span_with:.4f} um with model-based "
        f"decoupling ({reduction:.1f} % less; seed 001 measured 73.2 %); y RMS {y_rms:.4f} um"
    )
    # Seed 001 reduced its coupling by 73 %; the issue asks for better.
    assert reduction > 73.2
    # Feedforward alone, identified models, seed 000's creeping stage: y
    # follows its 4 um swing to a few per cent.
    assert y_rms < 0.15


@pytest.fixture(scope="module")
def feedforward_xy_results(fmus):
    """The demo's seed 001 runs (both methods, same trajectories)."""
    from demo.experiments import feedforward_xy_experiments, report_figures

    plant, controller = fmus
    spacing_um = float(controller.variables["L"].start) * 1e3
    results = {}
    for experiment in feedforward_xy_experiments():
        run = simulate(plant, controller, experiment.reference(), experiment.duration,
                       plant_parameters=experiment.plant,
                       controller_parameters=experiment.controller)
        results[experiment.key] = report_figures(experiment, run, spacing_um)
    return results


def test_seed_001_feedforward_linearity_beats_the_papers(feedforward_xy_results):
    """Seed 001 eq. (17)-(18): eta = max |d_e - d| / amplitude; the paper:
    8 % for x at 1.25 um, 5.5 % for y at 2 um (measured: docs/seed001.md)."""
    from demo.experiments import ABW_XY_LINEARITY_UM, ABW_XY_STAGES, abw_xy_key

    for stage in ABW_XY_STAGES:
        for axis, paper in (("x", 0.08), ("y", 0.055)):
            m = feedforward_xy_results[abw_xy_key(stage, "inverse_bouc_wen_model_based", f"linearity_{axis}")]
            eta = m["tracking_max"] / ABW_XY_LINEARITY_UM[axis]
            print(f"{stage} {axis}: eta {100 * eta:.2f} % (seed 001: {100 * paper} %)")
            assert eta < paper


@pytest.mark.parametrize("driven, key, paper", [
    ("y", "coupling_x_span", 73.2),
    ("x", "coupling_y_span", 72.9),
])
def test_seed_001_decoupling_beats_the_papers_reduction_and_seed_000s(
        feedforward_xy_results, driven, key, paper):
    from demo.experiments import ABW_XY_STAGES, abw_xy_key

    for stage in ABW_XY_STAGES:
        reductions = {}
        for method in ("inverse_pi_piecewise", "inverse_bouc_wen_model_based"):
            a = feedforward_xy_results[abw_xy_key(stage, method, f"coupling_{driven}_coupled")][key]
            b = feedforward_xy_results[abw_xy_key(stage, method, f"coupling_{driven}_decoupled")][key]
            reductions[method] = 100 * (1 - b / a)
        print(f"{stage} {key}: reduction by seed 000's method {reductions['inverse_pi_piecewise']:.1f} %, "
              f"by seed 001's {reductions['inverse_bouc_wen_model_based']:.1f} % (paper {paper} %)")
        assert reductions["inverse_bouc_wen_model_based"] > paper


def test_docs_seed001_prints_these_figures(feedforward_xy_results):
    """docs/seed001.md's two tables are this measurement (the tables `make
    demo`'s report prints): a figure left stale fails here."""
    from demo.report import feedforward_xy_section

    from demo.experiments import feedforward_xy_experiments

    measured = table_rows(feedforward_xy_section(feedforward_xy_results))
    assert len(measured) == 20
    problems = stale_rows(doc_rows("seed001.md"), measured, 2, "docs/seed001.md")
    # The runs behind them: how many, and the time they simulate.
    simulated = sum(experiment.duration for experiment in feedforward_xy_experiments())
    problems += stale_prose("seed001.md", r"\((\d+) runs, [0-9.]+ s simulated", str(len(feedforward_xy_results)),
                            "seed 001's runs", exact=True)
    problems += stale_prose("seed001.md", r"\(\d+ runs, ([0-9.]+) s simulated", f"{simulated:g}",
                            "time seed 001's runs simulate")
    assert not problems, "\n".join(problems)


def test_docs_seed001_prints_what_seed_000s_pi_does_on_the_xy200s(tmp_path):
    """docs/seed001.md's lead on seed 000's method with its PI feedback on the
    XY200S is a script and its output: the script runs as printed and every
    figure must be the one shown (within one unit of the last digit)."""
    measured, problems = stale_script_output(
        "seed001.md", "### Seed 000's method with its own PI feedback (XY200S)", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)


def test_docs_seed001_prints_the_xy200s_ratchet(tmp_path):
    """docs/seed001.md's account of why seed 000's feedforward drifts on the
    XY200S (the X actuator's minor loops ratchet) is a script and its output:
    the script runs as printed and every figure must be the one shown."""
    measured, problems = stale_script_output(
        "seed001.md", "### Why seed 000's feedforward drifts on the XY200S", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)


def test_docs_seed001_prints_the_linearity_runs_from_rest(tmp_path):
    """docs/seed001.md's second reading of §5.2 (sines from rest up to the
    paper's peak) is a script and its output: the script runs as printed
    and every figure must be the one shown."""
    measured, problems = stale_script_output(
        "seed001.md", "### Seed 001's §5.2 read from rest", tmp_path)
    print(measured)
    assert not problems, "\n".join(problems)
