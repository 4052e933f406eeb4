"""The one fmpy wrapper of the demo and the tests: an FMU extracted once,
instances of it with their own logger, values set and read by name.

It drives fmpy's low-level FMU2Slave, so a caller keeps control of the exact
FMI call sequence, the fmi2Instantiate arguments and the logger callback (the
importer tests need that); `Fmu.instance` is the short path of a master:
instantiate, parameters by name in initialization mode, ready at t = 0.
Every value is set through the setter of its declared type.
"""

from __future__ import annotations

import shutil
import tempfile
from ctypes import byref
from dataclasses import dataclass, field
from pathlib import Path

import fmpy
import numpy as np
from fmpy import fmi2
from fmpy.fmi1 import FMICallException

STATUS_NAMES = {
    fmi2.fmi2OK: "fmi2OK",
    fmi2.fmi2Warning: "fmi2Warning",
    fmi2.fmi2Discard: "fmi2Discard",
    fmi2.fmi2Error: "fmi2Error",
    fmi2.fmi2Fatal: "fmi2Fatal",
}


#: What a value of each type is, for set_values' refusals.
_KINDS_TAKE = {"Real": "a number", "Integer": "a whole number", "Boolean": "True or False"}


def _is_of_kind(value, kind: str) -> bool:
    """Whether `value` is a value of an FMI variable of type `kind` as it is,
    without a conversion that changes what it means."""
    import numbers

    if kind == "Boolean":
        return isinstance(value, (bool, np.bool_))
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return False
    if kind == "Integer":
        return float(value).is_integer()
    return True


@dataclass
class LogRecord:
    instance_name: str
    status: int
    category: str
    raw: str  # the message as the FMU passed it (a printf format: '%' doubled, '#' too)

    @property
    def text(self) -> str:
        """The message as an importer shows it: '%%' -> '%' (printf) and '##' -> '#'
        (FMI 2.0.4 §2.1.5: '#' opens a variable reference, which these FMUs never send)."""
        return self.raw.replace("%%", "%").replace("##", "#")

    def __str__(self) -> str:
        return (
            f"[{STATUS_NAMES.get(self.status, self.status)}|{self.category}|"
            f"{self.instance_name}] {self.raw}"
        )


@dataclass
class LogCapture:
    """A fmi2CallbackFunctions whose logger records every message.

    The callbacks object must stay alive as long as the instance, which
    Instance ensures by holding it.
    """

    records: list[LogRecord] = field(default_factory=list)

    def __post_init__(self):
        self._logger = fmi2.fmi2CallbackLoggerTYPE(self._log)
        self.callbacks = fmi2.fmi2CallbackFunctions()
        self.callbacks.logger = self._logger
        self.callbacks.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, instance_name, status, category, message):
        def dec(b):
            return b.decode("utf-8", "replace") if b is not None else None

        self.records.append(LogRecord(dec(instance_name), status, dec(category), dec(message)))

    def clear(self):
        self.records.clear()

    def matching(self, *needles: str, status: int | None = None) -> list[LogRecord]:
        """Records whose (unescaped) text contains every needle."""
        return [
            r
            for r in self.records
            if all(n in r.text for n in needles) and (status is None or r.status == status)
        ]

    def dump(self) -> str:
        return "\n".join(str(r) for r in self.records) or "(no log messages)"


class FmuCallError(FMICallException):
    """fmpy's FMICallException with what the FMU logged about it: the
    messages of status fmi2Warning and above of the instances concerned
    (the status alone does not say which parameter, or why)."""

    def __init__(self, error: FMICallException, *instances: "Instance"):
        super().__init__(error.function, error.status)
        self.messages = [str(r) for i in instances for r in i.log.records
                         if r.status >= fmi2.fmi2Warning]
        if self.messages:
            self.args = (self.args[0] + " The FMUs logged:\n" + "\n".join(self.messages),)


