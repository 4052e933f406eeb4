"""Helpers of the tests that inspect and run the FMUs' platform binaries
(tests/test_c_importer.py, tests/test_linux_binaries.py,
tests/test_windows_binaries.py): the official FMI 2.0 headers, the list of
functions a co-simulation FMU exports, a binary out of its .fmu, and the
tools, which fail the test (never skip it) when they are missing."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import zipfile
from functools import cache
from pathlib import Path

import pytest
from fmpy import read_model_description

from tests.conftest import REPO_ROOT

DIST = REPO_ROOT / "dist"
MODELS = ("FlexureStage", "PiezoController")
C_IMPORTER = REPO_ROOT / "tests" / "c_importer"
#: importer.c's runs: the input set, its value, the output read after 100
#: steps of 1e-4 s.
C_IMPORTER_CASES = [("FlexureStage", "u1", 5.0, "s1"), ("PiezoController", "y_ref", 6.0, "u1")]
#: The flags every C importer is built with, on every platform.
C_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")


@cache
def fmi_headers() -> Path:
    """The official FMI 2.0 headers that fmi-sys ships (the ones the Rust
    side is generated from), located with `cargo metadata`."""
    metadata = json.loads(subprocess.run(
        [os.environ.get("CARGO", "cargo"), "metadata", "--format-version", "1", "--locked"],
        cwd=REPO_ROOT, check=True, capture_output=True, text=True).stdout)
    package = next(p for p in metadata["packages"] if p["name"] == "fmi-sys")
    headers = Path(package["manifest_path"]).parent / "fmi-standard2" / "headers"
    assert (headers / "fmi2FunctionTypes.h").is_file(), headers
    return headers


@cache
def cosimulation_functions() -> frozenset[str]:
    """Every function of the common and co-simulation API, read from the
    official fmi2Functions.h (its `#define fmi2X fmi2FullName(fmi2X)` lines),
    without the model-exchange section, which a co-simulation-only FMU need
    not export."""
    text = (fmi_headers() / "fmi2Functions.h").read_text()
    # The first #define block: common functions, then model exchange, then
    # co-simulation; the sections are headed by these comments.
    exchange = text.index("Functions for FMI2 for Model Exchange")
    cosimulation = text.index("Functions for FMI2 for Co-Simulation")
    names = set()
    for match in re.finditer(r"^#define\s+(fmi2\w+)\s+fmi2FullName\(\1\)", text, re.M):
        if not exchange < match.start() < cosimulation:
            names.add(match.group(1))
    # 25 common + 9 co-simulation functions in FMI 2.0.x.
    assert len(names) == 34, sorted(names)
    return frozenset(names)


@cache
def model_exchange_functions() -> frozenset[str]:
    """The model-exchange section of the official fmi2Functions.h (10
    functions in FMI 2.0.x)."""
    text = (fmi_headers() / "fmi2Functions.h").read_text()
    exchange = text.index("Functions for FMI2 for Model Exchange")
    cosimulation = text.index("Functions for FMI2 for Co-Simulation")
    names = {
        match.group(1)
        for match in re.finditer(r"^#define\s+(fmi2\w+)\s+fmi2FullName\(\1\)", text, re.M)
        if exchange < match.start() < cosimulation
    }
    assert len(names) == 10, sorted(names)
    return frozenset(names)


def expected_functions(model: str) -> frozenset[str]:
    """What the model's binary exports: the common and co-simulation
    functions, and the model-exchange ones when its modelDescription offers
    Model Exchange (FlexureStage does, PiezoController does not)."""
    if read_model_description(str(fmu_path(model))).modelExchange is not None:
        return cosimulation_functions() | model_exchange_functions()
    return cosimulation_functions()


def require_tool(name: str, why: str) -> str:
    """The tool's path; fails the test with how to get it when it is missing."""
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} is missing ({why}): `make fmus` / `make test` install it when "
                    f"run as root on Debian/Ubuntu", pytrace=False)
    return path


def fmu_path(model: str) -> Path:
    path = DIST / f"{model}.fmu"
    if not path.is_file():
        pytest.fail(f"{path} is missing: run `make fmus` first", pytrace=False)
    return path


def extract_binary(model: str, platform: str, extension: str, into: Path) -> Path:
    """binaries/<platform>/<modelIdentifier>.<extension> of dist/<model>.fmu,
    extracted below `into`; fails the test when the FMU has none."""
    path = fmu_path(model)
    identifier = read_model_description(str(path)).coSimulation.modelIdentifier
    member = f"binaries/{platform}/{identifier}.{extension}"
    with zipfile.ZipFile(path) as archive:
        if member not in archive.namelist():
            pytest.fail(f"{path} has no {member}: `make fmus` printed why it could not build "
                        f"the {platform} binary", pytrace=False)
        archive.extract(member, into)
    return into / member


def compile_c(compiler: str, source: Path, out: Path, *libraries: str) -> Path:
    """Builds one C importer against the official headers with C_FLAGS; a
    warning fails the test with the compiler's message."""
    result = subprocess.run(
        [compiler, *C_FLAGS, f"-I{fmi_headers()}", str(source), "-o", str(out), *libraries],
        capture_output=True, text=True)
    if result.returncode != 0:
        pytest.fail(f"{compiler} could not build {source.name}:\n{result.stderr}", pytrace=False)
    return out
