"""The shipped controller presets identified by seed 000's procedure are what
their Makefile targets make: `make stage-preset` and `make
xy200s-controller-preset` run `piezo-identify stage` on dist/FlexureStage.fmu,
and that command, run again with the target's arguments, gives the committed
JSON again. A plant change not followed by re-identification, or an
identification that no longer reproduces what was shipped, fails here.

Tolerance: each value within 1e-6 of the largest magnitude in its group (an
array, or the value itself), with 1e-12 as a floor for all-zero groups. The
identification is deterministic (the search is bit-identical for any number
of threads; the noise is seeded), so only rounding that differs between
processors may move it; a stale preset moves by 1e-3 or more, and an
ill-conditioned linear solve by orders of magnitude (b_9 = 96 V/um where
the shipped preset gives that operator no weight)."""

from __future__ import annotations

import json
import pathlib
import re
import subprocess

import pytest

from tests.conftest import REPO_ROOT

BINARY = REPO_ROOT / "target" / "release" / "piezo-identify"
DIST = REPO_ROOT / "dist"
RELATIVE_TOLERANCE = 1e-6


def makefile_command(target: str) -> tuple[list[str], pathlib.Path]:
    """The arguments target `target` gives `piezo-identify stage` before
    `--out` ($(DIST) read as dist/), and the preset it writes; read from the
    Makefile so the test runs what the target runs."""
    recipe = _recipe(target)
    command = re.search(r"piezo-identify stage (.*?) --out (\S+)", recipe)
    assert command, f"Makefile: {target} does not run `piezo-identify stage ... --out PRESET`"
    arguments = [word.replace("$(DIST)", str(DIST)) for word in command.group(1).split()]
    return arguments, REPO_ROOT / command.group(2)


def _recipe(target: str) -> str:
    text = (REPO_ROOT / "Makefile").read_text(encoding="utf-8").replace("\\\n", " ")
    recipe = re.search(rf"^{re.escape(target)}:.*\n((?:\t.*\n)+)", text, re.MULTILINE)
    assert recipe, f"Makefile: no {target} target"
    return recipe.group(1)


def fitted_once_preset(target: str) -> pathlib.Path | None:
    """The preset with the law fitted once that `target` writes, if any."""
    found = re.search(r"--out-fitted-once (\S+)", _recipe(target))
    return REPO_ROOT / found.group(1) if found else None


def differences(shipped, made, path="") -> list[str]:
    """Every value of `made` off `shipped` beyond the tolerance, by path."""
    if isinstance(shipped, dict):
        assert set(shipped) == set(made), f"{path}: keys {sorted(shipped)} vs {sorted(made)}"
        return [d for key in shipped for d in differences(shipped[key], made[key], f"{path}.{key}")]
    values = shipped if isinstance(shipped, list) else [shipped]
    others = made if isinstance(made, list) else [made]
    assert len(values) == len(others), f"{path}: {len(values)} values vs {len(others)}"
    if all(isinstance(v, bool) or isinstance(v, str) for v in values):
        return [] if values == others else [f"{path}: {shipped} shipped, {made} made"]
    scale = max(max(abs(v) for v in values), 1e-12)
    return [f"{path}[{i}]: {a!r} shipped, {b!r} made" for i, (a, b) in enumerate(zip(values, others))
            if abs(a - b) > RELATIVE_TOLERANCE * scale]


_IDENTIFIED: dict[str, tuple[dict, dict]] = {}


def identified(target: str, scratch: pathlib.Path) -> tuple[dict, dict]:
    """(preset, report) of `piezo-identify stage` run as `make target` runs
    it, once per target for the module."""
    if target not in _IDENTIFIED:
        arguments, _ = makefile_command(target)
        plant = pathlib.Path(arguments[arguments.index("--plant") + 1])
        for path in (BINARY, plant):
            if not path.is_file():
                pytest.fail(f"{path} is missing: run `make fmus` and build the workspace",
                            pytrace=False)
        made, report = scratch / f"{target}.json", scratch / f"{target}.report.json"
        once = scratch / f"{target}.once.json"
        subprocess.run([str(BINARY), "stage", *arguments, "--out", str(made),
                        "--out-fitted-once", str(once), "--report", str(report)],
                       check=True, capture_output=True, text=True)
        _IDENTIFIED[target] = (json.loads(made.read_text()), json.loads(report.read_text()))
        _FITTED_ONCE[target] = json.loads(once.read_text())
    return _IDENTIFIED[target]


_FITTED_ONCE: dict[str, dict] = {}


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> pathlib.Path:
    return tmp_path_factory.mktemp("identified")


@pytest.mark.parametrize("target", ["stage-preset", "stage-memory-preset", "stage-no-memory-preset",
                                    "xy200s-controller-preset"])
def test_the_preset_target_makes_the_shipped_preset(scratch, target):
    _, shipped = makefile_command(target)
    made, _ = identified(target, scratch)
    problems = differences(json.loads(shipped.read_text()), made)
    assert not problems, (
        f"`piezo-identify stage` as `make {target}` runs it no longer makes {shipped.name} "
        f"(run `make {target}` after a plant or identification change):\n" + "\n".join(problems))


