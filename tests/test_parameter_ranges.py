"""Parameters out of their physical range, and states that leave it.

Through the C ABI (fmpy's FMU2Slave with a recording logger), for both FMUs:

- every parameter with a declared `min`/`max` in modelDescription.xml is refused
  at fmi2ExitInitializationMode when set outside it, with fmi2Error and a log
  line naming the parameter, the value and the declared range;
- the ranges a declaration cannot express (strict bounds such as L > 0, one
  parameter against another such as v_max > v_min) are refused the same way,
  with the model's own rule in the message;
- a refused instance recovers with fmi2Reset;
- (a NaN or infinite parameter never gets that far: fmi2SetReal refuses it, as
  the conformance harness checks for every variable);
- a parameter set that passes every check but lets the hysteresis diverge, and
  controller gains that overflow, end the step with fmi2Error naming the state
  or output and the time, never with a silent NaN.
"""

from __future__ import annotations

import math
import re
import shutil
import tempfile
import sys

import fmpy
import pytest
from fmpy import fmi2
from fmpy.fmi1 import FMICallException

from tests.conftest import REPO_ROOT, FmuEnv, STATUS_NAMES

MODELS = ("FlexureStage", "PiezoController")


def make_env(model_name: str) -> FmuEnv:
    path = REPO_ROOT / "dist" / f"{model_name}.fmu"
    if not path.is_file():
        pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    return FmuEnv(path, fmpy.extract(str(path), unzipdir=tempfile.mkdtemp(prefix="ranges_")))


@pytest.fixture(scope="module")
def envs():
    made = {name: make_env(name) for name in MODELS}
    yield made
    for env in made.values():
        env.free_all()
        shutil.rmtree(env.unzip_dir, ignore_errors=True)


def refused_at_exit_initialization(env: FmuEnv, values: dict) -> list:
    """Sets `values` in initialization mode and returns the error records that
    fmi2ExitInitializationMode logged while refusing them."""
    slave = env.instantiate("ranges", logging_on=False)
    slave.fmu.setupExperiment(startTime=0.0)
    slave.fmu.enterInitializationMode()
    for name, value in values.items():
        # Setting is accepted: a parameter is checked as a whole set, when the
        # importer says it is complete (FMI 2.0.4 §4.2.4).
        status = {"Real": slave.set_real, "Integer": slave.set_integer}[env.types[name]](
            {name: value})
        assert status == fmi2.fmi2OK, f"setting {name} = {value} returned {status}"
    slave.log.clear()
    with pytest.raises(FMICallException) as info:
        slave.fmu.exitInitializationMode()
    assert info.value.status == fmi2.fmi2Error, STATUS_NAMES.get(info.value.status)
    errors = [r for r in slave.log.records if r.status == fmi2.fmi2Error]
    assert errors, f"fmi2ExitInitializationMode refused {values} without a log line"
    # The standard allows fmi2Reset from the error state; the instance is
    # usable again with its start values.
    assert slave.fmu.fmi2Reset(slave.fmu.component) == fmi2.fmi2OK, slave.log.dump()
    slave.initialize()
    assert step_status(slave, 1e-4) == fmi2.fmi2OK, slave.log.dump()
    slave.free()
    return errors


def step_status(slave, step: float) -> int:
    """fmi2DoStep's status, whatever it is (fmpy raises above fmi2Warning)."""
    try:
        slave.fmu.doStep(slave.time, step)
    except FMICallException as e:
        return e.status
    finally:
        slave.time += step
    return fmi2.fmi2OK


def declared_ranges(env: FmuEnv):
    for v in env.md.modelVariables:
        if v.causality == "parameter" and v.type in ("Real", "Integer") and (
                v.min is not None or v.max is not None):
            yield v


def outside(v) -> list:
    """One value below the declared min and one above the declared max."""
    cast = int if v.type == "Integer" else float
    values = []
    if v.min is not None:
        low = cast(v.min)
        values.append(low - max(1, abs(low)))
    if v.max is not None:
        high = cast(v.max)
        values.append(high + max(1, abs(high)))
    return values


def rust_real(x: float) -> str:
    """A number as the FMU writes it (format_real: shortest digits, with an
    exponent outside 1e-4..1e7)."""
    if x == 0 or 1e-4 <= abs(x) < 1e7:
        text = repr(float(x))
        return text[:-2] if text.endswith(".0") else text
    mantissa, exponent = f"{x!r}".replace("E", "e").split("e") if "e" in repr(x) else (
        repr(x), "0")
    mantissa = mantissa[:-2] if mantissa.endswith(".0") else mantissa
    return f"{mantissa}e{int(exponent)}"


