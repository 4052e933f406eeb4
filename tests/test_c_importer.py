"""A C importer (tests/c_importer/importer.c) loads each FMU's binary from the
.fmu with dlopen and resolves every common and co-simulation function through
the official typedefs of fmi2FunctionTypes.h, compiled by gcc with warnings as
errors; it instantiates, initializes, steps, restores the FMU state from
memory and from serialized bytes (bit for bit), terminates and frees. Its
result must equal fmpy's for the same inputs.

The official headers are those fmi-sys ships (located with `cargo metadata`),
the same the Rust side is generated from."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from demo.cosim import Fmu
from tests.conftest import REPO_ROOT
from tests.platform_binaries import C_FLAGS, C_IMPORTER, C_IMPORTER_CASES, fmi_headers

SOURCE = C_IMPORTER / "importer.c"


@pytest.fixture(scope="module")
def importer(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.fail("gcc is needed to build the C importer", pytrace=False)
    out = tmp_path_factory.mktemp("c_importer") / "importer"
    subprocess.run(
        ["gcc", *C_FLAGS, f"-I{fmi_headers()}", str(SOURCE), "-o", str(out), "-ldl"],
        check=True, capture_output=True, text=True)
    return out


@pytest.mark.parametrize("model, input_name, value, output_name", C_IMPORTER_CASES)
def test_a_c_importer_runs_the_fmu_and_agrees_with_fmpy(importer, tmp_path, model, input_name,
                                                        value, output_name):
    fmu_path = REPO_ROOT / "dist" / f"{model}.fmu"
    if not fmu_path.is_file():
        pytest.fail(f"{fmu_path} is missing: run `make fmus` first", pytrace=False)
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extract(f"binaries/linux64/{model}.so", tmp_path)
    description = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in description.modelVariables}
    result = subprocess.run(
        [str(importer), str(tmp_path / "binaries" / "linux64" / f"{model}.so"),
         description.guid, str(vr[input_name]), repr(value), str(vr[output_name])],
        capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    from_c = float(result.stdout)

    with Fmu(fmu_path) as fmu:
        slave = fmu.instance("fmpy")
        try:
            slave.real_port((input_name,)).set([value])
            for k in range(100):
                slave.do_step(1e-4)
            from_fmpy = float(slave.real_port((output_name,)).get()[0])
        finally:
            slave.free()
    print(f"{model}: {output_name} after 100 steps: C importer {from_c!r}, fmpy {from_fmpy!r}")
    assert from_c == pytest.approx(from_fmpy, rel=1e-12, abs=1e-15)