class Fmu:
    """An FMU extracted once (into `unzipdir`, or a fresh temporary folder that
    `close` removes), instantiated as often as needed."""

    def __init__(self, path: str | Path, unzipdir: str | Path | None = None):
        self.path = str(path)
        self.description = fmpy.read_model_description(self.path)
        self._owns_unzipdir = unzipdir is None
        self.unzipdir = str(unzipdir) if unzipdir is not None else fmpy.extract(
            self.path, unzipdir=tempfile.mkdtemp(prefix="fmu-"))
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.vrs = {name: v.valueReference for name, v in self.variables.items()}
        self.types = {name: v.type for name, v in self.variables.items()}
        self.guid = self.description.guid

    def vr(self, name: str) -> int:
        try:
            return self.vrs[name]
        except KeyError:
            raise KeyError(f"{Path(self.path).name} has no variable {name!r}") from None

    def load(self, instance_name: str) -> fmi2.FMU2Slave:
        """The binary loaded for one instance (not yet instantiated)."""
        return fmi2.FMU2Slave(
            guid=self.guid,
            unzipDirectory=self.unzipdir,
            modelIdentifier=self.description.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )

    def instantiate(self, name: str = "probe", logging_on: bool = False,
                    resource_location: object = ...) -> "Instance":
        """A new co-simulation instance whose messages go to its `log`.
        resource_location: ... = fmpy's own URI of the resources folder,
        None = NULL, str = that exact string."""
        slave, log = self.load(name), LogCapture()
        if resource_location is ...:
            slave.instantiate(callbacks=log.callbacks, loggingOn=logging_on)
        else:
            slave.callbacks = log.callbacks
            location = None if resource_location is None else resource_location.encode("utf-8")
            slave.component = slave.fmi2Instantiate(
                name.encode("utf-8"), fmi2.fmi2CoSimulation, self.guid.encode("utf-8"), location,
                byref(log.callbacks), fmi2.fmi2False,
                fmi2.fmi2True if logging_on else fmi2.fmi2False,
            )
            if not slave.component:
                slave.freeLibrary()
                raise RuntimeError(
                    f"fmi2Instantiate returned NULL for fmuResourceLocation="
                    f"{resource_location!r}; log:\n{log.dump()}")
        return Instance(self, slave, log)

    def instance(self, name: str, parameters: dict | None = None) -> "Instance":
        """Instantiates, applies `parameters` (by name, any FMI type) in
        initialization mode, and leaves the instance ready to step at t = 0."""
        for key in parameters or {}:
            if key not in self.variables:
                raise KeyError(f"{Path(self.path).name} has no parameter {key!r}")
        instance = self.instantiate(name)
        try:
            instance.initialize(start_values=parameters, in_initialization_mode=True)
        except FMICallException as error:
            instance.free()
            raise FmuCallError(error, instance) from error
        except BaseException:
            instance.free()
            raise
        return instance

    def close(self) -> None:
        if self._owns_unzipdir:
            shutil.rmtree(self.unzipdir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Instance:
    """One instance (its own FMU2Slave, library handle and logger); values by
    name. Calls above fmi2Warning raise fmpy's FMICallException, except the
    raw fmi2DoStep of `do_step`/`do_step_at`, whose status is returned."""

    def __init__(self, fmu: Fmu, slave: fmi2.FMU2Slave, log: LogCapture):
        self.owner = fmu
        self.fmu = slave
        self.log = log
        self.time = 0.0
        self.freed = False

    # -- values by name -------------------------------------------------------
    def vr(self, *names: str) -> list[int]:
        return [self.owner.vr(n) for n in names]

    def get(self, *names: str) -> list[float]:
        return self.fmu.getReal(self.vr(*names))

    def get1(self, name: str) -> float:
        return self.get(name)[0]

    def _set(self, setter, ctype, values: dict, convert) -> int:
        names = list(values)
        vrs = (fmi2.fmi2ValueReference * len(names))(*self.vr(*names))
        vals = (ctype * len(names))(*(convert(values[n]) for n in names))
        return setter(self.fmu.component, vrs, len(names), vals)

    def set_real(self, values: dict[str, float]) -> int:
        """fmi2SetReal on the given values; returns the status (raises above warning)."""
        return self._set(self.fmu.fmi2SetReal, fmi2.fmi2Real, values, float)

    def set_integer(self, values: dict[str, int]) -> int:
        return self._set(self.fmu.fmi2SetInteger, fmi2.fmi2Integer, values, int)

    def set_boolean(self, values: dict[str, bool]) -> int:
        return self._set(self.fmu.fmi2SetBoolean, fmi2.fmi2Boolean, values,
                         lambda v: int(bool(v)))

    def set_values(self, values: dict) -> None:
        """Sets values by their declared type (Real, Integer or Boolean). A
        value of another kind is refused, not converted: "false" is true to
        Python's bool(), and int() takes 1.9 for 1."""
        setters = {"Real": self.set_real, "Integer": self.set_integer,
                   "Boolean": self.set_boolean}
        for name, value in values.items():
            kind = self.owner.types.get(name)
            if kind not in setters:
                raise KeyError(f"{Path(self.owner.path).name}: {name!r} is not a Real, "
                               f"Integer or Boolean variable ({kind})")
            if not _is_of_kind(value, kind):
                raise TypeError(f"{Path(self.owner.path).name}: {name!r} is a {kind} variable, "
                                f"which takes {_KINDS_TAKE[kind]}; {value!r} was given")
            setters[kind]({name: value})

    def real_port(self, names) -> "RealPort":
        return RealPort(self.fmu, self.vr(*names))

    # -- life cycle -----------------------------------------------------------
    def initialize(self, start_time: float = 0.0, start_values: dict | None = None,
                   in_initialization_mode: bool = False):
        """setupExperiment, the start values (before initialization mode, as
        fmpy's simulate_fmu sets them, or inside it), enter and exit."""
        self.fmu.setupExperiment(startTime=start_time)
        if start_values and not in_initialization_mode:
            self.set_values(start_values)
        self.fmu.enterInitializationMode()
        if start_values and in_initialization_mode:
            self.set_values(start_values)
        self.fmu.exitInitializationMode()
        self.time = start_time
        return self

    def do_step(self, step: float) -> int:
        """fmi2DoStep from the instance's own time; returns the status."""
        status = self.do_step_at(self.time, step)
        self.time = self.time + step
        return status

    def do_step_at(self, t: float, step: float) -> int:
        """fmi2DoStep from the communication point `t` a master keeps."""
        return self.fmu.fmi2DoStep(self.fmu.component, t, step, fmi2.fmi2True)

    def step_n(self, n: int, step: float = 1e-4, record: tuple[str, ...] = ()) -> list:
        rows = []
        for _ in range(n):
            self.do_step(step)
            if record:
                rows.append(self.get(*record))
        return rows

    def serialize_state(self) -> bytes:
        state = self.fmu.getFMUstate()
        try:
            return self.fmu.serializeFMUstate(state)
        finally:
            self.fmu.freeFMUstate(state)

    def restore_bytes(self, data: bytes):
        state = self.fmu.deSerializeFMUstate(data)
        try:
            self.fmu.setFMUstate(state)
        finally:
            self.fmu.freeFMUstate(state)

    def last_successful_time(self) -> float:
        return self.fmu.getRealStatus(fmi2.fmi2LastSuccessfulTime)

    def free(self, terminate: bool = False):
        """fmi2Terminate (when asked) and fmi2FreeInstance + dlclose of this
        handle; once."""
        if self.freed:
            return
        self.freed = True
        try:
            if terminate:
                self.fmu.terminate()
        finally:
            self.fmu.freeInstance()


class RealPort:
    """A fixed list of Real variables read or written together, with
    preallocated buffers (fmpy's convenience setters build new ctypes arrays
    on every call)."""

    def __init__(self, slave: fmi2.FMU2Slave, vrs: list[int]):
        self.slave = slave
        self.n = len(vrs)
        self.vrs = (fmi2.fmi2ValueReference * self.n)(*vrs)
        self.values = (fmi2.fmi2Real * self.n)()
        self.view = np.ctypeslib.as_array(self.values)

    def get(self) -> np.ndarray:
        self.slave.fmi2GetReal(self.slave.component, self.vrs, self.n, self.values)
        return self.view

    def set(self, values) -> None:
        self.view[:] = values
        self.slave.fmi2SetReal(self.slave.component, self.vrs, self.n, self.values)