def interval(v) -> str:
    """The declared range as the FMU's message writes it: an open end, which
    FMI's inclusive min and max declare as the nearest double inside it (for
    > 0 the smallest normal double, sys.float_info.min), in a round bracket at
    the round value next to it."""
    def end(bound, toward: float, closed: str, opened: str) -> str:
        value = float(bound)
        outside = 0.0 if abs(value) == sys.float_info.min else math.nextafter(value, toward)
        if len(rust_real(outside)) < len(rust_real(value)):
            return opened.format(rust_real(outside))
        return closed.format(rust_real(value))
    low = "[-inf" if v.min is None else end(v.min, -math.inf, "[{}", "({}")
    high = "inf]" if v.max is None else end(v.max, math.inf, "{}]", "{})")
    return f"{low}, {high}"


def test_open_ends_are_declared_inside_and_their_values_taken(envs):
    """FMI's min and max are inclusive: a parameter that must be > 0 declares
    the nearest double above 0, and the FMU takes that value (a tool that
    samples at the declared bounds gets no refusal); 0 itself is refused, as
    the description says."""
    cases = {"FlexureStage": ("mode.x.damping", "L"), "PiezoController": ("x.c", "L")}
    for model, names in cases.items():
        env = envs[model]
        for name in names:
            v = next(v for v in env.md.modelVariables if v.name == name)
            # Not the subnormal 5e-324, which C's strtod reports out of range.
            assert float(v.min) == sys.float_info.min, (name, v.min)
            assert "> 0" in v.description or "0 <" in v.description, v.description
            assert not refused_at_exit_initialization(env, {name: 0.0}) == [], name
    damping = next(v for v in envs["FlexureStage"].md.modelVariables if v.name == "mode.x.damping")
    assert float(damping.max) == math.nextafter(1.0, 0.0), damping.max
    slave = envs["FlexureStage"].instantiate("bounds")
    slave.initialize(start_values={"mode.x.damping": float(damping.max), "amplifier.gain": sys.float_info.min})
    assert step_status(slave, 1e-4) == fmi2.fmi2OK, slave.log.dump()
    slave.free()


def test_every_declared_range_is_enforced(envs):
    checked = 0
    names = set()
    for env in envs.values():
        parameters = list(declared_ranges(env))
        assert parameters, f"{env.md.modelName} declares no parameter range"
        for v in parameters:
            for value in outside(v):
                errors = refused_at_exit_initialization(env, {v.name: value})
                text = " ".join(r.text for r in errors)
                assert v.name in text, text
                assert f"= {value:g} is outside its allowed range {interval(v)}" in text, text
                checked += 1
                names.add(v.name)
    print(f"{checked} out-of-range values refused at fmi2ExitInitializationMode")
    # The ranges the physics fixes are declared (a lost declaration fails here).
    assert {"pzt[1].n", "coupling.x_from_pzt1.n", "amplifier.gain", "mode.x.damping",
            "solver.max_voltage_step", "noise.seed", "translation.kp", "rotation.ki", "x.c",
            "y.u1max", "bouc_wen.y_from_x.n", "hysteresis_model", "L"} <= names, names