@pytest.mark.parametrize("target", ["stage-preset", "stage-memory-preset", "stage-no-memory-preset"])
def test_the_stage_target_makes_the_shipped_law_fitted_once(scratch, target):
    """`make stage-preset` (and `make stage-memory-preset`, on the stage with
    the return-point memory) also writes the preset with D1..D4 fitted once
    (seed 000 §4's procedure, which make demo's seed 000 table runs): the
    same identification gives it again, and it differs from the refined
    preset in the decoupling law alone."""
    shipped = fitted_once_preset(target)
    assert shipped is not None, f"make {target} writes no --out-fitted-once preset"
    made, _ = identified(target, scratch)
    once = _FITTED_ONCE[target]
    problems = differences(json.loads(shipped.read_text()), once)
    assert not problems, (f"`make {target}` no longer makes {shipped.name}:\n"
                          + "\n".join(problems))
    assert {k: v for k, v in once.items() if k != "decoupling_params"} == \
        {k: v for k, v in made.items() if k != "decoupling_params"}
    assert once["decoupling_params"] != made["decoupling_params"]


def test_seed_000s_feedforward_on_the_xy200s_errs_at_most_its_fit(scratch):
    """Seed 000's inverse P-I models identified on the XY200S, run as the
    demo's seed 001 linearity experiments run them (feedforward only, a 2 Hz
    sine about the XY200S's home, the other axis at 0): the largest error may
    not exceed the model's worst error on its own eq. (6) record, in volts,
    times the stage's mean gain (the displacement at the top of the exercise
    cycle over the command's top, about 14.4 um/V). The home lies inside the
    record's range; a model that errs more there has learned something the
    record does not show. Weights that cancel on the record did: with the
    non-reversing operators weighted (b_9 = b_10 = -382 V/um against
    a_4 = +6915 V), x erred by 6.93 um against 5.0 um allowed (0.346 V)."""
    from demo.cosim import Fmu, simulate
    from demo.experiments import abw_xy_key, feedforward_xy_experiments, metrics

    preset, report = identified("xy200s-controller-preset", scratch)
    runs = {e.key: e for e in feedforward_xy_experiments()}
    with Fmu(DIST / "FlexureStage.fmu") as plant, Fmu(DIST / "PiezoController.fmu") as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        for axis in ("x", "y"):
            experiment = runs[abw_xy_key("xy200s", "inverse_pi_piecewise", f"linearity_{axis}")]
            run = simulate(plant, controller, experiment.reference(), experiment.duration,
                           plant_parameters=experiment.plant,
                           controller_parameters=experiment.controller)
            error = metrics(experiment, run, spacing_um)["tracking_max"]
            gain = preset[f"{axis}_model"]["rest_cycle"] / preset["command_max"]
            allowed = report[f"{axis}_fit"]["max_v"] * gain
            print(f"{axis}: max error {error:.3f} um, allowed {allowed:.3f} um "
                  f"({report[f'{axis}_fit']['max_v']:.4f} V x {gain:.2f} um/V)")
            assert error <= allowed


def test_docs_seed001_prints_the_fit_figures_the_targets_make(scratch):
    """docs/seed001.md explains why seed 000's method fails on the XY200S with
    the inverse P-I models' fit to their eq. (6) records on both stages, the
    XY200S's mean gains and the cutoff q3 of D3, all of which the two
    identifications of this module print: each figure must be the one they
    make now (tests/docs_figures.py's rule: 1 % or a unit of the last printed
    digit), so a re-identification that moves them leaves no stale sentence."""
    from tests.docs_figures import stale_prose

    xy200s_preset, xy200s = identified("xy200s-controller-preset", scratch)
    _, flexure = identified("stage-preset", scratch)
    rms = {(stage, axis): report[f"{axis}_fit"]["rms_v"]
           for stage, report in (("xy200s", xy200s), ("flexure", flexure))
           for axis in "xy"}
    gain = {axis: xy200s_preset[f"{axis}_model"]["rest_cycle"] / xy200s_preset["command_max"]
            for axis in "xy"}
    measured = (
        f"{rms['xy200s', 'x']:.4f} V RMS ({xy200s['x_fit']['max_v']:.3f} V max) on the XY200S and "
        f"{rms['flexure', 'x']:.4f} V RMS ({flexure['x_fit']['max_v']:.3f} V max) on FlexureStage, "
        f"{rms['xy200s', 'x'] / rms['flexure', 'x']:.1f}x; y: {rms['xy200s', 'y']:.4f} V and "
        f"{rms['flexure', 'y']:.4f} V, {rms['xy200s', 'y'] / rms['flexure', 'y']:.1f}x. At the "
        f"XY200S's mean gain ({gain['x']:.1f} um/V for x, {gain['y']:.1f} um/V for y: the top of "
        f"the exercise cycle over the {xy200s_preset['command_max']:g} V command) that is "
        f"{rms['xy200s', 'x'] * gain['x']:.2f} um and {rms['xy200s', 'y'] * gain['y']:.2f} um RMS")
    q3 = xy200s_preset["decoupling_params"]["q"][2]
    print(measured, f"q3 = {q3:.2f} um", sep="\n")
    problems = stale_prose("seed001.md", r"record with (\d.*? um RMS)\.", measured,
                           "the inverse P-I fits on eq. (6) and the XY200S's gains")
    problems += stale_prose("seed001.md", r"cutoff q3 = (\S+ um)", f"{q3:.2f} um",
                            "D3's cutoff on the XY200S")
    assert not problems, "\n".join(problems)
