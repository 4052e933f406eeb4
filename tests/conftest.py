"""Shared fixtures and helpers of the fmpy importer tests.

The FMU under test is dist/FlexureStage.fmu (built by `make fmus`). The helpers
(demo/fmu.py, the project's one fmpy wrapper) drive it through fmpy's
low-level FMU2Slave so that each test controls the exact FMI call sequence,
the fmi2Instantiate arguments and the logger callback.
"""

from __future__ import annotations

import math
import pathlib
import shutil
import sys
import tempfile

import fmpy
import pytest
from fmpy import fmi2
from fmpy.fmi1 import FMICallException

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
if str(REPO_ROOT) not in sys.path:  # test modules import conftest directly too
    sys.path.insert(0, str(REPO_ROOT))

from demo.fmu import STATUS_NAMES, Fmu, LogCapture, LogRecord  # noqa: E402
from demo.fmu import Instance as Slave  # noqa: E402

FMU_PATH = REPO_ROOT / "dist" / "FlexureStage.fmu"
MODEL_IDENTIFIER = "FlexureStage"

OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")
INPUTS = ("u1", "u2", "u3")


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


class FmuEnv:
    """The extracted FMU (demo.fmu.Fmu, the project's one fmpy wrapper) as an
    instance factory that frees every instance it made."""

    def __init__(self, fmu_path: pathlib.Path, unzip_dir: str):
        self.fmu = Fmu(fmu_path, unzipdir=unzip_dir)
        self.fmu_path = fmu_path
        self.unzip_dir = unzip_dir
        self.md = self.fmu.description
        self.guid = self.fmu.guid
        self.vrs = self.fmu.vrs
        self.types = self.fmu.types
        self.variables = self.fmu.variables
        self.resources_dir = pathlib.Path(unzip_dir, "resources")
        self._live: list[Slave] = []

    def load(self, instance_name: str = "probe") -> tuple[fmi2.FMU2Slave, LogCapture]:
        return self.fmu.load(instance_name), LogCapture()

    def instantiate(
        self,
        instance_name: str = "probe",
        logging_on: bool = False,
        resource_location: object = ...,
    ) -> Slave:
        """A new instance. resource_location: ... = fmpy's own URI of the
        resources folder, None = NULL, str = that exact string."""
        slave = self.fmu.instantiate(instance_name, logging_on, resource_location)
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
    "STATUS_NAMES",
    "LogRecord",
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
