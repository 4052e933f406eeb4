"""Calibration fingerprints of the FlexureStage FMU, measured through FMI.

The same procedures as piezo-models/src/fingerprint.rs, run here through the
packaged FMU with fmpy as any importer would: commands held over fixed steps of
100 us (seed 000's 10 kHz controller), the command of step k being the demand
at the end of that step, readings taken after each step (x = (s2+s3)/2,
y = s1, theta = (s2-s3)/L). Each procedure is spelled out in its docstring.

Used by tests/test_plant_fingerprints.py (which asserts each row) and by
tests/fingerprint_report.py (make demo).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from dataclasses import dataclass, field

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

SAMPLE_PERIOD = 1e-4
RAMP_TIME = 1.0
FULL_COMMAND = 10.0
SWEEP_SPAN_UM = 10.0
ROTATION_SWEEP_AMPLITUDE_DEG = 9.2e-3
RESONANCE_STEP_COMMAND = 0.1
RESONANCE_SAMPLE_PERIOD = 1e-5
RESONANCE_RECORD_TIME = 0.25


@dataclass(frozen=True)
class Target:
    """A figure of seed 000 and the tolerance the plant must meet."""

    name: str
    paper: float
    relative_tolerance: float
    unit: str
    source: str


TARGETS = {
    "stroke_x": Target("stroke x at 10 V", 12.74, 0.05, "um", "seed 000 §2"),
    "stroke_y": Target("stroke y at 10 V", 12.22, 0.05, "um", "seed 000 §2"),
    "rotation_anticlockwise": Target(
        "rotation range anticlockwise", 0.0103, 0.10, "deg", "seed 000 §2"
    ),
    "rotation_clockwise": Target("rotation range clockwise", 0.0088, 0.10, "deg", "seed 000 §2"),
    "theta_resonance": Target("theta_z resonance", 790.0, 0.02, "Hz", "seed 000 §2"),
    "s2_from_y": Target("coupling span s2 (x2) from y", 2.2065, 0.15, "um", "seed 000 Table 3"),
    "s3_from_y": Target("coupling span s3 (x3) from y", 2.7435, 0.15, "um", "seed 000 Table 3"),
    "y_from_x": Target("coupling span y from x", 1.2482, 0.15, "um", "seed 000 Table 3"),
    "y_from_rotation": Target(
        "coupling span y from rotation", 1.6784, 0.15, "um", "seed 000 Table 3"
    ),
    # Seed 000 §3.2 tuned its PI gains by Ziegler-Nichols: kp = 0.45 Ku and
    # ki = 1.2 kp / Tu, so translation (0.05, 50) and rotation kp 0.06 give:
    "ultimate_gain_x": Target(
        "Ziegler-Nichols ultimate gain x", 0.05 / 0.45, 0.10, "V/um", "seed 000 §3.2 kp / 0.45"
    ),
    "ultimate_gain_y": Target(
        "Ziegler-Nichols ultimate gain y", 0.05 / 0.45, 0.10, "V/um", "seed 000 §3.2 kp / 0.45"
    ),
    "ultimate_gain_theta": Target(
        "Ziegler-Nichols ultimate gain theta_z", 0.06 / 0.45, 0.10, "V/um",
        "seed 000 §3.2 kp / 0.45"
    ),
    "ultimate_period_x": Target(
        "Ziegler-Nichols ultimate period x", 1.2e-3, 0.10, "s", "seed 000 §3.2 1.2 kp / ki"
    ),
    "ultimate_period_y": Target(
        "Ziegler-Nichols ultimate period y", 1.2e-3, 0.10, "s", "seed 000 §3.2 1.2 kp / ki"
    ),
}
#: Major-loop width as a fraction of the stroke (issue: 8-15 %).
LOOP_WIDTH_RANGE = (0.08, 0.15)
#: A loop is asymmetric when max_d |w(c+d) - w(c-d)| / max|w| exceeds this.
LOOP_ASYMMETRY_MIN = 0.10
#: A coupling is a hysteresis loop when its width is at least this share of its span.
COUPLING_LOOP_WIDTH_MIN = 0.05


class Plant:
    """The FMU extracted once; `rig()` gives a fresh instance at rest."""

    def __init__(self, fmu_path: str, start_values: dict | None = None):
        self.fmu_path = fmu_path
        self.description = read_model_description(fmu_path)
        self.unzipdir = extract(fmu_path, unzipdir=tempfile.mkdtemp(prefix="flexure-stage-"))
        self.vr = {v.name: v.valueReference for v in self.description.modelVariables}
        self.start_values = dict(start_values or {})
        self.spacing_um = float(self._start("L")) * 1e3
        self.rigs_made = 0

    def _start(self, name: str):
        for v in self.description.modelVariables:
            if v.name == name:
                return self.start_values.get(name, v.start)
        raise KeyError(name)

    def rig(self) -> "Rig":
        self.rigs_made += 1
        return Rig(self)

    def close(self) -> None:
        shutil.rmtree(self.unzipdir, ignore_errors=True)


class Rig:
    """One instance at rest with zero commands, stepped at a fixed period."""

    def __init__(self, plant: Plant):
        self.plant = plant
        d = plant.description
        self.fmu = FMU2Slave(
            guid=d.guid,
            unzipDirectory=plant.unzipdir,
            modelIdentifier=d.coSimulation.modelIdentifier,
            instanceName=f"fingerprint{plant.rigs_made}",
        )
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in plant.start_values.items():
            vr = plant.vr[name]
            if isinstance(value, bool):
                self.fmu.setBoolean([vr], [value])
            elif isinstance(value, int):
                self.fmu.setInteger([vr], [value])
            else:
                self.fmu.setReal([vr], [float(value)])
        self.fmu.exitInitializationMode()
        self.time = 0.0
        self.commands = np.zeros(3)
        self.u_vrs = [plant.vr["u1"], plant.vr["u2"], plant.vr["u3"]]
        self.s_vrs = [plant.vr["s1"], plant.vr["s2"], plant.vr["s3"]]

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def sensors(self) -> np.ndarray:
        return np.array(self.fmu.getReal(self.s_vrs))

    def x(self) -> float:
        s = self.sensors()
        return 0.5 * (s[1] + s[2])

    def y(self) -> float:
        return float(self.sensors()[0])

    def theta_deg(self) -> float:
        s = self.sensors()
        return math.degrees((s[1] - s[2]) / self.plant.spacing_um)

    def run(self, duration: float, period: float, demand) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Steps `duration` s; the commands of step k are demand(k*period).
        Returns (t since the start of the run, commands, sensors) per step."""
        steps = round(duration / period)
        t = np.arange(1, steps + 1) * period
        commands = np.empty((steps, 3))
        sensors = np.empty((steps, 3))
        for k in range(steps):
            u = demand(t[k])
            self.fmu.setReal(self.u_vrs, list(u))
            self.fmu.doStep(self.time, period)
            self.time += period
            commands[k] = u
            sensors[k] = self.fmu.getReal(self.s_vrs)
        self.commands = np.array(commands[-1])
        return t, commands, sensors

    def ramp_to(self, target) -> None:
        """Linear ramp from the current commands to `target` over 1 s."""
        start = self.commands.copy()
        target = np.asarray(target, dtype=float)
        self.run(RAMP_TIME, SAMPLE_PERIOD, lambda t: start + (target - start) * (t / RAMP_TIME))
        self.commands = target

    def hold(self, duration: float) -> None:
        held = self.commands.copy()
        self.run(duration, SAMPLE_PERIOD, lambda t: held)


