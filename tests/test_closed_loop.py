"""PiezoController beside FlexureStage in closed loop (the demo's runs), and
PiezoController under fmpy's validator.

The runs are deterministic: the sensor noise is seeded and both FMUs are
stepped by the same fixed-step master, so the figures below repeat to the last
digits on one machine. The bounds are the issue's targets where this plant
meets them (x tracking, Table 3, circle), and regression bounds a little above
what is measured where it does not (y and theta_z tracking; report.md and the
README say why). The margins cover floating-point differences between
platforms and libm versions, not changes of behaviour.
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from fmpy.validation import validate_fmu

from demo.cosim import Fmu, simulate
from demo.experiments import HOME, experiments, metrics
from tests.conftest import REPO_ROOT

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"

RUNS = (
    "fig7_y_ffpi", "fig7_x_ffpi", "fig7_theta_ffpi",
    "fig10_y_decoupled", "fig10_x_decoupled", "fig10_theta_decoupled",
    "fig12_circle_coupled", "fig12_circle_decoupled",
)


@pytest.fixture(scope="module")
def results():
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    chosen = [e for e in experiments() if e.key in RUNS]
    out = {}
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        for experiment in chosen:
            run = simulate(
                plant, controller, experiment.reference(), experiment.duration,
                plant_parameters=experiment.plant, controller_parameters=experiment.controller,
            )
            out[experiment.key] = metrics(experiment, run, spacing_um)
    return out


def test_controller_fmu_passes_fmpy_validation():
    problems = validate_fmu(str(CONTROLLER))
    assert problems == [], "\n".join(problems)
    done = subprocess.run([sys.executable, "-m", "fmpy", "validate", str(CONTROLLER)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_x_feedforward_plus_pi_meets_the_papers_figures(results):
    # Seed 000 Fig. 7b: max 0.0701 um, RMS 0.0171 um. Measured 0.0624 / 0.0171.
    m = results["fig7_x_ffpi"]
    assert m["tracking_rms"] <= 0.0171 * 1.03, m
    assert m["tracking_max"] <= 0.0701, m


def test_y_feedforward_plus_pi_stays_near_the_papers_figures(results):
    # Seed 000 Fig. 7a: 0.0544 / 0.0134 um; measured 0.078 / 0.0189 um, of which
    # the seeded 0.01 um RMS sensor noise alone is 0.01 (in quadrature).
    m = results["fig7_y_ffpi"]
    assert m["tracking_rms"] <= 0.021, m
    assert m["tracking_max"] <= 0.09, m


def test_theta_tracking_is_bounded_by_the_x_pairs_saturation(results):
    # +-9.2e-3 deg asks more than the clockwise range (0.0088 deg, seed 000 §2)
    # that the plant reproduces: the x pair saturates at 10 V at both extremes.
    # Measured RMS 4.5e-4 deg; a loop that lost the rotation would be ~6e-3.
    m = results["fig7_theta_ffpi"]
    assert m["tracking_rms"] <= 5.5e-4, m


@pytest.mark.parametrize("axis, coupling", [
    ("y", "coupling_x2_span"), ("y", "coupling_x3_span"),
    ("x", "coupling_y_span"), ("theta", "coupling_y_span"),
])
def test_decoupling_shrinks_every_table_3_span_at_least_7x(results, axis, coupling):
    # Measured ratios 13.2, 19.4, 7.8, 7.6 (the paper: 7.0, 4.5, 3.9, 4.5).
    without = results[f"fig7_{axis}_ffpi"][coupling]
    with_decoupling = results[f"fig10_{axis}_decoupled"][coupling]
    assert without > 1.0, "the coupling the plant is calibrated to (Table 3: 1.2-2.7 um)"
    assert without / with_decoupling >= 7.0, (without, with_decoupling)


def test_circle_contour_error_is_smaller_with_decoupling(results):
    coupled = results["fig12_circle_coupled"]["contour_2norm"]
    decoupled = results["fig12_circle_decoupled"]["contour_2norm"]
    assert decoupled < coupled, (coupled, decoupled)


def test_demo_and_identification_share_the_single_axis_home():
    """piezo-identify fits the decoupling under the demo's single-axis
    conditions; the two must not drift apart."""
    source = (REPO_ROOT / "piezo-identify" / "src" / "stage.rs").read_text()
    found = re.search(r"pub const HOME: \[f64; 3\] = \[([^\]]*)\];", source)
    assert found, "HOME not found in piezo-identify/src/stage.rs"
    rust_home = tuple(float(v) for v in found.group(1).split(","))
    assert rust_home == HOME
