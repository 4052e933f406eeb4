"""Shared fixtures and helpers of the fmpy importer tests.

The FMU under test is dist/FlexureStage.fmu (built by `make fmus`). The helpers
drive it through fmpy's low-level FMU2Slave so that each test controls the exact
FMI call sequence, the fmi2Instantiate arguments and the logger callback.
"""

from __future__ import annotations

import math
import pathlib
import shutil
import tempfile
from ctypes import byref
from dataclasses import dataclass, field

import fmpy
import pytest
from fmpy import fmi2
from fmpy.fmi1 import FMICallException

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
FMU_PATH = REPO_ROOT / "dist" / "FlexureStage.fmu"
MODEL_IDENTIFIER = "FlexureStage"

OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")
INPUTS = ("u1", "u2", "u3")

STATUS_NAMES = {
    fmi2.fmi2OK: "fmi2OK",
    fmi2.fmi2Warning: "fmi2Warning",
    fmi2.fmi2Discard: "fmi2Discard",
    fmi2.fmi2Error: "fmi2Error",
    fmi2.fmi2Fatal: "fmi2Fatal",
}


def require_fmu() -> pathlib.Path:
    """The FMU's path; fails (never skips) when it was not built."""
    if not FMU_PATH.is_file():
        pytest.fail(
            f"{FMU_PATH} is missing: run `make fmus` in {REPO_ROOT} first",
            pytrace=False,
        )
    return FMU_PATH


def require_closed_loop_build() -> None:
    """Fails (never skips) unless both FMUs and the compiled master
    (`demo.master.binary()`, from `make master`) are built."""
    from demo import master

    for path in (REPO_ROOT / "dist" / "FlexureStage.fmu", REPO_ROOT / "dist" / "PiezoController.fmu"):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    try:
        master.binary()
    except FileNotFoundError as e:
        pytest.fail(str(e), pytrace=False)


@dataclass
class LogRecord:
    instance_name: str
    status: int
    category: str
    raw: str  # the message as the FMU passed it (a printf format: '%' doubled)

    @property
    def text(self) -> str:
        """The message as a printf-style importer shows it ('%%' -> '%')."""
        return self.raw.replace("%%", "%")

    def __str__(self) -> str:
        return (
            f"[{STATUS_NAMES.get(self.status, self.status)}|{self.category}|"
            f"{self.instance_name}] {self.raw}"
        )


@dataclass
class LogCapture:
    """A fmi2CallbackFunctions whose logger records every message.

    The callbacks object must stay alive as long as the instance, which the
    Slave wrapper ensures by holding it.
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

        self.records.append(
            LogRecord(dec(instance_name), status, dec(category), dec(message))
        )

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


class Slave:
    """One FMU instance (its own FMU2Slave, library handle and logger)."""

    def __init__(self, env: "FmuEnv", fmu: fmi2.FMU2Slave, log: LogCapture):
        self.env = env
        self.fmu = fmu
        self.log = log
        self.time = 0.0
        self.freed = False

    # -- value access by name -------------------------------------------------
    def vr(self, *names: str) -> list[int]:
        return [self.env.vrs[n] for n in names]

    def get(self, *names: str) -> list[float]:
        return self.fmu.getReal(self.vr(*names))

    def get1(self, name: str) -> float:
        return self.get(name)[0]

    def set_real(self, values: dict[str, float]) -> int:
        """fmi2SetReal on the given values; returns the status (raises above warning)."""
        names = list(values)
        vrs = (fmi2.fmi2ValueReference * len(names))(*self.vr(*names))
        vals = (fmi2.fmi2Real * len(names))(*(values[n] for n in names))
        return self.fmu.fmi2SetReal(self.fmu.component, vrs, len(names), vals)

    def set_integer(self, values: dict[str, int]) -> int:
        names = list(values)
        vrs = (fmi2.fmi2ValueReference * len(names))(*self.vr(*names))
        vals = (fmi2.fmi2Integer * len(names))(*(values[n] for n in names))
        return self.fmu.fmi2SetInteger(self.fmu.component, vrs, len(names), vals)

    def set_boolean(self, values: dict[str, bool]) -> int:
        names = list(values)
        vrs = (fmi2.fmi2ValueReference * len(names))(*self.vr(*names))
        vals = (fmi2.fmi2Boolean * len(names))(*(int(bool(values[n])) for n in names))
        return self.fmu.fmi2SetBoolean(self.fmu.component, vrs, len(names), vals)

    def set_start_values(self, values: dict):
        """Sets values by their declared type (Real, Integer or Boolean)."""
        for name, value in values.items():
            kind = self.env.types[name]
            if kind == "Real":
                self.set_real({name: value})
            elif kind == "Integer":
                self.set_integer({name: value})
            elif kind == "Boolean":
                self.set_boolean({name: value})
            else:
                raise AssertionError(f"{name}: unsupported type {kind}")

    # -- life cycle ---------------------------------------------------------
    def initialize(self, start_time: float = 0.0, start_values: dict | None = None):
        self.fmu.setupExperiment(startTime=start_time)
        if start_values:
            self.set_start_values(start_values)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.time = start_time
        return self

    def do_step(self, step: float) -> int:
        """fmi2DoStep from the slave's own time; returns the status."""
        status = self.fmu.fmi2DoStep(self.fmu.component, self.time, step, fmi2.fmi2True)
        self.time = self.time + step
        return status

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

    def free(self):
        if not self.freed:
            self.freed = True
            self.fmu.freeInstance()  # fmi2FreeInstance + dlclose of this handle