def stroke(plant: Plant, axis: str) -> float:
    """From rest, the driven command(s) ramp 0 -> 10 V over 1 s (others 0);
    the stroke is the axis reading after the last step."""
    with plant.rig() as rig:
        if axis == "x":
            rig.ramp_to([0.0, FULL_COMMAND, FULL_COMMAND])
            return rig.x()
        rig.ramp_to([FULL_COMMAND, 0.0, 0.0])
        return rig.y()


def solve_increasing(f, lo: float, hi: float, tolerance: float) -> float:
    """Root of an increasing f on [lo, hi] (Illinois regula falsi)."""
    a, b = lo, hi
    fa, fb = f(a), f(b)
    if fa >= 0.0:
        return a
    if fb <= 0.0:
        return b
    side = 0
    for _ in range(100):
        c = (a * fb - b * fa) / (fb - fa)
        fc = f(c)
        if abs(fc) <= tolerance or b - a < 1e-12:
            return c
        if fc < 0.0:
            a, fa = c, fc
            if side == -1:
                fb /= 2.0
            side = -1
        else:
            b, fb = c, fc
            if side == 1:
                fa /= 2.0
            side = 1
    return c


def x_home_command(plant: Plant, x_stroke: float, tolerance: float = 1e-6) -> float:
    """The u2 = u3 command whose 1 s ramp from rest ends at x = stroke/2
    (seed 000 §3.2: the x home is at half stroke)."""

    def x_after_ramp(u: float) -> float:
        with plant.rig() as rig:
            rig.ramp_to([0.0, u, u])
            return rig.x()

    return solve_increasing(lambda u: x_after_ramp(u) - 0.5 * x_stroke, 0.0, FULL_COMMAND, tolerance)