# The list, and the rules no min/max can declare. Each case: the FMU,
# the values set, and what the message must contain besides the parameter's
# name and value.
PHYSICAL_RANGE_CASES = [
    # negative thresholds (seed 000 eq. 5: d = c·[0,1,3,5,7,9], r = u1max·[…])
    ("PiezoController", {"x.c": -0.5}, "x.c", "-0.5", "(0, inf]"),
    ("PiezoController", {"y.u1max": -11.0}, "y.u1max", "-11", "(0, inf]"),
    # c = 0 makes every dead-zone threshold 0: not increasing (an open end:
    # the declared min is the double next above 0)
    ("PiezoController", {"x.c": 0.0}, "x.c", "= 0", "(0, inf]"),
    ("PiezoController", {"y.u1max": 0.0}, "y.u1max", "= 0", "(0, inf]"),
    # Bouc-Wen n below 1 (|h|^(n-1) must stay finite at h = 0)
    ("FlexureStage", {"pzt[2].n": 0.5}, "pzt[2].n", "0.5", "[1, inf]"),
    ("FlexureStage", {"coupling.y_from_pzt3.n": 0.99}, "coupling.y_from_pzt3.n", "0.99",
     "[1, inf]"),
    ("PiezoController", {"bouc_wen.y.n": 0.9}, "bouc_wen.y.n", "0.9", "[1, inf]"),
    # negative and zero gains
    ("PiezoController", {"translation.kp": -0.05}, "translation.kp", "-0.05", "[0, inf]"),
    ("PiezoController", {"rotation.ki": -70.0}, "rotation.ki", "-70", "[0, inf]"),
    ("FlexureStage", {"amplifier.gain": -10.0}, "amplifier.gain", "-10", "(0, inf]"),
    ("FlexureStage", {"amplifier.gain": 0.0}, "amplifier.gain", "= 0", "(0, inf]"),
    # a subnormal value, inside (0, ...) but below the declared min (the
    # smallest normal double): the message says why it is refused
    ("FlexureStage", {"amplifier.gain": 1e-310}, "amplifier.gain", "= 1e-310",
     "(0, inf] (a subnormal double: the range ends at the smallest normal double, "
     "2.2250738585072014e-308, as the declared min says)"),
    # a zero sensor spacing L (theta = (s2 - s3) / L)
    ("PiezoController", {"L": 0.0}, "L", "= 0", "(0, inf]"),
    ("FlexureStage", {"L": 0.0}, "L", "= 0", "(0, inf]"),
    # bounds that depend on another parameter
    ("PiezoController", {"command_min": 5.0, "command_max": 5.0}, "command_max", "= 5",
     "> command_min"),
    ("FlexureStage", {"amplifier.v_max": -40.0}, "amplifier.v_max", "= -40", "v_max > v_min"),
    ("FlexureStage", {"pzt[1].creep_time": 1e-5}, "pzt[1].creep_time", "0.00001",
     "creep_time > 10 x amplifier time constant"),
    # no mode without a frequency; damping within (0, 1)
    ("FlexureStage", {"mode.theta.frequency": 0.0}, "mode.theta.frequency", "= 0", "(0, inf]"),
    ("FlexureStage", {"mode.x.damping": 1.5}, "mode.x.damping", "1.5", "(0, 1)"),
    # selectors
    ("PiezoController", {"hysteresis_model": 3}, "hysteresis_model", "3", "[1, 2]"),
]


@pytest.mark.parametrize("model_name, values, name, value_text, rule", PHYSICAL_RANGE_CASES,
                         ids=[f"{c[0]}-{c[2]}={list(c[1].values())[-1]}"
                              for c in PHYSICAL_RANGE_CASES])
def test_parameters_out_of_physical_range_are_refused(envs, model_name, values, name,
                                                      value_text, rule):
    errors = refused_at_exit_initialization(envs[model_name], values)
    text = " ".join(r.text for r in errors)
    assert "fmi2ExitInitializationMode" in text, text
    assert name in text, text
    assert value_text in text, text
    assert rule in text, text


def test_values_far_from_one_are_written_short_and_only_subnormals_get_the_note(envs):
    """A value is written as the description writes numbers (1e300, not 301
    digits), and the subnormal note goes only where it explains a refusal:
    -1e-310 is refused for being negative."""
    for values, shown in (({"amplifier.gain": -1e-310}, "= -1e-310 is outside"),
                          ({"solver.max_voltage_step": 1e300}, "= 1e300 is outside")):
        text = " ".join(r.text for r in refused_at_exit_initialization(envs["FlexureStage"],
                                                                       values))
        assert shown in text and "subnormal" not in text, text
        assert max(len(line) for line in text.splitlines()) < 300, text


#: Sample periods that are not a positive finite number.
SAMPLE_PERIODS = [0.0, -1e-4, math.nan, math.inf]


@pytest.mark.parametrize("step", SAMPLE_PERIODS)
def test_controller_sample_period_must_be_positive(envs, step):
    """The controller samples once per communication step (its sample period
    is the step size), so a period that is not positive is a refused step."""
    slave = envs["PiezoController"].instantiate("period")
    slave.initialize()
    slave.log.clear()
    status = step_status(slave, step)
    assert status == fmi2.fmi2Error, STATUS_NAMES.get(status)
    assert slave.log.matching("fmi2DoStep", status=fmi2.fmi2Error), slave.log.dump()
    slave.free()