class FmuEnv:
    """The extracted FMU, its model description and an instance factory."""

    def __init__(self, fmu_path: pathlib.Path, unzip_dir: str):
        self.fmu_path = fmu_path
        self.unzip_dir = unzip_dir
        self.md = fmpy.read_model_description(str(fmu_path))
        self.guid = self.md.guid
        self.vrs = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.resources_dir = pathlib.Path(unzip_dir, "resources")
        self._live: list[Slave] = []

    def load(self, instance_name: str = "probe") -> tuple[fmi2.FMU2Slave, LogCapture]:
        fmu = fmi2.FMU2Slave(
            guid=self.guid,
            unzipDirectory=self.unzip_dir,
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )
        return fmu, LogCapture()

    def instantiate(
        self,
        instance_name: str = "probe",
        logging_on: bool = False,
        resource_location: object = ...,
    ) -> Slave:
        """A new instance. resource_location: ... = fmpy's own URI of the
        resources folder, None = NULL, str = that exact string."""
        fmu, log = self.load(instance_name)
        if resource_location is ...:
            fmu.instantiate(callbacks=log.callbacks, loggingOn=logging_on)
        else:
            fmu.callbacks = log.callbacks
            location = None if resource_location is None else resource_location.encode("utf-8")
            fmu.component = fmu.fmi2Instantiate(
                instance_name.encode("utf-8"),
                fmi2.fmi2CoSimulation,
                self.guid.encode("utf-8"),
                location,
                byref(log.callbacks),
                fmi2.fmi2False,
                fmi2.fmi2True if logging_on else fmi2.fmi2False,
            )
            if not fmu.component:
                fmu.freeLibrary()
                raise AssertionError(
                    f"fmi2Instantiate returned NULL for fmuResourceLocation={resource_location!r}; "
                    f"log:\n{log.dump()}"
                )
        slave = Slave(self, fmu, log)
        self._live.append(slave)
        return slave

    def free_all(self):
        for slave in self._live:
            try:
                slave.free()
            except Exception:  # pragma: no cover - cleanup must not mask a failure
                pass
        self._live.clear()


@pytest.fixture(scope="session")
def fmu_path() -> pathlib.Path:
    return require_fmu()


@pytest.fixture(scope="session")
def unzip_dir(fmu_path):
    directory = fmpy.extract(str(fmu_path), unzipdir=tempfile.mkdtemp(prefix="flexure_fmu_"))
    yield directory
    shutil.rmtree(directory, ignore_errors=True)


@pytest.fixture
def env(fmu_path, unzip_dir):
    """Instance factory; every instance it made is freed after the test."""
    e = FmuEnv(fmu_path, unzip_dir)
    yield e
    e.free_all()


def hexes(values) -> list[str]:
    """Floats as exact hex strings (bit-for-bit comparison)."""
    return [float(v).hex() for v in values]


def all_finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


def expect_error(call, *args, **kwargs) -> FMICallException:
    """Runs call and asserts it raised FMICallException with fmi2Error."""
    with pytest.raises(FMICallException) as info:
        call(*args, **kwargs)
    assert info.value.status == fmi2.fmi2Error, (
        f"{info.value.function} returned {STATUS_NAMES.get(info.value.status)}, expected fmi2Error"
    )
    return info.value


__all__ = [
    "FMU_PATH",
    "REPO_ROOT",
    "INPUTS",
    "OUTPUTS",
    "FmuEnv",
    "LogCapture",
    "Slave",
    "all_finite",
    "expect_error",
    "hexes",
    "require_fmu",
]
