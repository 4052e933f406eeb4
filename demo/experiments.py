"""Seed 000's experiments (§3.2, §5; Fig. 6-13, Table 3), as closed-loop runs
of PiezoController and FlexureStage, with the demands as the paper prints them.

Demands are absolute, measured from the stage's de-energized rest (every
actuator at 0 V, every reading 0):

- Single-axis sines (Fig. 6, 7, 10, Table 3): "the motion axis was driven
  (10 um or 9.2e-3 deg), with the demand on the other two axes held at zero"
  (§5). x and y: a 1 Hz sine from 0 to 10 um starting at the bottom
  (y = 5 - 5 cos 2 pi t), the other axes demanded at 0. theta_z: +-9.2e-3 deg
  (eq. 16's amplitude), y at 0 and x at half its stroke (12.74 / 2 um), the
  home §3.2 defines for rotation: "in order to implement the rotational
  motion of the platform, the home position in the x direction should be
  defined at the half stroke". About x = 0 the same rotation would need
  -5.9 um from one stack (about -46 V), beyond any amplifier of the paper.
  Seed 000 does not print the sine frequency of Fig. 6-7: 1 Hz, the
  fastest component of its identification signal eq. (6), read before any
  run (Fig. 8's "higher frequency" is 10 Hz).
- Fig. 11: eq. (13) as a y demand [um] (2..8 um), x and theta at 0.
- Fig. 12: the circle eq. (14)-(15) as printed, theta at 0.
- Fig. 13: theta_z by eq. (16), x at its half stroke as for every rotation;
  seed 000 does not print Fig. 13's y demand: y follows eq. (15)'s sine
  (the same 0.4 Hz), 1..11 um.
- Every run starts at rest; the reference reaches the trajectory's start by a
  raised cosine over 0.5 s and holds 0.5 s, so no run starts with a step.
- Errors are demand minus measurement, from the sensors, with the plant's
  sensor noise on (seeded), as the paper measured them: e_y = y_d - s1,
  e_x = x_d - (s2+s3)/2, e_theta = theta_d - (s2-s3)/L, coupling error in
  x2 = x_d2 - s2 and in x3 = x_d3 - s3 (x_d2,3 = x_d +- theta_d L/2).
  Single-axis metrics are taken over two cycles after three settling ones
  (`experiment_conditions.json`; the first reading was one, see
  docs/seed000.md).
- The decoupling law: seed 000 §4 computes D1..D4 once, from the Fig. 7
  runs. Every run of the paper's table with the decoupling on runs that law
  (`PiezoController.stage_once.json`, round 1 of `piezo-identify stage`);
  the FMU's start values (the `stage` preset) refine it over two more rounds
  fitted on the same runs, which the `_refined` runs measure beside it.
- Fig. 6, 7, 10 and Table 3: feedback on the driven axis only, the other
  axes getting feedforward of their demand (plus the decoupling
  compensation when it is on): with feedback on, ~2 um of coupling could not
  have been measured. Fig. 11-13 use the whole controller of Fig. 9, PI on
  every axis.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .paper import DECOUPLED

#: The conditions shared with piezo-identify's `stage` procedure, which fits
#: the decoupling on these same single-axis runs: one file, read by both.
CONDITIONS_FILE = Path(__file__).resolve().parent / "experiment_conditions.json"


def _load_conditions(path: Path = CONDITIONS_FILE) -> dict:
    conditions = json.loads(path.read_text())
    shapes = (conditions["approach"]["shape"], conditions["single_axis"]["sine_start"])
    if shapes != ("raised_cosine", "bottom"):
        raise ValueError(f"{path}: approach shape and sine start {shapes}: only "
                         "('raised_cosine', 'bottom') are implemented")
    return conditions


_CONDITIONS = _load_conditions()
_SINGLE_AXIS = _CONDITIONS["single_axis"]
_HOMES = _CONDITIONS["homes_um"]

APPROACH_TIME = _CONDITIONS["approach"]["time_s"]
SETTLE_TIME = _CONDITIONS["approach"]["settle_time_s"]
START = APPROACH_TIME + SETTLE_TIME
SINE_HZ = _SINGLE_AXIS["sine_frequency_hz"]
#: Single-axis sines: cycles run before the two that are measured. The
#: plant's Bouc-Wen minor loops need about four cycles to settle when an
#: actuator starts cycling about a new point (the offset left shrinks by
#: about 0.35 per cycle): the paper's steady figures are taken after three.
SETTLING_CYCLES = _SINGLE_AXIS["settling_cycles"]
MEASURED_CYCLES = _SINGLE_AXIS["measured_cycles"]
#: Peak-to-peak of the x and y sines, from 0 (seed 000 §5: 10 um).
TRANSLATION_SPAN_UM = _SINGLE_AXIS["translation_span_um"]
#: Demands of the held translations (x during a y run, y during an x run).
HELD_UM = (_SINGLE_AXIS["held_um"]["x"], _SINGLE_AXIS["held_um"]["y"])
#: x demand whenever the platform rotates: half the x stroke (§2: 12.74 um),
#: the home §3.2 defines for rotation.
ROTATION_X_UM = _HOMES["rotation"]["x"]
ROTATION_AMPLITUDE_DEG = _SINGLE_AXIS["rotation_amplitude_deg"]
ROTATION_AMPLITUDE_RAD = math.radians(ROTATION_AMPLITUDE_DEG)
#: Plant parameters of every run: sensor noise on, seeded (LK-H050 class).
PLANT_PARAMETERS = {"noise.enabled": True, "noise.seed": 2024}

ALL_FEEDBACK = {"feedback_x": True, "feedback_y": True, "feedback_theta": True}

# The two methods, selected by PiezoController's Integer parameters.
#: Modified inverse P-I feedforward with piecewise-linear decoupling (seed 000).
INVERSE_PI_PIECEWISE = {"hysteresis_model": 1, "decoupling_model": 1}
#: Inverse asymmetric Bouc-Wen feedforward with model-based decoupling (seed 001).
INVERSE_BOUC_WEN_MODEL_BASED = {"hysteresis_model": 2, "decoupling_model": 2}
METHODS = {"inverse_pi_piecewise": INVERSE_PI_PIECEWISE, "inverse_bouc_wen_model_based": INVERSE_BOUC_WEN_MODEL_BASED}
# Seed 001 §5.2-5.3: 2 Hz sines, feedforward only; linearity at 1.25 um (x)
# and 2 um (y) amplitude, coupling with a 2 um sine on one axis.
ABW_XY_HZ = 2.0
ABW_XY_LINEARITY_UM = {"x": 1.25, "y": 2.0}
ABW_XY_COUPLING_UM = 2.0
NO_FEEDBACK = {"feedback_x": False, "feedback_y": False, "feedback_theta": False}


def trajectory(path, start_pose=None):
    """A reference function of time: approach from the origin to the start
    pose, hold, then `path(tau)` with tau = t - START (tau >= 0)."""

    def reference(t):
        t = np.asarray(t, dtype=float)
        tau = t - START
        main = np.asarray(path(np.maximum(tau, 0.0)), dtype=float)
        start = np.asarray(path(np.zeros(1)), dtype=float)[0]
        s = np.clip(t / APPROACH_TIME, 0.0, 1.0)
        blend = 0.5 * (1.0 - np.cos(np.pi * s))
        approach = blend[:, None] * start[None, :]
        return np.where((tau >= 0.0)[:, None], main, approach)

    return reference


def pose(x=0.0, y=0.0, theta=0.0):
    """Columns of an (n, 3) reference: each axis a constant or a function of tau."""

    def path(tau):
        n = len(tau)
        return np.column_stack([
            value(tau) if callable(value) else np.full(n, float(value))
            for value in (x, y, theta)
        ])

    return path


def sine_from(base, span, frequency):
    """A sine from `base` to `base + span` starting at the bottom."""
    return lambda tau: base + 0.5 * span * (1.0 - np.cos(2 * np.pi * frequency * tau))


def rotation_sine(amplitude_rad=ROTATION_AMPLITUDE_RAD, frequency=SINE_HZ):
    return lambda tau: amplitude_rad * np.sin(2 * np.pi * frequency * tau)


@dataclass(frozen=True)
class Experiment:
    """One closed-loop run."""

    key: str
    title: str
    figure: str
    path: object
    duration_after_start: float
    measure_from: float  # tau at which metrics start
    controller: dict
    driven: str  # "y", "x", "theta", "xy", "ytheta"
    description: str = ""
    plant: dict = field(default_factory=lambda: dict(PLANT_PARAMETERS))

    @property
    def duration(self) -> float:
        return START + self.duration_after_start

    def reference(self):
        return trajectory(self.path)


def single_axis(axis: str, frequency: float = SINE_HZ, span: float = TRANSLATION_SPAN_UM,
                held: float | None = None, rotation_rad: float = ROTATION_AMPLITUDE_RAD):
    """Seed 000 §5's single-axis run: the driven axis's sine from rest, the
    other translation demanded at `held` (default HELD_UM, the paper's 0); a
    rotation runs about x at half stroke."""
    if axis == "y":
        return pose(x=HELD_UM[0] if held is None else held, y=sine_from(0.0, span, frequency))
    if axis == "x":
        return pose(x=sine_from(0.0, span, frequency), y=HELD_UM[1] if held is None else held)
    return pose(x=ROTATION_X_UM, y=0.0 if held is None else held,
                theta=rotation_sine(rotation_rad, frequency))


def single_axis_timing(frequency: float = SINE_HZ) -> tuple[float, float]:
    """(duration after the start, start of the measured window) of a
    single-axis run: SETTLING_CYCLES, then MEASURED_CYCLES."""
    return (SETTLING_CYCLES + MEASURED_CYCLES) / frequency, SETTLING_CYCLES / frequency


def driven_axis_feedback(axis: str) -> dict:
    return {**NO_FEEDBACK, f"feedback_{axis}": True}


def circle(tau):
    """eq. (14)-(15): x = 5 sin(0.8 pi t) + 6, y = 5 sin(0.8 pi t - pi/2) + 6."""
    return np.column_stack(
        [5 * np.sin(0.8 * np.pi * tau) + 6, 5 * np.sin(0.8 * np.pi * tau - 0.5 * np.pi) + 6,
         np.zeros_like(tau)]
    )


def y_and_rotation(tau):
    """eq. (16): theta_z = 9.2 sin(0.8 pi t) x 1e-3 deg about x at half stroke,
    with y following eq. (15)'s sine (seed 000 does not print Fig. 13's y)."""
    return np.column_stack(
        [np.full_like(tau, ROTATION_X_UM), 5 * np.sin(0.8 * np.pi * tau - 0.5 * np.pi) + 6,
         np.radians(9.2e-3 * np.sin(0.8 * np.pi * tau))]
    )


def composite(tau):
    """eq. (13), applied to y in um: 5.5 + 1.5 sin(2 pi t - pi/2) + sin(0.6 pi t - pi/2)
    + sin(pi t - pi/2); its period is 10 s. x and theta at 0."""
    y = (5.5 + 1.5 * np.sin(2 * np.pi * tau - 0.5 * np.pi) + np.sin(0.6 * np.pi * tau - 0.5 * np.pi)
         + np.sin(np.pi * tau - 0.5 * np.pi))
    return np.column_stack([np.zeros_like(tau), y, np.zeros_like(tau)])


#: The decoupling law fitted once, as seed 000 §4 computes it (round 1 of the
#: `stage` identification): dist/presets, written by `make fmus`.
FITTED_ONCE_PRESET = "PiezoController.stage_once.json"


def fitted_once() -> dict:
    """The compensations D1..D4 of FITTED_ONCE_PRESET by FMI name: the only
    entries in which it differs from the `stage` preset, the start values."""
    return {name: value for name, value in preset(FITTED_ONCE_PRESET).items()
            if name.startswith("compensation.")}


#: The runs of seed 000's table with the decoupling on (demo.paper's
#: DECOUPLED), each run twice: with the law fitted once (the table's) and
#: refined (the start values), under its key plus REFINED.
REFINED = "_refined"


def experiments() -> list[Experiment]:
    """Every run of the demo, in report order."""
    runs = [
        Experiment("fig6_y_ff", "y sine, feedforward only", "Fig. 6", single_axis("y"),
                   *single_axis_timing(), {**NO_FEEDBACK, "decoupling": False}, "y"),
    ]
    for axis in ("y", "x", "theta"):
        runs.append(Experiment(
            f"fig7_{axis}_ffpi", f"{axis} sine, feedforward + PI on {axis}", "Fig. 7 / Table 3",
            single_axis(axis), *single_axis_timing(),
            {**driven_axis_feedback(axis), "decoupling": False}, axis))
    for axis in ("y", "x", "theta"):
        runs.append(Experiment(
            f"fig10_{axis}_decoupled", f"{axis} sine, feedforward + PI on {axis} + decoupling",
            "Fig. 10 / Table 3", single_axis(axis), *single_axis_timing(),
            {**driven_axis_feedback(axis), "decoupling": True}, axis))
    runs += [
        Experiment("fig8_y_10hz_ff", "y sine at 10 Hz, feedforward only", "Fig. 8",
                   single_axis("y", 10.0), *single_axis_timing(10.0),
                   {**NO_FEEDBACK, "decoupling": False}, "y"),
        Experiment("fig8_y_10hz_ffpi", "y sine at 10 Hz, feedforward + PI on y", "Fig. 8",
                   single_axis("y", 10.0), *single_axis_timing(10.0),
                   {**driven_axis_feedback("y"), "decoupling": False}, "y"),
        Experiment("fig11_composite", "composite signal eq. (13) on y, decoupling controller",
                   "Fig. 11", composite, 10.0, 0.0, {**ALL_FEEDBACK, "decoupling": True}, "y"),
        Experiment("fig12_circle_coupled", "circle eq. (14)-(15), feedforward + PI",
                   "Fig. 12a", circle, 5.0, 2.5, {**ALL_FEEDBACK, "decoupling": False}, "xy"),
        Experiment("fig12_circle_decoupled", "circle eq. (14)-(15), decoupling controller",
                   "Fig. 12b", circle, 5.0, 2.5, {**ALL_FEEDBACK, "decoupling": True}, "xy"),
        Experiment("fig13_y_theta_coupled", "y + theta_z eq. (16), feedforward + PI", "Fig. 13a",
                   y_and_rotation, 5.0, 2.5, {**ALL_FEEDBACK, "decoupling": False}, "ytheta"),
        Experiment("fig13_y_theta_decoupled", "y + theta_z eq. (16), decoupling controller",
                   "Fig. 13b", y_and_rotation, 5.0, 2.5, {**ALL_FEEDBACK, "decoupling": True},
                   "ytheta"),
    ]
    for axis in ("y", "x", "theta"):
        for decoupling in (False, True):
            tag = "decoupled" if decoupling else "coupled"
            runs.append(Experiment(
                f"allfb_{axis}_{tag}",
                f"{axis} sine, PI on all axes{' + decoupling' if decoupling else ''}",
                "Table 3 (feedback on all axes)", single_axis(axis), *single_axis_timing(),
                {**ALL_FEEDBACK, "decoupling": decoupling}, axis))
    # The decoupled runs of the paper's table with the law fitted once (the
    # table's runs), and with the start values' refined law beside them.
    once = fitted_once()
    for e in list(runs):
        if e.key in DECOUPLED:
            runs.append(replace(e, key=e.key + REFINED,
                                title=e.title + ", decoupling refined (start values)"))
            runs[runs.index(e)] = replace(e, controller={**once, **e.controller})
    runs += feedforward_xy_experiments()
    return runs


def on_parameter_sets(runs: list[Experiment], plant_set: dict, controller_set: dict,
                      fitted_once_set: dict | None = None) -> list[Experiment]:
    """The runs on another stage: FlexureStage's parameters `plant_set` and
    PiezoController's `controller_set` (sets by FMI name, as dist/presets
    holds them and `flexure-stage-parameters`, `piezo-controller-parameters`
    write them) in place of the start values, each run's own settings kept:
    the plant's noise switch and seed (the set's noise level is the stage's),
    the controller's switches. A run with the law fitted once takes
    `fitted_once_set`'s D1..D4 (the `--out-fitted-once` preset of
    `piezo-identify stage`; without it, `controller_set`'s own law). A run
    on a stage of its own (the XY200S runs) stays on it."""
    law = "compensation."
    once = {k: v for k, v in (fitted_once_set or controller_set).items() if k.startswith(law)}
    moved = []
    for e in runs:
        if set(e.plant) - set(PLANT_PARAMETERS):  # a stage of its own: the XY200S's
            moved.append(e)
            continue
        # Every setting of the run is kept, whatever its value; a run that
        # names a law (the law fitted once) takes the set's.
        own = {k: v for k, v in e.controller.items() if not k.startswith(law)}
        if len(own) < len(e.controller):
            own |= once
        moved.append(replace(e, plant={**plant_set, **e.plant},
                             controller={**controller_set, **own}))
    return moved


#: The conditions and readings report.md lists (the module comment says why).
CONDITIONS = [
    "Demands as seed 000 prints them, absolute from the de-energized rest (every stack at "
    "0 V on its working loop, every reading 0): a single-axis sine drives its axis from 0 to "
    f"{TRANSLATION_SPAN_UM:g} um (y = {TRANSLATION_SPAN_UM / 2:g} - {TRANSLATION_SPAN_UM / 2:g} "
    "cos 2 pi t) with the other axes demanded at 0; a rotation runs "
    f"+-{ROTATION_AMPLITUDE_DEG:g} deg about x at half its stroke ({ROTATION_X_UM:g} um), the "
    "home §3.2 defines for rotation, "
    "y at 0. The stacks go below 0 V where the demand needs it: the PI E-505 takes -2..12 V "
    "(-20..120 V at the stacks), the controller's command range.",
    f"Single-axis sines at {SINE_HZ:g} Hz (seed 000 does not print the frequency of Fig. 6-7; "
    f"{SINE_HZ:g} Hz is "
    "the fastest component of its identification signal eq. (6) and Fig. 8's 'higher "
    "frequency' is 10 Hz). Each run starts at rest; the reference reaches the trajectory's "
    f"start by a raised cosine over {APPROACH_TIME:g} s and holds {SETTLE_TIME:g} s; t = 0 in "
    "the figures is the start "
    "of the trajectory.",
    f"Single-axis figures are taken over {MEASURED_CYCLES} cycles after {SETTLING_CYCLES} "
    "settling cycles: the plant's Bouc-Wen minor loops need about four cycles to settle when "
    "a held actuator starts cycling about a new point (the offset left shrinks by about 0.35 "
    "per cycle). Other runs: the circle and eq. (16) over their second revolution "
    "(2.5 s), eq. (13) over its first period (10 s).",
    "Errors are demand minus sensor reading (s1; (s2+s3)/2; (s2-s3)/L; x2 = s2, x3 = s3), "
    "sensor noise on (0.005 um RMS per reading, seeded), as the paper measured them.",
    "Fig. 6, 7, 10 and Table 3: feedback on the driven axis only, feedforward of the demand "
    "(plus the decoupling compensation when it is on) on the others, as the paper. Fig. 11-13: "
    "the whole controller of Fig. 9, PI on every axis.",
    "Fig. 11: eq. (13) read as a y demand in um (its values, 2..8, fit the y stroke), x and "
    "theta at 0.",
    "Fig. 12: contour error = distance of the measured point from the demanded circle minus "
    "its radius; the 2-norm is the square root of the sum of squares over one revolution "
    "(2.5 s) at the 10 kHz loop rate, 25,001 samples: at that count the paper's 2-norms "
    "(11.19, 5.72) and its error bounds (+-162/+-117 nm, +-97/+-65 nm) describe the same "
    "errors (RMS 0.071 and 0.036 um). The text prints '11.19 and 5.72 with and without' "
    "beside 'significantly improved when the decoupling technique is enabled'; the larger "
    "norm is read as the one without decoupling.",
    "Fig. 13: theta_z by eq. (16) about x at half stroke; seed 000 does not print the y "
    "demand: y follows eq. (15)'s sine (1..11 um, the same 0.4 Hz).",
]


#: A pose in the middle of both strokes, x at its rotation home: where the
#: packaged closed loop (demo.systems) parks the stage.
MID_STROKE = (_HOMES["mid_stroke"]["x"], _HOMES["mid_stroke"]["y"], 0.0)
#: Seed 001's single-axis homes on FlexureStage (its runs about a home).
ABW_XY_HOME = (_HOMES["single_axis_flexure"]["x"], _HOMES["single_axis_flexure"]["y"], 0.0)

# The stages seed 001's experiments run on: FlexureStage as it starts, and
# its XY200S parameter set with the controller identified on it (both sets
# written by `make fmus` from the Rust tables). The XY200S home sits at the
# same fraction of its strokes as seed 000's (piezo-identify's --home).
ABW_XY_STAGES = {
    "flexure": {"home": ABW_XY_HOME, "plant": None, "controller": None},
    "xy200s": {
        "home": (_HOMES["single_axis_xy200s"]["x"], _HOMES["single_axis_xy200s"]["y"], 0.0),
        "plant": "FlexureStage.xy200s.json",
        "controller": "PiezoController.xy200s.json",
    },
}


def preset(name: str | None) -> dict:
    """A parameter set of dist/presets by file name (empty for None)."""
    if name is None:
        return {}
    path = Path(__file__).resolve().parent.parent / "dist" / "presets" / name
    if not path.is_file():
        raise FileNotFoundError(f"{path}: run `make fmus` first")
    return json.loads(path.read_text())


def abw_xy_key(stage: str, method: str, rest: str) -> str:
    prefix = "abw_xy" if stage == "flexure" else f"abw_xy_{stage}"
    return f"{prefix}_{method}_{rest}"


def feedforward_xy_experiments() -> list[Experiment]:
    """Seed 001 §5.2-5.3 on both stages, by both methods: feedforward only
    (no feedback, as seed 001), 2 Hz sines about the stage's single-axis
    home; for the linearity runs the other axis is demanded at 0 (seed 001:
    0 V), for the coupling runs it is held at its home (where a coupling can
    be cancelled)."""
    runs = []
    for stage, setup in ABW_XY_STAGES.items():
        home = setup["home"]
        plant = {**preset(setup["plant"]), **PLANT_PARAMETERS}
        base = preset(setup["controller"])

        def path(axis, amplitude, other_at_zero, home=home):
            other = "y" if axis == "x" else "x"
            index = {"x": 0, "y": 1}

            def columns(tau):
                cols = [np.full(len(tau), home[0]), np.full(len(tau), home[1]),
                        np.zeros(len(tau))]
                base = home[index[axis]] - amplitude
                cols[index[axis]] = sine_from(base, 2 * amplitude, ABW_XY_HZ)(tau)
                if other_at_zero:
                    cols[index[other]] = np.zeros(len(tau))
                return np.column_stack(cols)

            return columns

        for method, selectors in METHODS.items():
            def run(rest, title, figure, path, axis, decoupling, method=method,
                    selectors=selectors):
                return Experiment(
                    abw_xy_key(stage, method, rest), f"{title} ({method}, {stage})", figure,
                    path, *single_axis_timing(ABW_XY_HZ),
                    {**base, **NO_FEEDBACK, **selectors, "decoupling": decoupling}, axis,
                    plant=plant)

            for axis in ("x", "y"):
                amplitude = ABW_XY_LINEARITY_UM[axis]
                runs.append(run(
                    f"linearity_{axis}",
                    f"{axis} {ABW_XY_HZ:g} Hz sine of {amplitude} um, feedforward only",
                    "seed 001 §5.2", path(axis, amplitude, True), axis, False))
            for axis in ("y", "x"):
                for decoupling in (False, True):
                    tag = "decoupled" if decoupling else "coupled"
                    runs.append(run(
                        f"coupling_{axis}_{tag}",
                        f"{axis} {ABW_XY_HZ:g} Hz sine of {ABW_XY_COUPLING_UM:g} um, other axis held, "
                        f"feedforward only{' + decoupling' if decoupling else ''}",
                        "seed 001 §5.3", path(axis, ABW_XY_COUPLING_UM, False), axis, decoupling))
    return runs


@dataclass
class Errors:
    """Demand-minus-measurement errors over the measured window."""

    t: np.ndarray
    e_x: np.ndarray
    e_y: np.ndarray
    e_theta: np.ndarray
    e_x2: np.ndarray
    e_x3: np.ndarray


def errors(run, spacing_um: float, measure_from: float) -> Errors:
    t = run.t
    window = t >= START + measure_from - 1e-12
    x_d, y_d, th_d = run["x_ref"], run["y_ref"], run["theta_ref"]
    s1, s2, s3 = run["s1"], run["s2"], run["s3"]
    x_d2 = x_d + th_d * spacing_um / 2
    x_d3 = x_d - th_d * spacing_um / 2
    return Errors(
        t=t[window],
        e_x=(x_d - 0.5 * (s2 + s3))[window],
        e_y=(y_d - s1)[window],
        e_theta=(th_d - (s2 - s3) / spacing_um)[window],
        e_x2=(x_d2 - s2)[window],
        e_x3=(x_d3 - s3)[window],
    )


def rms(v) -> float:
    return float(np.sqrt(np.mean(np.square(v))))


def max_abs(v) -> float:
    return float(np.max(np.abs(v)))


def span(v) -> float:
    return float(np.max(v) - np.min(v))


def straight_line_floor(coupling: np.ndarray, demand: np.ndarray) -> float:
    """The smallest span of `coupling` minus any straight line in `demand`,
    min over k of span(coupling - k * demand) (an offset does not change a
    span): what the best law D = dk * demand + db leaves of a coupling if
    the held axis answered the correction exactly. span(coupling - k *
    demand) is convex in k (a maximum minus a minimum of affine functions),
    so a ternary search finds its minimum; the bracket holds every slope a
    coupling of this stage has (under 10 um per um)."""
    low, high = -10.0, 10.0
    for _ in range(200):
        a, b = low + (high - low) / 3, high - (high - low) / 3
        if span(coupling - a * demand) <= span(coupling - b * demand):
            high = b
        else:
            low = a
    return span(coupling - 0.5 * (low + high) * demand)


def coupling_analysis(experiment: Experiment, run, spacing_um: float) -> dict:
    """Beyond the paper's figures, for seed 001's coupling runs: the span the
    best straight-line law in the driving demand would leave of the coupling
    (`straight_line_floor`), the bound on any piecewise-linear law of seed
    000's form (eq. 11) that the cutoffs do not clip."""
    if not experiment.figure.startswith("seed 001 §5.3") or experiment.driven not in ("x", "y"):
        return {}
    e = errors(run, spacing_um, experiment.measure_from)
    window = run.t >= START + experiment.measure_from - 1e-12
    if experiment.driven == "y":
        return {"coupling_x_line_floor": straight_line_floor(e.e_x, run["y_ref"][window])}
    return {"coupling_y_line_floor": straight_line_floor(e.e_y, run["x_ref"][window])}


