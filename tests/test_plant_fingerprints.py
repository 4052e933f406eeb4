"""The FlexureStage defaults reproduce seed 000's stage (issue: fingerprint
table), measured through the packaged FMU with fmpy. Each row is a test that
prints the measured figure beside the target (pytest -s shows them)."""

from __future__ import annotations

import pathlib

import pytest

from plant_fingerprints import (
    COUPLING_LOOP_WIDTH_MIN,
    LOOP_ASYMMETRY_MIN,
    LOOP_WIDTH_RANGE,
    TARGETS,
    Plant,
    measure,
)


FMU = pathlib.Path(__file__).resolve().parent.parent / "dist" / "FlexureStage.fmu"


@pytest.fixture(scope="module")
def fingerprints():
    assert FMU.is_file(), f"{FMU} is missing: run `make fmus`"
    plant = Plant(str(FMU))
    try:
        yield measure(plant)
    finally:
        plant.close()


def check_target(fingerprints, key: str) -> None:
    target = TARGETS[key]
    measured = fingerprints.value(key)
    error = measured / target.paper - 1.0
    print(
        f"\n{target.name}: measured {measured:.5g} {target.unit}, seed 000 {target.paper:g} "
        f"{target.unit} ({error:+.1%}, tolerance ±{target.relative_tolerance:.0%})"
    )
    assert abs(error) <= target.relative_tolerance, (
        f"{target.name}: {measured:.5g} {target.unit} is {error:+.1%} from {target.paper:g}"
    )


@pytest.mark.parametrize("key", ["stroke_x", "stroke_y"])
def test_stroke_at_full_command(fingerprints, key):
    check_target(fingerprints, key)


@pytest.mark.parametrize("key", ["rotation_anticlockwise", "rotation_clockwise"])
def test_rotation_range_from_x_home(fingerprints, key):
    check_target(fingerprints, key)


def test_theta_resonance_is_the_spectral_peak(fingerprints):
    check_target(fingerprints, "theta_resonance")


@pytest.mark.parametrize("axis", ["x", "y"])
def test_major_loop_is_asymmetric_and_8_to_15_percent_wide(fingerprints, axis):
    shape = getattr(fingerprints, f"loop_{axis}")
    stroke = getattr(fingerprints, f"stroke_{axis}")
    width_ratio = shape.max_width / stroke
    print(
        f"\nmajor loop {axis}: width {shape.max_width:.4f} um = {width_ratio:.1%} of the stroke "
        f"(target 8-15 %), asymmetry {shape.asymmetry:.2f} (> {LOOP_ASYMMETRY_MIN})"
    )
    low, high = LOOP_WIDTH_RANGE
    assert low <= width_ratio <= high, f"loop width {width_ratio:.1%} of the stroke"
    assert shape.asymmetry > LOOP_ASYMMETRY_MIN, f"loop asymmetry {shape.asymmetry:.3f}"


@pytest.mark.parametrize("key", ["s2_from_y", "s3_from_y", "y_from_x", "y_from_rotation"])
def test_coupling_span_and_hysteresis(fingerprints, key):
    check_target(fingerprints, key)
    shape = fingerprints.couplings.shapes[key]
    print(f"{key}: loop width {shape.width_ratio:.1%} of its span (a loop when >= 5 %)")
    assert shape.width_ratio >= COUPLING_LOOP_WIDTH_MIN, (
        f"{key}: the coupling is not hysteretic (width {shape.width_ratio:.1%} of its span)"
    )


@pytest.mark.parametrize(
    "key",
    ["ultimate_gain_x", "ultimate_gain_y", "ultimate_gain_theta", "ultimate_period_x",
     "ultimate_period_y"],
)
def test_ziegler_nichols_ultimate_gain_matches_the_papers_pi_gains(fingerprints, key):
    """Seed 000 tuned its PI gains by Ziegler-Nichols, so the plant must put
    its ultimate gain where the paper's gains say (gain margin 1/0.45 = 2.2)."""
    check_target(fingerprints, key)
