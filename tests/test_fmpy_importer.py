"""FlexureStage.fmu seen from an importer: fmpy 0.3.32 (high- and low-level API).

Each test checks one promise of the FMU (see the module docstrings of the Rust
crates fmi2-cosim and fmu-plant): FMI 2.0 co-simulation state machine, logging,
resource locations, FMU state (also across processes), communication-point
rounding, no direct feedthrough, and the seeded sensor noise.

Helpers (FmuEnv, Slave, LogCapture, ...) live in conftest.py; fmu_child.py is
run in a subprocess where a second process is needed.

Only what fmpy does that a C importer would not is tested here (its
validator and simulate_fmu, start values set while instantiated, its resource
URIs of a path with spaces, its printf logger, its model-description parser,
pickling a state to another process). The ABI rules every importer relies on
are checked once, in Rust, against the same binary (fmi2-conformance/src/
checks.rs, run by fmu-plant/tests/abi_conformance.rs):

- instances independent of each other: `checks::instances_are_independent`;
- a fixed parameter re-set with its value warns, changed is an error, the
  instance then refuses fmi2DoStep until fmi2Reset:
  `checks::fixed_parameters_after_initialization`;
- a resource location that is not a file: URI is accepted with a warning:
  `checks::resource_locations_in_every_spelling`;
- a communication point that skips or repeats a step is refused:
  `checks::communication_points_must_continue`;
- zero, negative, NaN and infinite step sizes are refused:
  `checks::step_sizes_must_be_positive_and_finite`;
- damaged serialized states are refused and change nothing:
  `checks::corrupted_states_are_refused`;
- fmi2SetDebugLogging switches categories, errors always arrive:
  `checks::logging_follows_debug_logging`;
- a refused call (illegal in the state, unknown reference, NULL array, type
  mismatch, non-finite value) enters the error state, getters still work:
  `checks::state_machine_allows_exactly_the_standard_calls`,
  `unknown_value_references_are_refused`, `null_arrays`,
  `type_mismatch_is_refused`, `non_finite_and_partial_sets_change_nothing`.
"""

from __future__ import annotations

import json
import pathlib
import re
import shutil
import subprocess
import sys
import urllib.parse

import fmpy
import numpy as np
import pytest
from fmpy import fmi2
from fmpy.validation import validate_fmu

from conftest import (
    INPUTS,
    OUTPUTS,
    FmuEnv,
    all_finite,
    require_closed_loop_build,
    expect_error,
    hexes,
)

TESTS_DIR = pathlib.Path(__file__).resolve().parent
CHILD = TESTS_DIR / "fmu_child.py"
STEP = 1e-4


def _rows_hex(rows):
    return [hexes(r) for r in rows]


def _first_difference(a, b):
    for i, (ra, rb) in enumerate(zip(a, b)):
        if ra != rb:
            return f"first difference at row {i}: {ra} != {rb}"
    if len(a) != len(b):
        return f"lengths differ: {len(a)} != {len(b)}"
    return "no difference"


# --------------------------------------------------------------------------
# 1. validation and declared capabilities
# --------------------------------------------------------------------------


