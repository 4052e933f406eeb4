"""Closed-loop co-simulation of PiezoController and FlexureStage with fmpy.

Master algorithm (documented because it decides the loop's delay): fixed
communication step h (10 kHz by default, seed 000's DS1103 rate), Jacobi
ordering. At each communication point t_k both FMUs receive the other's
outputs at t_k (controller: the sensors s(t_k); plant: the commands u(t_k) that
the controller produced at its previous step), then both step from t_k to
t_k+1. The controller samples its inputs at the start of its step and its
outputs hold from the end of the step, so the command the plant applies over
[t_k, t_k+1] was computed from s(t_k-1): one sample of compute delay, as on a
DSP that writes its outputs at the next sample. Gauss-Seidel ordering (one FMU
stepped first, its new outputs fed to the other) would remove that sample and
give another loop.

The references are known in advance (the trajectory is a function of time, as
it was on the DS1103), so the controller receives them with a preview of
`preview` samples: r(t_k + preview·h) at t_k. With preview = 2 the command
applied over [t_k, t_k+1] aims at r(t_k+1), the next point where the loop is
sampled, which makes up for the compute delay of the master; the remaining lag
of the amplifier and the structure is the feedback's job.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy.fmi1 import FMICallException

# The demo's and the tests' import path for these names.
from demo.fmu import Fmu, FmuCallError, Instance, RealPort  # noqa: F401


#: The closed loop's wiring, the one table every master that builds the loop
#: reads: this module's fmpy master, the SSP package and the container FMU that
#: demo.systems generates, and the libcosim tests. (source, destination) pairs:
#: the controller's commands drive the plant's amplifier channels, the plant's
#: laser sensors feed the controller. demo.systems checks every name against
#: both modelDescription.xml files (causality and type) when it generates.
COMMANDS = (("u1", "u1"), ("u2", "u2"), ("u3", "u3"))  # PiezoController -> FlexureStage
SENSORS = (("s1", "s1"), ("s2", "s2"), ("s3", "s3"))  # FlexureStage -> PiezoController
#: PiezoController inputs driven by the trajectory (x [um], y [um], theta [rad]).
REFERENCES = ("x_ref", "y_ref", "theta_ref")
#: Instance names of the two FMUs in every master (and SSP component names).
PLANT_INSTANCE = "plant"
CONTROLLER_INSTANCE = "controller"

PLANT_OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")
CONTROLLER_INPUTS = REFERENCES + tuple(sensor for _, sensor in SENSORS)
CONTROLLER_OUTPUTS = (
    "u1", "u2", "u3", "u1_ff", "u2_ff", "u3_ff", "u1_fb", "u2_fb", "u3_fb",
    "e_x", "e_y", "e_theta", "x_r2", "x_r3", "y_rx", "y_rtheta",
)
#: The seed 000 controller's sample rate (§2).
SAMPLE_PERIOD = 1e-4


@dataclass
class Run:
    """Everything recorded at each communication point of a closed-loop run."""

    t: np.ndarray
    references: np.ndarray  # x_ref [um], y_ref [um], theta_ref [rad] at t (without preview)
    plant: dict
    controller: dict
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.plant:
            return self.plant[name]
        if name in self.controller:
            return self.controller[name]
        index = {"x_ref": 0, "y_ref": 1, "theta_ref": 2}.get(name)
        if index is None:
            raise KeyError(name)
        return self.references[:, index]

    def write_csv(self, path: Path) -> None:
        names = ["t", "x_ref", "y_ref", "theta_ref", *PLANT_OUTPUTS, *CONTROLLER_OUTPUTS]
        data = np.column_stack(
            [self.t, self.references]
            + [self.plant[n] for n in PLANT_OUTPUTS]
            + [self.controller[n] for n in CONTROLLER_OUTPUTS]
        )
        units = {"t": "s", "theta_ref": "rad", "theta_z": "rad", "e_theta": "rad"}
        header = ",".join(
            f"{n}[{units.get(n, 'V' if n.startswith('u') else 'um')}]" for n in names
        )
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.10g")


def simulate(
    plant: Fmu,
    controller: Fmu,
    reference,
    duration: float,
    step: float = SAMPLE_PERIOD,
    plant_parameters: dict | None = None,
    controller_parameters: dict | None = None,
    preview: int = 2,
    progress=None,
    communication_points=None,
) -> Run:
    """Runs the closed loop for `duration` s. `reference(t)` takes an array of
    times and returns an (n, 3) array of x_ref [um], y_ref [um], theta_ref
    [rad]; `progress(steps_done)` is called every 1000 steps.

    `communication_points` (optional) are the times t_0..t_n to step through,
    each step being t_k+1 - t_k; by default t_k = k·step. An importer that
    keeps time in integer nanoseconds (libcosim) hands the FMUs its own
    double time points and steps; passing those reproduces its run exactly."""
    steps = round(duration / step)
    if communication_points is None:
        t = np.arange(steps + 1) * step
        step_sizes = np.full(steps, step)
    else:
        t = np.asarray(communication_points, dtype=float)
        if t.shape != (steps + 1,):
            raise ValueError(f"{steps + 1} communication points expected, got {t.shape}")
        step_sizes = np.diff(t)
    references = np.asarray(reference(t), dtype=float)
    # The preview's times as the compiled master takes them, (k + preview)·h:
    # t_k + preview·h differs in the last bit, which on a table's step edge
    # made the two masters 2.8e-12 um apart.
    ahead_t = (np.arange(steps + 1) + preview) * step if communication_points is None \
        else t + preview * step
    ahead = np.asarray(reference(ahead_t), dtype=float)
    p = plant.instance(PLANT_INSTANCE, plant_parameters)
    try:
        c = controller.instance(CONTROLLER_INSTANCE, controller_parameters)
    except BaseException:
        p.free()
        raise
    completed = False
    try:
        plant_in = p.real_port(tuple(command for _, command in COMMANDS))
        plant_out = p.real_port(PLANT_OUTPUTS)
        ctrl_in = c.real_port(CONTROLLER_INPUTS)
        ctrl_out = c.real_port(CONTROLLER_OUTPUTS)
        plant_log = np.empty((steps + 1, len(PLANT_OUTPUTS)))
        ctrl_log = np.empty((steps + 1, len(CONTROLLER_OUTPUTS)))
        controller_inputs = np.empty(len(CONTROLLER_INPUTS))
        commands = [CONTROLLER_OUTPUTS.index(source) for source, _ in COMMANDS]
        sensors = [PLANT_OUTPUTS.index(source) for source, _ in SENSORS]
        n_references = len(REFERENCES)
        for k in range(steps + 1):
            plant_log[k] = plant_out.get()
            ctrl_log[k] = ctrl_out.get()
            if k == steps:
                break
            # Jacobi: both FMUs see the other's outputs at t_k.
            plant_in.set(ctrl_log[k, commands])
            controller_inputs[:n_references] = ahead[k]
            controller_inputs[n_references:] = plant_log[k, sensors]
            ctrl_in.set(controller_inputs)
            p.do_step_at(t[k], step_sizes[k])
            c.do_step_at(t[k], step_sizes[k])
            if progress is not None and k % 1000 == 999:
                progress(1000)
        if progress is not None:
            progress(steps % 1000)
        completed = True
    except FMICallException as error:
        raise FmuCallError(error, p, c) from error
    finally:
        # An instance that returned fmi2Error may only be freed (or reset):
        # fmi2Terminate is for a run that ended well. Both are freed, and a
        # refused fmi2Terminate is raised with what the FMUs logged.
        refused = []
        for instance in (c, p):
            try:
                instance.free(terminate=completed)
            except FMICallException as error:
                refused.append(error)
        if refused:
            raise FmuCallError(refused[0], p, c) from refused[0]
    return Run(
        t=t,
        references=references,
        plant={n: plant_log[:, i].copy() for i, n in enumerate(PLANT_OUTPUTS)},
        controller={n: ctrl_log[:, i].copy() for i, n in enumerate(CONTROLLER_OUTPUTS)},
        meta={"step": step, "preview": preview},
    )
