"""FlexureStage.fmu as Model Exchange, and both FMUs restarted from a saved
state, as fmpy 0.3.32 runs them.

- Model Exchange beside Co-Simulation in the one .fmu: fmpy validates it,
  integrates it with CVode (its default variable-step solver, BDF, absolute
  tolerances from the FMU's nominals) and with forward Euler, and both agree
  with the co-simulation run of the same inputs.
- Restart: a state serialized after initialization is restored into a freshly
  instantiated instance (what `fmusim --initial-fmu-state-file` does: no
  initialization in between), which then continues bit for bit as the saved
  instance did; also after an fmi2Error.

The Rust tests (fmu-plant/tests/model_exchange.rs, fmi2-conformance's
restore and Model Exchange checks) cover every state combination and the
calibration sweeps; these show the same through a Python importer.
"""

from __future__ import annotations

import pathlib
import shutil
import tempfile
from ctypes import POINTER

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Model, FMU2Slave, fmi2Real
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from conftest import LogCapture
from tests.docs_figures import doc_rows, stale_rows

#: The rows of docs/fmi.md's fmpy table that these tests measure again (the
#: solver and the span are the rows' key): CVode's, by relative tolerance,
#: and forward Euler's.
CVODE_ROWS = {
    1e-11: "CVode, relative tolerance 1e-11 (absolute: 1e-11 × each state's nominal, as fmpy sets it)",
    1e-10: "CVode, relative tolerance 1e-10",
    1e-9: "CVode, relative tolerance 1e-9",
}
EULER_ROWS = ("forward Euler, 2 µs steps", "forward Euler, 1 µs steps")
MEMORY_ROWS = (
    "CVode, relative tolerance 1e-10, return-point memory on (the default)",
    "the same run with `return_point_memory = false` (the memory's branches not followed)",
)


def assert_documented(rows: list[list[str]]) -> None:
    """docs/fmi.md prints what was measured (within 1 % or the last digit)."""
    assert not stale_rows(doc_rows("fmi.md"), rows, 2, "docs/fmi.md"), stale_rows(
        doc_rows("fmi.md"), rows, 2, "docs/fmi.md")

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
DIST = REPO_ROOT / "dist"
PLANT = DIST / "FlexureStage.fmu"
CONTROLLER = DIST / "PiezoController.fmu"
SENSORS = ["s1", "s2", "s3", "x", "y", "theta_z"]
#: Commands held from t = 0 (y, and the x pair apart so that theta_z moves).
COMMANDS = {"u1": 5.0, "u2": 3.0, "u3": 7.0}


def require(path: pathlib.Path) -> str:
    if not path.is_file():
        pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    return str(path)


def co_simulation(stop_time: float) -> np.ndarray:
    """The co-simulation reference, with 1 mV hysteresis chords (its own
    approximation ~1e-10 um, MODEL.md §3)."""
    return fmpy.simulate_fmu(
        require(PLANT), fmi_type="CoSimulation",
        start_values={**COMMANDS, "solver.max_voltage_step": 1e-3},
        stop_time=stop_time, step_size=1e-4, output_interval=1e-4, output=SENSORS,
    )