def test_validate_fmu_reports_no_problem(fmu_path):
    problems = validate_fmu(str(fmu_path))
    assert problems == [], "fmpy.validate_fmu found problems:\n" + "\n".join(problems)

    # The same through the command line an engineer would use.
    cli = subprocess.run(
        [sys.executable, "-m", "fmpy", "validate", str(fmu_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert cli.returncode == 0, f"`fmpy validate` failed:\n{cli.stdout}\n{cli.stderr}"
    assert "No problems found" in cli.stdout, f"`fmpy validate` output:\n{cli.stdout}"


def test_model_description_declares_the_promised_interface(fmu_path):
    md = fmpy.read_model_description(str(fmu_path))
    cs = md.coSimulation
    assert cs is not None and md.modelExchange is not None, "both interfaces are promised"
    assert cs.modelIdentifier == md.modelExchange.modelIdentifier == "FlexureStage"
    expected_flags = {
        "canHandleVariableCommunicationStepSize": True,
        "canGetAndSetFMUstate": True,
        "canSerializeFMUstate": True,
        "canBeInstantiatedOnlyOncePerProcess": False,
        "providesDirectionalDerivative": False,
        "canInterpolateInputs": False,
        "canRunAsynchronuously": False,
    }
    actual = {k: bool(getattr(cs, k)) for k in expected_flags}
    assert actual == expected_flags, f"capability flags differ: {actual}"
    assert int(cs.maxOutputDerivativeOrder or 0) == 0, "no output derivatives are promised"

    by_name = {v.name: v for v in md.modelVariables}
    for name in INPUTS:
        v = by_name[name]
        assert (v.causality, v.type, v.unit) == ("input", "Real", "V"), name
    for name in OUTPUTS:
        v = by_name[name]
        assert (v.causality, v.type) == ("output", "Real"), name
    assert {by_name[n].unit for n in ("s1", "s2", "s3", "x", "y")} == {"um"}
    assert by_name["theta_z"].unit == "rad" and by_name["theta_z"].displayUnit == "deg"
    for i in (1, 2, 3):
        assert by_name[f"amplifier.voltage[{i}]"].causality == "local"
    for name, kind in [
        ("amplifier.gain", "Real"),
        ("amplifier.bandwidth", "Real"),
        ("pzt[1].A", "Real"),
        ("mode.theta.frequency", "Real"),
        ("L", "Real"),
        ("noise.enabled", "Boolean"),
        ("return_point_memory", "Boolean"),
        ("noise.rms", "Real"),
        ("noise.seed", "Integer"),
        ("solver.max_voltage_step", "Real"),
    ]:
        v = by_name[name]
        assert (v.causality, v.variability, v.type) == ("parameter", "fixed", kind), name
    assert float(by_name["amplifier.gain"].start) == 10.0

    categories = [c if isinstance(c, str) else c.name for c in md.logCategories]
    assert set(categories) == {
        "logEvents",
        "logStatusWarning",
        "logStatusDiscard",
        "logStatusError",
        "logStatusFatal",
        "logFmiCalls",
        "logAll",
    }, f"log categories: {categories}"


# --------------------------------------------------------------------------
# 2. simulate_fmu
# --------------------------------------------------------------------------


def test_simulate_fmu_default_experiment_gives_finite_outputs(fmu_path, capsys):
    result = fmpy.simulate_fmu(str(fmu_path))
    names = result.dtype.names
    for name in OUTPUTS:
        assert name in names, f"output {name} missing from the result columns {names}"
        assert np.all(np.isfinite(result[name])), f"non-finite values in {name}"
    md = fmpy.read_model_description(str(fmu_path))
    assert result["time"][0] == float(md.defaultExperiment.startTime) == 0.0
    assert result["time"][-1] == pytest.approx(float(md.defaultExperiment.stopTime))
    printed = capsys.readouterr().out
    assert "[ERROR]" not in printed and "[FATAL]" not in printed, printed


def test_simulate_fmu_held_u1_raises_y(fmu_path, capsys):
    stop, step = 1.0, 1e-4
    signals = np.array(
        [(0.0, 5.0, 0.0, 0.0), (stop, 5.0, 0.0, 0.0)],
        dtype=[("time", float), ("u1", float), ("u2", float), ("u3", float)],
    )
    result = fmpy.simulate_fmu(
        str(fmu_path),
        stop_time=stop,
        step_size=step,
        output_interval=step,
        input=signals,
        output=list(OUTPUTS) + ["amplifier.voltage[1]"],
    )
    expected_rows = round(stop / step) + 1
    assert len(result) == expected_rows, f"{len(result)} result rows, expected {expected_rows}"
    for name in OUTPUTS:
        assert np.all(np.isfinite(result[name])), f"non-finite values in {name}"
    y = result["y"]
    assert y[0] == 0.0, f"the stage must start at rest, y(0) = {y[0]}"
    assert y[-1] > 1.0, f"y should rise to a positive displacement with u1 = 5 V, y(end) = {y[-1]}"
    tail = y[-1000:]  # last 0.1 s: settled (creep only)
    assert np.ptp(tail) < 0.05 * y[-1], f"y has not settled: last 0.1 s spans {np.ptp(tail)} um"
    assert np.all(result["s1"] == y), "with noise off, s1 reads y exactly"
    # Amplifier gain 10: the PZT1 voltage settles at 50 V.
    assert result["amplifier.voltage[1]"][-1] == pytest.approx(50.0, rel=1e-9)
    printed = capsys.readouterr().out
    assert "[WARNING]" not in printed and "[ERROR]" not in printed, printed


# --------------------------------------------------------------------------
# 3. inputs set while Instantiated
# --------------------------------------------------------------------------


def test_fmpy_sets_input_start_values_while_instantiated(fmu_path):
    calls = []
    result = fmpy.simulate_fmu(
        str(fmu_path),
        start_values={"u1": 5.0},
        stop_time=0.01,
        output_interval=1e-4,
        fmi_call_logger=calls.append,
    )
    set_u1 = [i for i, c in enumerate(calls) if c.startswith("fmi2SetReal(") and "vr=[0]" in c]
    enter = [i for i, c in enumerate(calls) if c.startswith("fmi2EnterInitializationMode(")]
    assert set_u1 and enter, "fmpy did not set u1 / enter initialization:\n" + "\n".join(calls[:10])
    assert set_u1[0] < enter[0], "u1 should have been set while Instantiated"
    assert calls[set_u1[0]].endswith("-> OK"), f"setting u1 while Instantiated: {calls[set_u1[0]]}"
    assert result["y"][0] == 0.0, "the stage starts at rest whatever the inputs"
    assert result["y"][-1] > 1.0, f"the held start value of u1 should move y: {result['y'][-1]}"


def test_inputs_set_before_initialization_are_kept_but_stage_starts_at_rest(env):
    s = env.instantiate("instantiated_inputs")
    assert s.set_real({"u1": 8.0, "u2": 8.0}) == fmi2.fmi2OK  # state Instantiated
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    assert s.set_real({"u3": 8.0}) == fmi2.fmi2OK  # state InitializationMode
    s.fmu.exitInitializationMode()
    at_rest = s.get(*OUTPUTS, "amplifier.voltage[1]", "amplifier.voltage[2]", "amplifier.voltage[3]")
    assert at_rest == [0.0] * 9, f"outputs/voltages at t0 must be zero (at rest, de-energized): {at_rest}"
    assert s.get(*INPUTS) == [8.0, 8.0, 8.0], "the inputs set before initialization must be kept"
    s.step_n(50)
    y, x = s.get1("y"), s.get1("x")
    assert y > 0.0 and x > 0.0, f"the inputs set while Instantiated drive the stage: x={x}, y={y}"


# --------------------------------------------------------------------------
# 6. resource locations
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def spaced_unzip_dir(fmu_path, tmp_path_factory):
    """The FMU extracted below a folder whose name contains spaces."""
    root = tmp_path_factory.mktemp("res") / "fmu dir with space"
    root.mkdir()
    directory = fmpy.extract(str(fmu_path), unzipdir=str(root))
    yield pathlib.Path(directory)
    shutil.rmtree(root, ignore_errors=True)


def _resource_locations(unzip: pathlib.Path):
    res = unzip / "resources"
    quoted = urllib.parse.quote(str(res))  # '/tmp/.../fmu%20dir%20with%20space/resources'
    assert "%20" in quoted
    return {
        "file:/": "file:" + quoted,
        "file:///": "file://" + quoted,
        "file://localhost/": "file://localhost" + quoted,
        "percent-encoded (pathlib.as_uri)": res.as_uri(),
        "NULL": None,
    }


RESOURCE_CASES = ["file:/", "file:///", "file://localhost/", "percent-encoded (pathlib.as_uri)", "NULL"]


@pytest.mark.parametrize("case", RESOURCE_CASES)
def test_resource_location_spellings_are_accepted(fmu_path, spaced_unzip_dir, case):
    env = FmuEnv(fmu_path, str(spaced_unzip_dir))
    try:
        location = _resource_locations(spaced_unzip_dir)[case]
        ref = env.instantiate("reference")  # fmpy's own spelling
        ref.initialize(start_values={"u1": 5.0})
        expected = hexes(ref.step_n(100, record=OUTPUTS)[-1])

        s = env.instantiate("resources", resource_location=location)
        assert not s.log.matching(status=fmi2.fmi2Warning) and not s.log.matching(status=fmi2.fmi2Error), (
            f"fmuResourceLocation {location!r} should be accepted silently:\n{s.log.dump()}"
        )
        s.initialize(start_values={"u1": 5.0})
        rows = s.step_n(100, record=OUTPUTS)
        assert all_finite(rows[-1]) and rows[-1][OUTPUTS.index("y")] > 0.0
        assert hexes(rows[-1]) == expected, "the resource location must not change the simulation"
    finally:
        env.free_all()


# --------------------------------------------------------------------------
# 7. communication points in integer nanoseconds (libcosim)
# --------------------------------------------------------------------------


def _libcosim_run(env, name, n=1000):
    s = env.instantiate(name).initialize(start_values={"u1": 2.0})
    summed, off_grid = 0.0, 0
    for k in range(n):
        t = k * 100000 * 1e-9  # libcosim: integer ns -> double seconds
        off_grid += t != summed  # differs from a sum of float steps
        status = s.fmu.fmi2DoStep(s.fmu.component, t, STEP, fmi2.fmi2True)
        assert status == fmi2.fmi2OK, f"step {k} at t = {t!r}: status {status}\n{s.log.dump()}"
        summed += STEP
    return s, off_grid


def test_libcosim_nanosecond_communication_points_are_accepted(env):
    s, off_grid = _libcosim_run(env, "libcosim")
    assert off_grid > 0, "the test should exercise points that differ from a float sum"
    assert s.last_successful_time() == pytest.approx(0.1, abs=1e-12)
    assert all_finite(s.get(*OUTPUTS)) and s.get1("y") > 0.0
    assert not s.log.matching(status=fmi2.fmi2Error), s.log.dump()


@pytest.mark.parametrize("offset,accepted", [(5e-10, True), (-5e-10, True), (3e-9, False), (-3e-9, False)])
def test_communication_point_rounding_tolerance(env, offset, accepted):
    # tolerance = min(1e-9 * max(1, |t|), step / 2) = 1e-9 at t = 0.1
    s, _ = _libcosim_run(env, "tolerance")
    t = 1000 * 100000 * 1e-9 + offset
    if accepted:
        assert s.fmu.fmi2DoStep(s.fmu.component, t, STEP, fmi2.fmi2True) == fmi2.fmi2OK, s.log.dump()
    else:
        expect_error(s.fmu.doStep, t, STEP)
        assert s.log.matching("fmi2DoStep", status=fmi2.fmi2Error), s.log.dump()


# --------------------------------------------------------------------------
# 8. variable communication step sizes
# --------------------------------------------------------------------------


def test_variable_step_sizes(env):
    inputs = {"u1": 5.0, "u2": 3.0, "u3": 1.0}
    var = env.instantiate("variable").initialize(start_values=inputs)
    fixed = env.instantiate("fixed").initialize(start_values=inputs)
    var_rows, fixed_rows = [], []
    for _ in range(100):
        assert var.do_step(1e-4) == fmi2.fmi2OK
        assert var.do_step(3.7e-5) == fmi2.fmi2OK
        var_rows.append(var.get(*OUTPUTS))
        fixed.do_step(1.37e-4)
        fixed_rows.append(fixed.get(*OUTPUTS))
    assert var.last_successful_time() == var.time, "the FMU's time is the sum of the steps"
    assert var.time == pytest.approx(100 * 1.37e-4, rel=1e-12)
    var_rows, fixed_rows = np.array(var_rows), np.array(fixed_rows)
    assert np.all(np.isfinite(var_rows))
    # Both runs reach the same times; the transient (y swings by several um in
    # the first ms) must agree, not only the settled end.
    scale = np.max(np.abs(fixed_rows), axis=0)
    worst = np.max(np.abs(var_rows - fixed_rows) / scale)
    assert worst < 1e-6, f"variable steps deviate from fixed steps by {worst:.3g} of full scale"


# --------------------------------------------------------------------------
# 9. FMU state: across processes, in-process, refusals
# --------------------------------------------------------------------------


def _continue_after_restore(s, steps, new_inputs):
    rows = []
    for k in range(steps):
        if k == steps // 2:
            s.set_real(dict(zip(INPUTS, new_inputs)))
        s.do_step(STEP)
        rows.append(hexes(s.get(*OUTPUTS)))
    return rows


def test_serialized_state_restores_bit_for_bit_in_another_process(env, fmu_path, tmp_path):
    steps, new_inputs = 100, (6.0, 1.0, 3.0)
    a = env.instantiate("origin").initialize(
        start_values={"noise.enabled": True, "noise.seed": 42, "u1": 4.0, "u2": 2.5, "u3": 1.5}
    )
    a.step_n(500)  # t = 0.05
    t_saved = a.time
    assert t_saved == pytest.approx(0.05)
    data = a.serialize_state()
    state_file = tmp_path / "state.bin"
    state_file.write_bytes(data)

    expected = _continue_after_restore(a, steps, new_inputs)  # the original run continues

    # Same bytes, restored in this process in a fresh instance with default parameters.
    b = env.instantiate("restored_here").initialize()
    b.restore_bytes(state_file.read_bytes())
    b.time = t_saved
    assert b.last_successful_time().hex() == t_saved.hex()
    here = _continue_after_restore(b, steps, new_inputs)

    child = subprocess.run(
        [
            sys.executable,
            str(CHILD),
            "restore-state",
            "--fmu", str(fmu_path),
            "--state-file", str(state_file),
            "--time-hex", t_saved.hex(),
            "--step-hex", STEP.hex(),
            "--steps", str(steps),
            "--inputs-hex", ",".join(v.hex() for v in new_inputs),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.returncode == 0, f"child process failed:\n{child.stdout}\n{child.stderr}"
    there = json.loads(child.stdout.strip().splitlines()[-1])
    assert "error" not in there, f"child: {there['error']}\nlog: {there['log']}"
    assert there["restored_time"] == t_saved.hex(), "the state must carry the FMU's time"

    assert here == expected, "in-process restore differs from the original run: " + _first_difference(here, expected)
    assert there["rows"] == here, (
        "restore in another process differs from the in-process restore: "
        + _first_difference(there["rows"], here)
    )
    noise = [float.fromhex(r[0]) - float.fromhex(r[4]) for r in here]
    assert any(d != 0.0 for d in noise), "noise was on: the state must carry the noise settings"


@pytest.mark.parametrize("noise", [False, True], ids=["noise off", "noise on"])
def test_restoring_a_state_reproduces_the_run(env, noise):
    s = env.instantiate("replay").initialize(
        start_values={"noise.enabled": noise, "noise.seed": 5, "u1": 7.0, "u2": 2.0}
    )
    s.step_n(200)
    t0 = s.time
    state = s.fmu.getFMUstate()
    try:
        first = _continue_after_restore(s, 100, (1.0, 8.0, 2.0))
        s.fmu.setFMUstate(state)  # also brings back the inputs held at t0
        s.time = t0
        second = _continue_after_restore(s, 100, (1.0, 8.0, 2.0))
    finally:
        s.fmu.freeFMUstate(state)
    assert first == second, "replay after fmi2SetFMUstate differs: " + _first_difference(first, second)
    if noise:
        assert any(r[0] != r[4] for r in first), "with noise on, s1 should differ from y"


@pytest.mark.parametrize("name", ["FlexureStage", "PiezoController"])
def test_a_run_continues_from_a_finished_runs_state(name):
    """fmpy's fmu_state continues a run from a state a finished run left:
    the state is the FMU's, the stop time each run's own. A first run to
    10 ms with its stopTime set, then one from 10 to 20 ms from its state
    (fmpy calls no fmi2SetupExperiment then), ends where one run to 20 ms
    ends; the state used to bring back the first run's stopTime, which
    refused the second run's first step."""
    require_closed_loop_build()
    fmu_path = TESTS_DIR.parent / "dist" / f"{name}.fmu"
    # Something moves: the stage held at 7 V on u1, the controller's demand.
    start_values = ({"noise.enabled": False, "u1": 7.0} if name == "FlexureStage"
                    else {"y_ref": 3.0})
    kwargs = dict(step_size=STEP, output_interval=STEP)
    whole = fmpy.simulate_fmu(str(fmu_path), stop_time=0.02, start_values=start_values, **kwargs)
    md = fmpy.read_model_description(str(fmu_path))
    unzipped = fmpy.extract(str(fmu_path))
    try:
        fmu = fmi2.FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="first")
        fmu.instantiate()
        try:
            fmpy.simulate_fmu(unzipped, model_description=md, fmu_instance=fmu, stop_time=0.01,
                              start_values=start_values, terminate=False, **kwargs)
            state = fmu.serializeFMUstate(fmu.getFMUstate())
        finally:
            fmu.freeInstance()
        # The state holds the start values and the inputs set.
        rest = fmpy.simulate_fmu(unzipped, start_time=0.01, stop_time=0.02, fmu_state=state,
                                 **kwargs)
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)
    name = md.outputs[0].variable.name
    assert rest["time"][-1] == pytest.approx(0.02)
    # The second run's communication points are 0.01 + k h, not a sum of
    # steps from 0: the last bits may differ.
    assert rest[name][-1] == pytest.approx(whole[name][-1], rel=1e-12, abs=0.0), name
    assert rest[name][-1] != rest[name][0], f"{name} should move over the second run"


def test_values_of_another_kind_are_refused_not_converted():
    """demo.cosim sets parameters through demo.fmu's set_values: "false"
    would be true to bool() and 1.9 an int() 1, each run with exit 0."""
    from demo.cosim import Fmu

    with Fmu(TESTS_DIR.parent / "dist" / "PiezoController.fmu") as controller:
        s = controller.instance("kinds")
        try:
            for values, message in [
                ({"feedback_y": "false"}, "'feedback_y' is a Boolean variable, which takes "
                                          "True or False; 'false' was given"),
                ({"hysteresis_model": 1.9}, "'hysteresis_model' is a Integer variable, which "
                                            "takes a whole number; 1.9 was given"),
                ({"y_ref": "5"}, "'y_ref' is a Real variable, which takes a number; '5' was "
                                 "given"),
            ]:
                with pytest.raises(TypeError) as refused:
                    s.set_values(values)
                assert str(refused.value).endswith(message)
            s.set_values({"feedback_y": False, "hysteresis_model": 1.0, "y_ref": 5,
                          "decoupling": np.bool_(True)})
        finally:
            s.free()


# --------------------------------------------------------------------------
# 10. '%' and '#' in log messages
# --------------------------------------------------------------------------

LONE_PERCENT = re.compile(r"%(?!%)")


def _has_lone_percent(raw: str) -> bool:
    return bool(LONE_PERCENT.search(raw.replace("%%", "")))


def test_percent_in_messages_is_doubled(env):
    s = env.instantiate("probe%s", logging_on=True, resource_location="http://example.org/a%20b")
    cats = (fmi2.fmi2String * 2)(b"log%s%d", b"tag#r1#")
    status = s.fmu.fmi2SetDebugLogging(s.fmu.component, fmi2.fmi2True, 2, cats)
    assert status == fmi2.fmi2Warning, f"an unknown category should give fmi2Warning, got {status}"
    s.initialize()
    s.step_n(3)

    unknown = s.log.matching('unknown log category "log%s%d"', status=fmi2.fmi2Warning)
    assert unknown, f"no warning quoting the unknown category:\n{s.log.dump()}"
    assert '"log%%s%%d"' in unknown[0].raw, f"'%' must be doubled in the raw message: {unknown[0].raw}"
    # '#' opens a variable reference that FMI importers expand (#r1# -> a name).
    tagged = s.log.matching('unknown log category "tag#r1#"', status=fmi2.fmi2Warning)
    assert tagged and '"tag##r1##"' in tagged[0].raw, f"'#' must be doubled: {s.log.dump()}"
    location = s.log.matching("http://example.org/a%20b", status=fmi2.fmi2Warning)
    assert location and "a%%20b" in location[0].raw, f"resource warning: {s.log.dump()}"
    lone = [r for r in s.log.records if _has_lone_percent(r.raw)]
    assert not lone, "messages with an undoubled '%':\n" + "\n".join(map(str, lone))
    assert {r.instance_name for r in s.log.records} == {"probe%s"}, "instance name must arrive intact"


def test_percent_messages_survive_fmpys_printf_logger(fmu_path):
    # Run in a child process: an unescaped '%s' would make fmpy's native
    # vsnprintf proxy read garbage and could crash the whole pytest process.
    child = subprocess.run(
        [sys.executable, str(CHILD), "percent-log", "--fmu", str(fmu_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert child.returncode == 0, f"child crashed ({child.returncode}):\n{child.stdout}\n{child.stderr}"
    out = json.loads(child.stdout.strip().splitlines()[-1])
    assert "error" not in out, out
    log = out["log"]
    assert log, "no message reached the logger"
    assert all(r["instance"] == "probe%s" for r in log), log
    unknown = [r for r in log if 'unknown log category "log%s%d"' in r["message"]]
    assert unknown, "after printf formatting the message should read exactly log%s%d:\n" + "\n".join(
        r["message"] for r in log
    )
    traces = [r for r in log if r["category"] == "logFmiCalls" and r["message"].startswith("fmi2DoStep")]
    assert traces, "the logFmiCalls trace of fmi2DoStep should arrive through the proxy"


# --------------------------------------------------------------------------
# 11. fmi2SetDebugLogging
# --------------------------------------------------------------------------


def test_log_fmi_calls_traces_every_call(env):
    s = env.instantiate("trace_all", logging_on=False)
    s.fmu.setDebugLogging(True, ["logFmiCalls"])
    s.log.clear()
    s.fmu.setupExperiment(startTime=0.0)
    s.set_real({"u1": 1.0})
    s.fmu.enterInitializationMode()
    s.fmu.exitInitializationMode()
    s.get("y")
    s.do_step(STEP)
    state = s.fmu.getFMUstate()
    s.fmu.setFMUstate(state)
    s.fmu.freeFMUstate(state)
    s.fmu.terminate()
    s.fmu.reset()
    called = [
        "fmi2SetupExperiment",
        "fmi2SetReal",
        "fmi2EnterInitializationMode",
        "fmi2ExitInitializationMode",
        "fmi2GetReal",
        "fmi2DoStep",
        "fmi2GetFMUstate",
        "fmi2SetFMUstate",
        "fmi2FreeFMUstate",
        "fmi2Terminate",
        "fmi2Reset",
    ]
    traced = {r.text.split(":", 1)[0] for r in s.log.records if r.category == "logFmiCalls"}
    missing = [f for f in called if f not in traced]
    assert not missing, (
        f"logFmiCalls is on but these calls were not traced: {missing}\nlog:\n{s.log.dump()}"
    )


# --------------------------------------------------------------------------
# 12. no direct feedthrough
# --------------------------------------------------------------------------


def test_outputs_have_no_direct_feedthrough(env):
    md = env.md
    # No output depends on an input; in Model Exchange the sensors depend on
    # the pose states (x, y, theta_z, outputs themselves, list none).
    states = {d.variable.derivative.name for d in md.derivatives}
    for unknown in md.outputs:
        names = [v.name for v in unknown.dependencies]
        assert not set(names) & set(INPUTS), f"{unknown.variable.name} depends on {names}"
        assert set(names) <= states, f"{unknown.variable.name} depends on {names}"
    # After initialization the outputs and the states are at rest, whatever
    # the inputs and parameters; the hysteretic states rest where their
    # parameters settle them: they depend on every known (no list).
    for unknown in md.initialUnknowns:
        if unknown.variable.name.endswith(".h"):
            assert unknown.dependencies is None or unknown.dependencies == list(
                md.modelVariables), unknown.dependencies
        elif unknown.variable.causality == "output" or unknown.variable.name in states:
            assert unknown.dependencies == [], (
                f"{unknown.variable.name}: initial dependencies should be empty, got "
                f"{[v.name for v in unknown.dependencies] if unknown.dependencies is not None else None}"
            )
    assert {u.variable.name for u in md.outputs} == set(OUTPUTS)

    s = env.instantiate("feedthrough").initialize()
    before_init = s.get(*OUTPUTS)
    s.set_real({"u1": 8.0})
    assert s.get(*OUTPUTS) == before_init, "outputs changed after fmi2SetReal at t0 without a step"

    s.step_n(20)
    before = hexes(s.get(*OUTPUTS))
    s.set_real({"u1": 0.0, "u2": 8.0, "u3": 2.0})
    assert hexes(s.get(*OUTPUTS)) == before, "outputs changed after fmi2SetReal without fmi2DoStep"
    s.do_step(STEP)
    assert hexes(s.get(*OUTPUTS)) != before, "outputs should change after fmi2DoStep"


# --------------------------------------------------------------------------
# 14. sensor noise
# --------------------------------------------------------------------------


def _noise_run(env, enabled, seed, n, rms=None):
    values = {"noise.enabled": enabled, "noise.seed": seed, "u1": 4.0, "u2": 3.0, "u3": 2.0}
    if rms is not None:
        values["noise.rms"] = rms
    s = env.instantiate("noise").initialize(start_values=values)
    rows = np.array(s.step_n(n, STEP, record=OUTPUTS))
    rms_param, spacing_mm = s.get1("noise.rms"), s.get1("L")
    s.free()
    return rows, rms_param, spacing_mm


def _minor_loop_rests(env, memory):
    """y at the 0 V end of each of four 0 -> 0.8 V -> 0 command cycles (1 s each,
    10 kHz, PZT1 alone), from the stage's rest."""
    s = env.instantiate("loops").initialize(
        start_values={"return_point_memory": memory, "u1": 0.0, "u2": 0.0, "u3": 0.0})
    rests = []
    for _ in range(4):
        for k in range(10_000):
            s.set_real({"u1": 0.8 * np.sin(np.pi * (k + 1) / 10_000) ** 2})
            s.do_step(STEP)
        rests.append(s.get1("y"))
    s.free()
    return rests


def test_return_point_memory_closes_the_stacks_minor_loops(env):
    # MODEL.md §6: without the memory PZT1's 0 -> 8 V -> 0 loops sink by 0.23, 0.34,
    # 0.38, 0.40 um after 1-4 cycles. With it the hysteresis closes each loop, and what
    # is left at each rest is the creep's tail (first order, 1.5 s): the tails of the
    # 1 s cycles add up as a geometric series of ratio exp(-1/1.5), a few nm in all.
    drifting = _minor_loop_rests(env, False)
    closing = _minor_loop_rests(env, True)
    assert drifting[-1] < -0.3, drifting
    assert max(abs(r) for r in closing) < 0.005, closing
    added = np.diff(closing)
    ratios = added[1:] / added[:-1]
    assert np.allclose(ratios, np.exp(-1 / 1.5), rtol=0.05), (closing, ratios)


def test_return_point_memory_closes_the_loops_in_model_exchange(env):
    """The test above in Model Exchange: fmpy's CVode, the command held over
    1 ms steps (each step's two time stamps, which fmpy turns into input
    events: its CVode does not set an interpolated input where it evaluates
    the derivatives, docs/fmi.md), so every turn and wipe-out of the memory
    is an event update. Bound: the Co-Simulation rests' 5 nm, and the two
    interfaces' rests within 1 nm of each other (the 1 ms staircase against
    the 0.1 ms one)."""
    t = np.arange(0.0, 2.0 + 1e-9, 1e-3)  # the first two cycles
    held = np.zeros(2 * len(t) - 1, dtype=[("time", float), ("u1", float), ("u2", float),
                                           ("u3", float)])
    held["time"] = np.repeat(t, 2)[1:]
    held["u1"] = np.repeat(0.8 * np.sin(np.pi * (t + 1e-3)) ** 2, 2)[:-1]
    result = fmpy.simulate_fmu(
        str(env.fmu_path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-8,
        start_values={"return_point_memory": True}, input=held, stop_time=2.0,
        output_interval=1e-3, output=["y"])
    rests = [float(result["y"][np.flatnonzero(np.isclose(result["time"], c))[-1]])
             for c in (1, 2)]
    co_simulation = _minor_loop_rests(env, True)[:2]
    print(f"rests, Model Exchange {rests}, Co-Simulation {co_simulation} um")
    assert max(abs(r) for r in rests) < 0.005, rests
    assert np.allclose(rests, co_simulation, rtol=0, atol=1e-3), (rests, co_simulation)


def test_sensor_noise_rms_and_seeding(env):
    n = 10_000
    rows, rms, spacing_mm = _noise_run(env, True, 7, n)
    s1, s2, s3, x, y, theta = rows.T
    half = theta * spacing_mm * 1e3 / 2  # rad * mm -> um
    d1, d2, d3 = s1 - y, s2 - (x + half), s3 - (x - half)
    assert np.count_nonzero(d1) == n, "every step should draw a fresh noise sample for s1"
    for label, d in (("s1 - y", d1), ("s2 - (x + theta L/2)", d2), ("s3 - (x - theta L/2)", d3)):
        measured = float(np.sqrt(np.mean(d**2)))
        assert abs(measured / rms - 1.0) < 0.10, f"{label}: RMS {measured:.4g} um vs noise.rms {rms} um"
    assert not np.array_equal(d1, d2), "the sensors need independent noise"

    same, _, _ = _noise_run(env, True, 7, 500)
    assert same.tobytes() == rows[:500].tobytes(), "the same seed must give the same sequence"
    other, _, _ = _noise_run(env, True, 8, 500)
    assert not np.array_equal(other[:, 0], rows[:500, 0]), "another seed must give another sequence"

    quiet, _, _ = _noise_run(env, False, 7, 500)
    assert np.array_equal(quiet[:, 0], quiet[:, 4]), "noise disabled: s1 must equal y exactly"
    # x, y, theta_z stay noise-free: identical with and without noise.
    assert quiet[:, 3:].tobytes() == rows[:500, 3:].tobytes(), "noise leaked into x, y or theta_z"


def test_sensor_noise_rms_parameter_is_used(env):
    rows, rms, _ = _noise_run(env, True, 3, 4000, rms=0.25)
    assert rms == 0.25
    measured = float(np.sqrt(np.mean((rows[:, 0] - rows[:, 4]) ** 2)))
    assert abs(measured / 0.25 - 1.0) < 0.10, f"RMS {measured} um with noise.rms = 0.25 um"


# --------------------------------------------------------------------------
# amplifier clipping (E-505: input -3..13 V, output -30..130 V; one warning
# per channel)
# --------------------------------------------------------------------------


def test_amplifier_clipping_warns_once_per_channel(env):
    s = env.instantiate("clip").initialize()
    s.set_real({"u1": 15.0, "u2": -4.0, "u3": 5.0})
    s.step_n(500)  # 50 ms: the 3 kHz amplifiers have settled
    v = s.get("amplifier.voltage[1]", "amplifier.voltage[2]", "amplifier.voltage[3]")
    assert v[0] == pytest.approx(130.0) and v[1] == pytest.approx(-30.0) and v[2] == pytest.approx(50.0), (
        f"amplifier voltages {v}: expected 15 V clipped to 13 V (130 V), -4 V to -3 V (-30 V), 50 V"
    )
    warnings = s.log.matching("clipped", status=fmi2.fmi2Warning)
    per_channel = sorted(re.search(r"PZT(\d)", w.text).group(1) for w in warnings)
    assert per_channel == ["1", "2"], f"one warning per clipped channel expected:\n{s.log.dump()}"