def test_diverging_hysteresis_is_reported_with_variable_and_time(envs):
    """beta + gamma < 0 passes every parameter check where the model stays
    bounded over the amplifier's range (softening hysteresis is a legitimate
    shape over a short travel), but with n = 2 and delta = 0 the state escapes
    to infinity at u* = pi / (2 sqrt(A c)) of travel: dh/du = A + c·h², here
    c = 6.8e-5 and A = 0.008, so u* = 2130 V, past the 1 kV the build checks
    and inside a 10 kV amplifier's range. The step where it happens must fail,
    naming the state, the time and the likely cause."""
    env = envs["FlexureStage"]
    slave = env.instantiate("diverging")
    # From a de-energized, never-cycled stack: the ramp below is its first
    # travel.
    slave.initialize(start_values={
        "rest_cycle_voltage": 0.0,
        "amplifier.gain": 1000.0,
        "amplifier.v_max": 1e4,
        "coupling.x_from_pzt1.beta": -5.5e-5,
        "coupling.x_from_pzt1.gamma": -1.3e-5,
        "coupling.x_from_pzt1.delta": 0.0,
    })
    # A ramp of the command, 5 V/s (5 kV/s of amplifier output): the escape
    # near 2130 V comes after some 4300 steps, not in the first.
    status = fmi2.fmi2OK
    steps = 0
    while status == fmi2.fmi2OK and steps < 20_000:
        slave.set_real({"u1": 5.0 * slave.time})
        status = step_status(slave, 1e-4)
        steps += 1
    assert status == fmi2.fmi2Error, f"no error after {steps} steps: {slave.log.dump()}"
    assert 2000 < steps < 8000, steps
    failed_at = slave.time
    message = " ".join(r.text for r in slave.log.matching("diverged", status=fmi2.fmi2Error))
    assert "coupling x from PZT1" in message, slave.log.dump()
    assert "likely cause: a Bouc-Wen model whose state runs away" in message, message
    reported = re.search(r"to t = ([-+0-9.e]+)", message)
    assert reported and abs(float(reported.group(1)) - failed_at) < 1e-9, (failed_at, message)
    # The instance is in the error state: stepping on is refused, not NaN.
    assert step_status(slave, 1e-4) == fmi2.fmi2Error
    print(f"diverged after {steps} steps: {message}")
    # README.md shows this message, its times to 0.1 ms and cut after the state.
    shown = " ".join(readme_log("A stage state that diverges"))
    rounded = re.sub(r"t = ([-+0-9.e]+)", lambda m: f"t = {float(m.group(1)):.4f}", message)
    assert shown.endswith(" ...") and shown[:-len(" ...")] in rounded, (shown, rounded)
    slave.free()


def test_diverging_hysteresis_in_the_amplifier_range_is_refused_at_initialization(envs):
    """beta + gamma = -0.68 with n = 2 escapes within 21 V of travel, inside
    the amplifier's -30..130 V: initialization is refused, naming the
    parameter by its FMI name (a stack's as pzt[k], not the model's internal
    path) and the runaway, and the instance does not step (no NaN reaches an
    output)."""
    for changed, named in (
        ({"coupling.x_from_pzt1.beta": -0.55, "coupling.x_from_pzt1.gamma": -0.13},
         "coupling.x_from_pzt1.gamma"),
        ({"pzt[1].beta": -1.0}, "pzt[1].beta"),
    ):
        slave = envs["FlexureStage"].instantiate("runaway")
        status = fmi2.fmi2OK
        try:
            slave.initialize(start_values=changed)
            status = step_status(slave, 1e-4)
        except FMICallException as failed:
            status = failed.status
        assert status == fmi2.fmi2Error, slave.log.dump()
        message = " ".join(r.text for r in slave.log.matching("runs away", status=fmi2.fmi2Error))
        assert f"parameter {named} (" in message, slave.log.dump()
        assert "output range -30..130 V" in message and "actuators[" not in message.split(
            ") = ")[1], message
        assert step_status(slave, 1e-4) == fmi2.fmi2Error
        print(message)
        slave.free()


def test_sound_parameters_never_trip_the_divergence_check(envs):
    """The same drive with the shipped parameters runs through: the bound
    (1 m) is far from any real state."""
    slave = envs["FlexureStage"].instantiate("sound")
    slave.initialize()
    slave.set_real({"u1": 10.0, "u2": 10.0, "u3": 10.0})
    for _ in range(2000):
        assert step_status(slave, 1e-4) == fmi2.fmi2OK, slave.log.dump()
    slave.free()