def rig_at_x_home(plant: Plant, u_home: float) -> Rig:
    rig = plant.rig()
    rig.ramp_to([0.0, u_home, u_home])
    return rig


def rotation_range_deg(plant: Plant, u_home: float) -> tuple[float, float]:
    """From rest: ramp to the x home; ramp to (0, 10, 0), read theta+; back to
    the home; ramp to (0, 0, 10), read theta-. theta from the orientation at
    rest. Returns (anticlockwise = theta+, clockwise = -theta-)."""
    with rig_at_x_home(plant, u_home) as rig:
        rig.ramp_to([0.0, FULL_COMMAND, 0.0])
        anticlockwise = rig.theta_deg()
        rig.ramp_to([0.0, u_home, u_home])
        rig.ramp_to([0.0, 0.0, FULL_COMMAND])
        return anticlockwise, -rig.theta_deg()


def rotation_step_record(plant: Plant, u_home: float) -> np.ndarray:
    """At the x home, hold 0.5 s, then step to (0, u_home+0.1, u_home-0.1) and
    record theta every 10 us for 0.25 s."""
    with rig_at_x_home(plant, u_home) as rig:
        rig.hold(0.5)
        held = np.array([0.0, u_home + RESONANCE_STEP_COMMAND, u_home - RESONANCE_STEP_COMMAND])
        _, _, sensors = rig.run(RESONANCE_RECORD_TIME, RESONANCE_SAMPLE_PERIOD, lambda t: held)
        return (sensors[:, 1] - sensors[:, 2]) / plant.spacing_um


def spectral_peak_hz(record: np.ndarray, period: float) -> float:
    """Largest |DFT(theta - mean)| scanned 300..2000 Hz every 0.5 Hz."""
    centred = record - record.mean()
    k = np.arange(len(record))
    best_f, best = 0.0, -1.0
    for f in np.arange(300.0, 2000.0 + 1e-9, 0.5):
        phase = -2.0 * math.pi * f * period * k
        value = abs(np.dot(centred, np.cos(phase)) + 1j * np.dot(centred, np.sin(phase)))
        if value > best:
            best_f, best = float(f), value
    return best_f


@dataclass
class LoopShape:
    span: float
    max_width: float
    width_ratio: float
    asymmetry: float


def _interpolate(branch_in: np.ndarray, branch_out: np.ndarray, u: float) -> float:
    order = np.argsort(branch_in, kind="stable")
    return float(np.interp(u, branch_in[order], branch_out[order]))