def report_figures(experiment: Experiment, run, spacing_um: float) -> dict:
    """`metrics` and `coupling_analysis` of a run: what the demo reports."""
    return {**metrics(experiment, run, spacing_um), **coupling_analysis(experiment, run, spacing_um)}


def metrics(experiment: Experiment, run, spacing_um: float) -> dict:
    """The figures the paper reports for this kind of run."""
    e = errors(run, spacing_um, experiment.measure_from)
    m: dict = {}
    if experiment.driven in ("y", "x", "theta"):
        tracking = {"y": e.e_y, "x": e.e_x, "theta": e.e_theta}[experiment.driven]
        m["tracking_max"] = max_abs(tracking)
        m["tracking_rms"] = rms(tracking)
        if experiment.driven == "y":
            m["coupling_x_span"] = span(e.e_x)
            m["coupling_x2_span"] = span(e.e_x2)
            m["coupling_x2_range"] = (float(e.e_x2.min()), float(e.e_x2.max()))
            m["coupling_x3_span"] = span(e.e_x3)
            m["coupling_x3_range"] = (float(e.e_x3.min()), float(e.e_x3.max()))
        else:
            m["coupling_y_span"] = span(e.e_y)
            m["coupling_y_range"] = (float(e.e_y.min()), float(e.e_y.max()))
    elif experiment.driven == "xy":
        # Contour error: distance from the measured point to the demanded
        # circle (radius 5 um about (6, 6)), as the 2-norm over the samples.
        x = 0.5 * (run["s2"] + run["s3"])
        y = run["s1"]
        window = run.t >= START + experiment.measure_from - 1e-12
        contour = np.hypot(x - 6.0, y - 6.0)[window] - 5.0
        m["contour_2norm"] = float(np.linalg.norm(contour))
        m["contour_rms"] = rms(contour)
        m["contour_samples"] = int(window.sum())
        m["x_error_range"] = (float(e.e_x.min()), float(e.e_x.max()))
        m["y_error_range"] = (float(e.e_y.min()), float(e.e_y.max()))
        m["x_error_max"] = max_abs(e.e_x)
        m["y_error_max"] = max_abs(e.e_y)
    elif experiment.driven == "ytheta":
        m["theta_error_range"] = (float(e.e_theta.min()), float(e.e_theta.max()))
        m["y_error_range"] = (float(e.e_y.min()), float(e.e_y.max()))
        m["theta_error_max"] = max_abs(e.e_theta)
        m["y_error_max"] = max_abs(e.e_y)
    return m


