"""Closed-loop co-simulation of PiezoController and FlexureStage with fmpy.

Master algorithm (documented because it decides the loop's delay): fixed
communication step h (10 kHz by default, seed 000's DS1103 rate), Jacobi
ordering. At each communication point t_k both FMUs receive the other's
outputs at t_k (controller: the sensors s(t_k); plant: the commands u(t_k) that
the controller produced at its previous step), then both step from t_k to
t_k+1. The controller samples its inputs at the start of its step and its
outputs hold from the end of the step, so the command the plant applies over
[t_k, t_k+1] was computed from s(t_k-1): one sample of compute delay, as on a
DSP that writes its outputs at the next sample. Because neither FMU has direct
feedthrough, Gauss-Seidel ordering would give the same result.

The references are known in advance (the trajectory is a function of time, as
it was on the DS1103), so the controller receives them with a preview of
`preview` samples: r(t_k + preview·h) at t_k. With preview = 2 the command
applied over [t_k, t_k+1] aims at r(t_k+1), the next point where the loop is
sampled, which makes up for the compute delay of the master; the remaining lag
of the amplifier and the structure is the feedback's job.
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2Real, fmi2ValueReference

PLANT_OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")
CONTROLLER_INPUTS = ("x_ref", "y_ref", "theta_ref", "s1", "s2", "s3")
CONTROLLER_OUTPUTS = (
    "u1", "u2", "u3", "u1_ff", "u2_ff", "u3_ff", "u1_fb", "u2_fb", "u3_fb",
    "e_x", "e_y", "e_theta", "x_r2", "x_r3", "y_rx", "y_rtheta",
)
#: The seed 000 controller's sample rate (§2).
SAMPLE_PERIOD = 1e-4


class Fmu:
    """An FMU extracted once, instantiated as often as needed."""

    def __init__(self, path: str | Path):
        self.path = str(path)
        self.description = read_model_description(self.path)
        self.unzipdir = extract(self.path, unzipdir=tempfile.mkdtemp(prefix="cosim-"))
        self.variables = {v.name: v for v in self.description.modelVariables}

    def vr(self, name: str) -> int:
        try:
            return self.variables[name].valueReference
        except KeyError:
            raise KeyError(f"{Path(self.path).name} has no variable {name!r}") from None

    def instance(self, name: str, parameters: dict | None = None) -> "Slave":
        """Instantiates, applies `parameters` (by name, any FMI type) in
        initialization mode, and leaves the instance ready to step at t = 0."""
        d = self.description
        slave = FMU2Slave(
            guid=d.guid,
            unzipDirectory=self.unzipdir,
            modelIdentifier=d.coSimulation.modelIdentifier,
            instanceName=name,
        )
        slave.instantiate()
        try:
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            for key, value in (parameters or {}).items():
                variable = self.variables.get(key)
                if variable is None:
                    raise KeyError(f"{Path(self.path).name} has no parameter {key!r}")
                if variable.type == "Boolean":
                    slave.setBoolean([variable.valueReference], [bool(value)])
                elif variable.type == "Integer":
                    slave.setInteger([variable.valueReference], [int(value)])
                else:
                    slave.setReal([variable.valueReference], [float(value)])
            slave.exitInitializationMode()
        except BaseException:
            slave.freeInstance()
            raise
        return Slave(self, slave)

    def close(self) -> None:
        shutil.rmtree(self.unzipdir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Slave:
    """An initialized instance with preallocated value-reference and value
    buffers for the names it exchanges at every step (fmpy's convenience
    setters build new ctypes arrays on every call)."""

    def __init__(self, fmu: Fmu, slave: FMU2Slave):
        self.fmu = fmu
        self.slave = slave

    def real_port(self, names) -> "RealPort":
        return RealPort(self.slave, [self.fmu.vr(n) for n in names])

    def do_step(self, t: float, h: float) -> None:
        self.slave.fmi2DoStep(self.slave.component, t, h, 1)

    def free(self) -> None:
        try:
            self.slave.terminate()
        finally:
            self.slave.freeInstance()


class RealPort:
    """A fixed list of Real variables read or written together."""

    def __init__(self, slave: FMU2Slave, vrs: list[int]):
        self.slave = slave
        self.n = len(vrs)
        self.vrs = (fmi2ValueReference * self.n)(*vrs)
        self.values = (fmi2Real * self.n)()
        self.view = np.ctypeslib.as_array(self.values)

    def get(self) -> np.ndarray:
        self.slave.fmi2GetReal(self.slave.component, self.vrs, self.n, self.values)
        return self.view

    def set(self, values) -> None:
        self.view[:] = values
        self.slave.fmi2SetReal(self.slave.component, self.vrs, self.n, self.values)


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
) -> Run:
    """Runs the closed loop for `duration` s. `reference(t)` takes an array of
    times and returns an (n, 3) array of x_ref [um], y_ref [um], theta_ref
    [rad]; `progress(steps_done)` is called every 1000 steps."""
    steps = round(duration / step)
    t = np.arange(steps + 1) * step
    references = np.asarray(reference(t), dtype=float)
    ahead = np.asarray(reference(t + preview * step), dtype=float)
    p = plant.instance("plant", plant_parameters)
    try:
        c = controller.instance("controller", controller_parameters)
    except BaseException:
        p.free()
        raise
    try:
        plant_in = p.real_port(("u1", "u2", "u3"))
        plant_out = p.real_port(PLANT_OUTPUTS)
        ctrl_in = c.real_port(CONTROLLER_INPUTS)
        ctrl_out = c.real_port(CONTROLLER_OUTPUTS)
        plant_log = np.empty((steps + 1, len(PLANT_OUTPUTS)))
        ctrl_log = np.empty((steps + 1, len(CONTROLLER_OUTPUTS)))
        controller_inputs = np.empty(len(CONTROLLER_INPUTS))
        for k in range(steps + 1):
            plant_log[k] = plant_out.get()
            ctrl_log[k] = ctrl_out.get()
            if k == steps:
                break
            # Jacobi: both FMUs see the other's outputs at t_k.
            plant_in.set(ctrl_log[k, :3])
            controller_inputs[:3] = ahead[k]
            controller_inputs[3:] = plant_log[k, :3]
            ctrl_in.set(controller_inputs)
            p.do_step(t[k], step)
            c.do_step(t[k], step)
            if progress is not None and k % 1000 == 999:
                progress(1000)
        if progress is not None:
            progress(steps % 1000)
    finally:
        c.free()
        p.free()
    return Run(
        t=t,
        references=references,
        plant={n: plant_log[:, i].copy() for i, n in enumerate(PLANT_OUTPUTS)},
        controller={n: ctrl_log[:, i].copy() for i, n in enumerate(CONTROLLER_OUTPUTS)},
        meta={"step": step, "preview": preview},
    )