def test_overflowing_controller_output_is_an_error(envs):
    """Gains near f64::MAX are within the declared range [0, inf) but make the
    x and theta feedback +inf and -inf on the same PZT channel: the sum is NaN,
    which must not reach the plant."""
    slave = envs["PiezoController"].instantiate("overflow")
    slave.initialize(start_values={"translation.kp": 1e308, "rotation.kp": 1e308})
    # x error +5 um; theta error of the opposite sign on s3's channel.
    slave.set_real({"x_ref": 5.0, "s1": 0.0, "s2": 0.0, "s3": 3.0})
    status = step_status(slave, 1e-4)
    assert status == fmi2.fmi2Error, slave.log.dump()
    text = " ".join(r.text for r in slave.log.matching("became", status=fmi2.fmi2Error))
    # The first non-finite output by its FMI name, and the time.
    assert re.search(r"t = 0: \w+ became (NaN|inf|-inf)", text), slave.log.dump()
    slave.free()


def readme_log(after: str) -> list[str]:
    """The lines of the README's first text block (a log excerpt) after the
    paragraph that says `after`."""
    from tests.test_readme import blocks

    text = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    line = text[:text.index(after)].count("\n") + 1
    # The first block after the paragraph must be one without a language
    # (a log), not code.
    _, language, code, _ = next(b for b in blocks() if b[0] > line)
    assert not language, f"README.md: no log block right after {after!r}"
    return code.splitlines()


def test_the_readmes_refusals_are_what_the_fmus_log(envs):
    """README.md shows three refusals at fmi2ExitInitializationMode: each line is
    the one the FMU logs for that value, word for word."""
    shown = readme_log("offence, and `fmi2Reset` brings back the start values")
    cases = [("FlexureStage", {"pzt[2].n": 0.5}), ("PiezoController", {"x.c": 0.0}),
             ("FlexureStage", {"pzt[1].creep_time": 1e-5})]
    assert len(shown) == len(cases), shown
    for line, (name, values) in zip(shown, cases):
        logged = [r.text for r in refused_at_exit_initialization(envs[name], values)]
        print(logged)
        assert line in logged, (line, logged)


def test_initial_unknowns_read_in_initialization_mode_follow_the_parameters_set(envs):
    """FMI 2.0's InitialUnknowns are functions of the knowns set: read in
    Initialization Mode (as libcosim and OMSimulator read them, to wire the
    other FMU's inputs), they are what fmi2ExitInitializationMode then makes
    of the parameters set, not what the start values would give. A set of
    values no initialization would take is refused there already, with the
    reason (fmi2Warning: an importer may pass through such a set on its way);
    fmi2ExitInitializationMode refuses them if they stay."""
    cases = {"PiezoController": ({"command_min": 1.0}, "u1", 1.0),
             "FlexureStage": ({"rest_cycle_voltage": 50.0}, "pzt[1].h", None)}
    for model, (parameters, unknown, expected) in cases.items():
        env = envs[model]
        slave = env.instantiate("initial-unknowns")
        default = slave.initialize().get1(unknown)
        slave.free()
        slave = env.instantiate("initial-unknowns")
        assert slave.set_real(parameters) == fmi2.fmi2OK
        slave.fmu.setupExperiment(startTime=0.0)
        slave.fmu.enterInitializationMode()
        during = slave.get1(unknown)
        slave.fmu.exitInitializationMode()
        after = slave.get1(unknown)
        assert during == after != default, (model, unknown, during, after, default)
        assert expected is None or after == expected, (model, after)
        slave.free()
    slave = envs["PiezoController"].instantiate("initial-unknowns", logging_on=True)
    slave.fmu.setupExperiment(startTime=0.0)
    slave.fmu.enterInitializationMode()
    assert slave.set_real({"command_min": 20.0}) == fmi2.fmi2OK  # above command_max
    values = (fmi2.fmi2Real * 1)()
    vr = (fmi2.fmi2ValueReference * 1)(envs["PiezoController"].vrs["u1"])
    status = slave.fmu.fmi2GetReal(slave.fmu.component, vr, 1, values)
    assert status == fmi2.fmi2Warning, STATUS_NAMES.get(status)
    assert values[0] == 0.0  # the start values' rest command
    assert slave.log.matching("fmi2GetReal: the initial values cannot be computed from the values "
                              "set so far", "command_max", status=fmi2.fmi2Warning), slave.log.dump()
    # A parameter reads as set, without the model; the instance goes on.
    assert slave.get1("command_min") == 20.0
    assert slave.set_real({"command_min": 1.0}) == fmi2.fmi2OK
    assert slave.get1("u1") == 1.0
    slave.fmu.exitInitializationMode()
    slave.free()