#: The driven axis's error and the stack whose local slope sets its loop
#: gain (PZT1 for y; PZT2 for x and theta_z, which PZT3 mirrors).
_DRIVEN_STACK = {"y": ("e_y", "s1", "u1"), "x": ("e_x", "s2", "u2"),
                 "theta": ("e_theta", "s2", "u2")}


def noise_error_by_phase(experiment: Experiment, noisy, clean, spacing_um: float,
                         frequency: float = SINE_HZ,
                         bins: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Where in the sine's cycle the sensor noise makes a single-axis run's
    error: the RMS of (error with noise - error of the same run without) over
    each 1/`bins` of the cycle (the sine of `frequency` starts at START), and the driven stack's local slope
    d(sensor)/d(command) [um/V] there on the run without noise. A loop that
    only filters the noise gives the same RMS in every bin; one that reaches
    its stability limit where the stack is steepest grows bursts there."""
    error, sensor, command = _DRIVEN_STACK[experiment.driven]
    share = (getattr(errors(noisy, spacing_um, experiment.measure_from), error)
             - getattr(errors(clean, spacing_um, experiment.measure_from), error))
    t = clean.t
    window = t >= START + experiment.measure_from - 1e-12
    phase_bin = np.minimum(np.floor(((t - START) * frequency) % 1.0 * bins),
                           bins - 1).astype(int)
    rate_sensor = np.gradient(clean[sensor], t)
    rate_command = np.gradient(clean[command], t)
    rms_by_bin = np.empty(bins)
    slope_by_bin = np.empty(bins)
    for b in range(bins):
        inside = window & (phase_bin == b)
        rms_by_bin[b] = rms(share[phase_bin[window] == b])
        slope_by_bin[b] = (np.sum(rate_sensor[inside] * rate_command[inside])
                           / np.sum(rate_command[inside] ** 2))
    return rms_by_bin, slope_by_bin