def on_output_grid(result: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The rows of a Model Exchange result at the output times `grid`: fmpy
    also records a row before and after each state event (a hysteretic state
    crossing 0), between output times."""
    index = np.searchsorted(result["time"], grid - 1e-12)
    assert np.all(index < len(result)), "the result ends before the grid"
    assert np.allclose(result["time"][index], grid, rtol=0, atol=1e-12)
    return result[index]


def half_spacing_um() -> float:
    """L/2, the sensors' distance from the stage's centre [um] (L in mm)."""
    spacing = next(v for v in fmpy.read_model_description(require(PLANT)).modelVariables
                   if v.name == "L")
    assert spacing.unit == "mm", spacing.unit
    return float(spacing.start) * 1e3 / 2


def largest_difference(a: np.ndarray, b: np.ndarray) -> float:
    b = on_output_grid(b, a["time"])
    # theta_z in rad is compared as the displacement it makes at the sensors
    # (s2 = x + theta_z L/2), like the other signals in um.
    theta_scale = half_spacing_um()
    return max(
        float(np.max(np.abs(a[name] - b[name]) * (theta_scale if name == "theta_z" else 1.0)))
        for name in SENSORS
    )


def test_both_interfaces_validate_and_are_declared():
    path = require(PLANT)
    assert validate_fmu(path) == []
    md = fmpy.read_model_description(path)
    me = md.modelExchange
    assert me is not None and md.coSimulation is not None
    assert me.modelIdentifier == md.coSimulation.modelIdentifier == "FlexureStage"
    assert md.numberOfContinuousStates == 19
    # Per Bouc-Wen model (7): its branch state, where its rate switches
    # form, and the return-point memory's turn and wipe-out (clipping acts on
    # the inputs and needs none).
    assert md.numberOfEventIndicators == 21
    assert me.completedIntegratorStepNotNeeded is False
    assert me.canGetAndSetFMUstate and me.canSerializeFMUstate
    states = [d.variable.derivative.name for d in md.derivatives]
    assert states[:3] == [f"amplifier.voltage[{i}]" for i in (1, 2, 3)]
    assert {"x", "y", "theta_z", "velocity.x"} <= set(states)
    # The controller is sampled: co-simulation only, and it says why.
    controller = fmpy.read_model_description(require(CONTROLLER))
    assert controller.modelExchange is None and controller.coSimulation is not None
    assert "no continuous states" in controller.description


@pytest.mark.parametrize("tolerance", sorted(CVODE_ROWS), ids=lambda rtol: f"rtol={rtol:g}")
def test_cvode_matches_co_simulation(tolerance):
    """CVode (absolute tolerance: the relative one x each state's nominal, as
    fmpy sets it) against Co-Simulation over 50 ms of held commands, through
    the amplifier's transient and the modes' ringing: within 1e5 x the
    relative tolerance in um (1e-6 um at 1e-11), as CVode's error follows its
    tolerance. The step from the exercised rest drives all seven hysteretic
    states through 0, each a state event where CVode restarts: without the
    event indicators it took more than its 500 steps per output interval to
    creep across the n = 1 kinks."""
    cs = co_simulation(0.05)
    me = fmpy.simulate_fmu(
        require(PLANT), fmi_type="ModelExchange", solver="CVode", relative_tolerance=tolerance,
        start_values=COMMANDS, stop_time=0.05, output_interval=1e-4, output=SENSORS,
    )
    worst = largest_difference(cs, me)
    print(f"CVode (rtol {tolerance:g}) vs Co-Simulation: largest difference {worst:.2e} um "
          f"(y at the end {me['y'][-1]:.6f} um)")
    assert worst < 1e5 * tolerance
    assert me["y"][-1] > 1.0, "the stage moved"
    assert_documented([[CVODE_ROWS[tolerance], "50 ms", f"{worst:.1e} µm"]])


def test_forward_euler_converges_to_co_simulation():
    """fmpy's forward Euler (one step per output interval) at 2 us and 1 us
    over 10 ms: stable (the amplifier needs h < 2 tau = 106 us, the 790 Hz
    modes with their damping h < 2 zeta / omega = 17 us) and first-order
    accurate: halving the step halves the difference to Co-Simulation (0.27
    and 0.13 um when measured; the ringing of the modes dominates it)."""
    cs = co_simulation(0.01)
    differences = []
    for h in (2e-6, 1e-6):
        me = fmpy.simulate_fmu(
            require(PLANT), fmi_type="ModelExchange", solver="Euler", step_size=h,
            start_values=COMMANDS, stop_time=0.01, output_interval=h, output=SENSORS,
        )
        differences.append(largest_difference(cs, me))
    print(f"Euler vs Co-Simulation: 2 us {differences[0]:.3f} um, 1 us {differences[1]:.3f} um")
    assert 0.4 < differences[1] / differences[0] < 0.6, differences
    assert differences[1] < 0.5
    assert_documented([[row, "10 ms", f"{d:.2f} µm"] for row, d in zip(EULER_ROWS, differences)])


#: Commands held 2 ms each (the FMU's inputs, before the amplifier [V]): every
#: channel turns at each change, and the later holds carry the voltages past
#: earlier turns, where the return-point memory wipes loops out.
MEMORY_HOLDS = [
    (5.0, 3.0, 7.0), (2.0, 1.0, 4.0), (4.0, 2.5, 6.0), (1.0, 0.5, 3.0), (6.0, 4.0, 8.0),
    (3.0, 2.0, 5.0), (3.5, 2.2, 5.5), (-0.2, -0.1, 1.0), (9.0, 7.0, 10.0), (4.0, 3.0, 6.0),
]


def held_commands(hold: float) -> np.ndarray:
    """MEMORY_HOLDS as an fmpy input signal: piecewise constant, each change a
    repeated time stamp (fmpy's time event)."""
    rows = []
    for k, commands in enumerate(MEMORY_HOLDS):
        rows += [(k * hold, *commands), ((k + 1) * hold, *commands)]
    return np.array(rows, dtype=[("time", float), ("u1", float), ("u2", float), ("u3", float)])


def test_model_exchange_runs_the_return_point_memory():
    """With the stacks' minor loops closed (the tracking parameter set), CVode
    with the memory's events (each turn remembered, each wipe-out taken where
    its indicator crosses 0) traces the loops Co-Simulation steps through:
    20 ms of commands that turn every channel at each 2 ms change and pass
    earlier turns. Bound: 1e5 x the relative tolerance in um, as for the
    memory-free stage above. The same run with the memory off differs from
    this co-simulation by orders of magnitude more, so the bound tells the
    two apart."""
    import json
    preset = json.loads((DIST / "presets" / "FlexureStage.3dof.json").read_text())
    assert preset["return_point_memory"] is True
    preset.pop("noise.enabled", None)
    hold, stop = 2e-3, 2e-3 * len(MEMORY_HOLDS)
    signal = held_commands(hold)
    common = dict(input=signal, stop_time=stop, output_interval=1e-4, output=SENSORS)
    cs = fmpy.simulate_fmu(require(PLANT), fmi_type="CoSimulation", step_size=1e-4,
                           start_values={**preset, "solver.max_voltage_step": 1e-3}, **common)
    tolerance = 1e-10
    me = fmpy.simulate_fmu(require(PLANT), fmi_type="ModelExchange", solver="CVode",
                           relative_tolerance=tolerance, start_values=preset, **common)
    worst = largest_difference(cs, me)
    forgetting = fmpy.simulate_fmu(require(PLANT), fmi_type="ModelExchange", solver="CVode",
                                   relative_tolerance=tolerance,
                                   start_values={**preset, "return_point_memory": False}, **common)
    without = largest_difference(cs, forgetting)
    print(f"return-point memory, CVode (rtol {tolerance:g}) vs Co-Simulation: {worst:.2e} um; "
          f"with the memory off {without:.2e} um")
    assert worst < 1e5 * tolerance
    assert without > 100 * 1e5 * tolerance
    assert_documented([
        [MEMORY_ROWS[0], "20 ms", f"{worst:.1e} µm"],
        [MEMORY_ROWS[1], "20 ms", f"{without:.2f} µm"],
    ])


def test_model_exchange_refuses_sensor_noise():
    """Sensor noise is one sample per communication step, which Model
    Exchange has none of: refused at initialization, with the reason."""
    u = Unzipped(require(PLANT))
    log = LogCapture()
    try:
        fmu = u.instance(FMU2Model, callbacks=log.callbacks)
        fmu.setBoolean([u.vr["noise.enabled"]], [True])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        with pytest.raises(FMICallException):
            fmu.exitInitializationMode()
        assert log.matching("noise.enabled", "Model Exchange"), log.dump()
        fmu.freeInstance()
    finally:
        u.close()


class Unzipped:
    """The FMU extracted once; fresh instances of either interface."""

    def __init__(self, path: str):
        self.md = fmpy.read_model_description(path)
        self.dir = fmpy.extract(path, unzipdir=tempfile.mkdtemp(prefix="restart-"))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.count = 0

    def instance(self, cls, callbacks=None):
        self.count += 1
        fmu = cls(guid=self.md.guid, unzipDirectory=self.dir,
                  modelIdentifier=self.md.coSimulation.modelIdentifier,
                  instanceName=f"restart{self.count}")
        fmu.instantiate(callbacks=callbacks)
        return fmu

    def close(self):
        shutil.rmtree(self.dir, ignore_errors=True)


@pytest.fixture(params=["FlexureStage", "PiezoController"])
def unzipped(request):
    u = Unzipped(require(DIST / f"{request.param}.fmu"))
    yield u
    u.close()


def _inputs_and_outputs(u: Unzipped):
    inputs = [v.valueReference for v in u.md.modelVariables
              if v.causality == "input" and v.type == "Real"]
    outputs = [v.valueReference for v in u.md.modelVariables
               if v.causality == "output" and v.type == "Real"]
    return inputs, outputs


def _steps(fmu, u: Unzipped, t: float, n: int) -> list[list[float]]:
    inputs, outputs = _inputs_and_outputs(u)
    rows = []
    for k in range(n):
        fmu.setReal(inputs, [1.0 + 0.5 * np.sin(0.01 * (k + 1000 * t)) + i for i in range(len(inputs))])
        fmu.doStep(t, 1e-4)
        t += 1e-4
        rows.append(fmu.getReal(outputs))
    return rows


def test_restart_from_a_saved_state_in_a_fresh_instance(unzipped):
    """fmusim's --initial-fmu-state-file: instantiate, deserialize, set the
    state, step (no initialization); and the same into an instance that is in
    its error state after an illegal call."""
    u = unzipped
    saved = u.instance(FMU2Slave)
    saved.setupExperiment(startTime=0.0)
    saved.enterInitializationMode()
    saved.exitInitializationMode()
    _steps(saved, u, 0.0, 200)
    bytes_ = saved.serializeFMUstate(saved.getFMUstate())
    expected = _steps(saved, u, 0.02, 100)

    fresh = u.instance(FMU2Slave)
    fresh.setFMUstate(fresh.deSerializeFMUstate(bytes_))
    assert _steps(fresh, u, 0.02, 100) == expected

    failed = u.instance(FMU2Slave)
    failed.setupExperiment(startTime=0.0)
    failed.enterInitializationMode()
    failed.exitInitializationMode()
    with pytest.raises(FMICallException):
        failed.enterInitializationMode()  # illegal now: fmi2Error
    failed.setFMUstate(failed.deSerializeFMUstate(bytes_))
    assert _steps(failed, u, 0.02, 100) == expected
    for fmu in (saved, fresh, failed):
        fmu.terminate()
        fmu.freeInstance()


def test_model_exchange_restarts_from_a_saved_state():
    """The same for Model Exchange: a state saved in continuous-time mode,
    restored into a freshly instantiated instance, gives the same
    derivatives, states and outputs, and integrates on identically."""
    u = Unzipped(require(PLANT))
    try:
        n = u.md.numberOfContinuousStates
        outputs = [u.vr[name] for name in SENSORS]

        def pointer(array: np.ndarray):
            return array.ctypes.data_as(POINTER(fmi2Real))

        def run(fmu, t0, steps):
            """Forward Euler steps of 1 us from t0, recording outputs and states."""
            rows = []
            x, dx = np.zeros(n), np.zeros(n)
            for k in range(steps):
                fmu.getContinuousStates(pointer(x), n)
                fmu.getDerivatives(pointer(dx), n)
                x += 1e-6 * dx
                fmu.setTime(t0 + (k + 1) * 1e-6)
                fmu.setContinuousStates(pointer(x), n)
                fmu.completedIntegratorStep()
                rows.append(fmu.getReal(outputs) + [float(v) for v in x])
            return rows

        saved = u.instance(FMU2Model)
        saved.setupExperiment(startTime=0.0)
        saved.enterInitializationMode()
        saved.setReal([u.vr["u1"], u.vr["u2"]], [6.0, 2.0])
        saved.exitInitializationMode()
        saved.newDiscreteStates()
        saved.enterContinuousTimeMode()
        run(saved, 0.0, 300)
        bytes_ = saved.serializeFMUstate(saved.getFMUstate())
        expected = run(saved, 300e-6, 200)

        fresh = u.instance(FMU2Model)
        fresh.setFMUstate(fresh.deSerializeFMUstate(bytes_))
        assert run(fresh, 300e-6, 200) == expected
        for fmu in (saved, fresh):
            fmu.terminate()
            fmu.freeInstance()
    finally:
        u.close()