def loop_shape(u: np.ndarray, y: np.ndarray) -> LoopShape:
    """Widths w(u) = descending - ascending at 19 inputs across the range; the
    cycle runs min -> max -> min, split at the maximum of u."""
    top = int(np.argmax(u))
    lo, hi = float(u.min()), float(u.max())
    widths = []
    for j in range(1, 20):
        v = lo + (hi - lo) * j / 20.0
        widths.append(_interpolate(u[top:], y[top:], v) - _interpolate(u[: top + 1], y[: top + 1], v))
    widths = np.array(widths)
    span = float(y.max() - y.min())
    max_width = float(np.abs(widths).max())
    n = len(widths)
    asymmetry = max(abs(widths[j] - widths[n - 1 - j]) for j in range(n // 2)) / max_width
    return LoopShape(span, max_width, max_width / span, float(asymmetry))


def _window(t: np.ndarray, start: float, end: float) -> np.ndarray:
    return (t >= start - 1e-6) & (t <= end + 1e-6)


def major_loop(plant: Plant, axis: str) -> LoopShape:
    """From rest, the driven command(s) follow 5(1 - cos 2 pi t) V for 2 s;
    the loop is the reading versus the command over t in [1, 2] s."""

    def wave(t: float) -> float:
        return 0.5 * FULL_COMMAND * (1.0 - math.cos(2.0 * math.pi * t))

    with plant.rig() as rig:
        if axis == "x":
            t, u, s = rig.run(2.0, SAMPLE_PERIOD, lambda t: [0.0, wave(t), wave(t)])
            reading, command = 0.5 * (s[:, 1] + s[:, 2]), u[:, 1]
        else:
            t, u, s = rig.run(2.0, SAMPLE_PERIOD, lambda t: [wave(t), 0.0, 0.0])
            reading, command = s[:, 0], u[:, 0]
    w = _window(t, 1.0, 2.0)
    return loop_shape(command[w], reading[w])


@dataclass
class Sweep:
    amplitude: float
    t: np.ndarray
    commands: np.ndarray
    sensors: np.ndarray


def _y_sweep(plant: Plant, u_home: float, a: float) -> Sweep:
    with rig_at_x_home(plant, u_home) as rig:
        t, u, s = rig.run(
            2.0, SAMPLE_PERIOD, lambda t: [0.5 * a * (1.0 - math.cos(2 * math.pi * t)), u_home, u_home]
        )
    w = _window(t, 1.0, 2.0)
    return Sweep(a, t[w], u[w], s[w])


def _x_sweep(plant: Plant, a: float) -> Sweep:
    def demand(t: float):
        v = 0.5 * a * (1.0 - math.cos(2 * math.pi * t))
        return [0.0, v, v]

    with plant.rig() as rig:
        t, u, s = rig.run(2.0, SAMPLE_PERIOD, demand)
    w = _window(t, 1.0, 2.0)
    return Sweep(a, t[w], u[w], s[w])


def _rotation_sweep(plant: Plant, u_home: float, d: float) -> Sweep:
    def demand(t: float):
        v = d * math.sin(2 * math.pi * t)
        return [0.0, u_home + v, u_home - v]

    with rig_at_x_home(plant, u_home) as rig:
        t, u, s = rig.run(2.75, SAMPLE_PERIOD, demand)
    w = _window(t, 1.75, 2.75)
    return Sweep(d, t[w], u[w], s[w])


@dataclass
class Couplings:
    y_sweep: Sweep
    x_sweep: Sweep
    rotation_sweep: Sweep
    shapes: dict = field(default_factory=dict)


def coupling_sweeps(plant: Plant, u_home: float, tolerance: float = 1e-4) -> Couplings:
    """Open-loop sweeps of seed 000 Table 3: one axis follows a 1 Hz wave whose
    amplitude is solved so it spans 10 um (x, y) or 2 x 9.2e-3 deg (theta) over
    the measured cycle; the other actuators hold their home commands."""
    spacing = plant.spacing_um

    def span(values: np.ndarray) -> float:
        return float(values.max() - values.min())

    a_y = solve_increasing(
        lambda a: span(_y_sweep(plant, u_home, a).sensors[:, 0]) - SWEEP_SPAN_UM,
        0.0, FULL_COMMAND, tolerance,
    )
    ys = _y_sweep(plant, u_home, a_y)
    a_x = _solve_x_amplitude(plant, tolerance)
    xs = _x_sweep(plant, a_x)

    def theta_span(d: float) -> float:
        s = _rotation_sweep(plant, u_home, d).sensors
        return span(np.degrees((s[:, 1] - s[:, 2]) / spacing))

    d = solve_increasing(
        lambda d: theta_span(d) - 2.0 * ROTATION_SWEEP_AMPLITUDE_DEG,
        0.0, min(u_home, FULL_COMMAND - u_home), tolerance * 1e-3,
    )
    rs = _rotation_sweep(plant, u_home, d)
    result = Couplings(ys, xs, rs)
    result.shapes = {
        "s2_from_y": loop_shape(ys.commands[:, 0], ys.sensors[:, 1]),
        "s3_from_y": loop_shape(ys.commands[:, 0], ys.sensors[:, 2]),
        "y_from_x": loop_shape(xs.commands[:, 1], xs.sensors[:, 0]),
        "y_from_rotation": loop_shape(
            0.5 * (rs.commands[:, 1] - rs.commands[:, 2]), rs.sensors[:, 0]
        ),
    }
    return result


def _solve_x_amplitude(plant: Plant, tolerance: float) -> float:
    def x_span(a: float) -> float:
        s = _x_sweep(plant, a).sensors
        x = 0.5 * (s[:, 1] + s[:, 2])
        return float(x.max() - x.min())

    return solve_increasing(lambda a: x_span(a) - SWEEP_SPAN_UM, 0.0, FULL_COMMAND, tolerance)


#: u1 at the operating point of the loop tests (y at mid stroke) [V].
LOOP_Y_COMMAND = 5.0
#: Reference step that starts a loop's oscillation [um].
LOOP_STEP_UM = 0.05
#: Length of one proportional-loop probe [s] and its two envelope windows.
LOOP_PROBE_TIME = 0.12
LOOP_WINDOWS = ((0.02, 0.06), (0.08, 0.12))
#: How each loop axis drives the channels (seed 000 §3.2).
LOOP_DIRECTIONS = {"x": (0.0, 1.0, 1.0), "y": (1.0, 0.0, 0.0), "theta": (0.0, 1.0, -1.0)}


def _loop_reading(sensors, axis: str) -> float:
    """x = (s2+s3)/2, y = s1, theta as the half-differential (s2-s3)/2 [um]."""
    if axis == "x":
        return 0.5 * (sensors[1] + sensors[2])
    if axis == "y":
        return float(sensors[0])
    return 0.5 * (sensors[1] - sensors[2])


def proportional_loop_growth(rig: Rig, axis: str, kp: float) -> tuple[float, float]:
    """From the rig's current state, a proportional loop follows a 0.05 um
    reference step; the command over [t_k, t_k+1] is the operating command plus
    directions * kp * (r - reading(t_k-1)): one sample of compute delay, as the
    co-simulation gives. Returns the growth rate of the oscillation [1/s]
    (RMS about the mean in the two windows) and its period [s]; a probe whose
    command leaves 0..10 V is unstable (growth +inf). The rig's state and time
    are restored afterwards (FMU state), so probes can repeat from one point."""
    state = rig.fmu.getFMUstate()
    time0 = rig.time
    operating = rig.commands.copy()
    directions = np.array(LOOP_DIRECTIONS[axis])
    previous = current = _loop_reading(rig.sensors(), axis)
    reference = current + LOOP_STEP_UM
    steps = round(LOOP_PROBE_TIME / SAMPLE_PERIOD)
    errors = np.empty(steps)
    try:
        for k in range(steps):
            u = operating + directions * (kp * (reference - previous))
            if np.any(u < 0.0) or np.any(u > FULL_COMMAND):
                return math.inf, math.nan
            rig.fmu.setReal(rig.u_vrs, list(u))
            rig.fmu.doStep(rig.time, SAMPLE_PERIOD)
            rig.time += SAMPLE_PERIOD
            previous, current = current, _loop_reading(rig.fmu.getReal(rig.s_vrs), axis)
            errors[k] = reference - current
    finally:
        rig.fmu.setFMUstate(state)
        rig.fmu.freeFMUstate(state)
        rig.time = time0

    def window(bounds):
        a, b = (round(v / SAMPLE_PERIOD) for v in bounds)
        segment = errors[a:b] - errors[a:b].mean()
        return math.sqrt(float(np.mean(segment**2))), segment

    first, _ = window(LOOP_WINDOWS[0])
    last, centred = window(LOOP_WINDOWS[1])
    growth = math.log(max(last, 1e-300) / max(first, 1e-300)) / (LOOP_WINDOWS[1][0] - LOOP_WINDOWS[0][0])
    k = np.nonzero(np.signbit(centred[:-1]) != np.signbit(centred[1:]))[0]
    crossings = k + centred[k] / (centred[k] - centred[k + 1])
    period = (
        2.0 * (crossings[-1] - crossings[0]) * SAMPLE_PERIOD / (len(crossings) - 1)
        if len(crossings) >= 3
        else math.nan
    )
    return growth, period


def ultimate_gain(plant: Plant, u_home: float, axis: str) -> tuple[float, float]:
    """Ziegler-Nichols ultimate gain Ku [V/um] and period Tu [s] of `axis`: at
    the operating point (ramp to (5 V, u_home, u_home) over 1 s, hold 0.5 s),
    the gain at which the proportional loop's growth changes sign, by
    bisection in log gain between 0.001 and 10 V/um to a relative width 1e-3."""
    with plant.rig() as rig:
        rig.ramp_to([LOOP_Y_COMMAND, u_home, u_home])
        rig.hold(0.5)
        stable, unstable = 1e-3, 10.0
        while unstable / stable > 1.0 + 1e-3:
            kp = math.sqrt(stable * unstable)
            if proportional_loop_growth(rig, axis, kp)[0] > 0.0:
                unstable = kp
            else:
                stable = kp
        _, period = proportional_loop_growth(rig, axis, stable)
        return math.sqrt(stable * unstable), period


@dataclass
class Fingerprints:
    stroke_x: float
    stroke_y: float
    u_home: float
    rotation_anticlockwise: float
    rotation_clockwise: float
    theta_resonance: float
    loop_x: LoopShape
    loop_y: LoopShape
    couplings: Couplings
    ultimate_gain_x: float
    ultimate_gain_y: float
    ultimate_gain_theta: float
    ultimate_period_x: float
    ultimate_period_y: float
    ultimate_period_theta: float

    def value(self, key: str) -> float:
        if key in self.couplings.shapes:
            return self.couplings.shapes[key].span
        return getattr(self, key)


def measure(plant: Plant, progress=lambda message: None) -> Fingerprints:
    """Runs every procedure; `progress(message)` is told what runs next."""
    progress("strokes")
    stroke_x = stroke(plant, "x")
    stroke_y = stroke(plant, "y")
    progress("x home command")
    u_home = x_home_command(plant, stroke_x)
    progress("rotation range")
    anticlockwise, clockwise = rotation_range_deg(plant, u_home)
    progress("theta_z resonance")
    resonance = spectral_peak_hz(rotation_step_record(plant, u_home), RESONANCE_SAMPLE_PERIOD)
    progress("major loops")
    loop_x = major_loop(plant, "x")
    loop_y = major_loop(plant, "y")
    progress("coupling sweeps")
    couplings = coupling_sweeps(plant, u_home)
    progress("ultimate gains")
    (ku_x, tu_x), (ku_y, tu_y), (ku_t, tu_t) = (
        ultimate_gain(plant, u_home, axis) for axis in ("x", "y", "theta")
    )
    return Fingerprints(
        stroke_x, stroke_y, u_home, anticlockwise, clockwise, resonance, loop_x, loop_y, couplings,
        ku_x, ku_y, ku_t, tu_x, tu_y, tu_t,
    )
