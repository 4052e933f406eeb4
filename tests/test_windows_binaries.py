"""The win64 binary in each .fmu, as Simulink users on Windows get it:

- it exports every FMI 2.0 common and co-simulation function (and the
  model-exchange ones where the FMU offers Model Exchange) under its
  standard, unprefixed name, and imports Windows' own DLLs only (no
  libgcc_s_seh-1.dll, libwinpthread-1.dll or other mingw runtime: Rust's
  standard library and libgcc's unwinder, which catches panics at the C
  boundary, are linked in);
- a C importer cross-compiled for Windows (tests/c_importer/importer.c, the
  one tests/test_c_importer.py runs on Linux) loads it with LoadLibrary under
  wine, steps it and restores its state bit for bit;
- a C master (tests/c_importer/closed_loop.c) runs PiezoController and
  FlexureStage in closed loop under wine, and the same source built for Linux
  runs the FMUs' linux64 binaries: the two trajectories agree.

Tools: x86_64-w64-mingw32-gcc and -objdump (`make fmus` installs them) and
wine (`make test` installs wine64), with a prefix in build/wine so that the
tests do not depend on the home folder. A missing tool fails the test."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from tests.conftest import REPO_ROOT
from tests.docs_figures import stale_prose
from tests.platform_binaries import (
    C_FLAGS,
    C_IMPORTER,
    C_IMPORTER_CASES,
    MODELS,
    compile_c,
    expected_functions,
    extract_binary,
    fmu_path,
    require_tool,
)

MINGW = "x86_64-w64-mingw32"
WINE_PREFIX = REPO_ROOT / "build" / "wine"

#: Exports beyond the FMI functions that the DLL may carry, and why.
#: callback_log is fmi-sys's importer-side logging trampoline, a #[no_mangle]
#: item of a dependency: rustc lists every such item in the .def file it hands
#: to the linker, and GNU ld for PE cannot drop one (on Linux the version
#: script hides it). It is harmless on Windows: a DLL's exports are looked up
#: per module (GetProcAddress), they do not enter a process-wide namespace
#: where they could capture another library's symbol as ELF's can.
TOLERATED_EXPORTS = {"callback_log"}

#: DLLs that come with every Windows 10/11 (the oldest Windows Rust's
#: standard library supports): the kernel, the C runtime, Rust std's random
#: source and what std::net/std::env use. Compared case-insensitively.
SYSTEM_DLLS = {"kernel32.dll", "ntdll.dll", "msvcrt.dll", "ucrtbase.dll",
               "bcryptprimitives.dll", "advapi32.dll", "ws2_32.dll", "userenv.dll"}
#: Windows' API-set names (api-ms-win-core-synch-l1-2-0.dll, ...), which the
#: loader maps to system DLLs.
API_SET = re.compile(r"^(api|ext)-ms-win-[a-z0-9-]+\.dll$")

#: Closed-loop run: 3000 steps of 0.1 ms (0.3 s, long enough for the PI loop
#: of about 10 Hz bandwidth to settle), references x = 2 um, y = 5 um from
#: t = 0, the plant's seeded sensor noise on so that its random number
#: generator runs too.
LOOP_STEPS = 3000
LOOP_STEP = 1e-4
LOOP_REFERENCES = {"x_ref": 2.0, "y_ref": 5.0}

#: Windows and Linux run the same machine code for the models' arithmetic
#: (IEEE 754 double, no x87, no fused multiply-add at the default x86-64
#: target), but exp, expm1, log1p and pow come from each platform's C
#: library (mingw-w64/msvcrt vs glibc), which may differ in the last bit or
#: two (a few 1e-16, relative). The loop is stable, so such differences stay
#: near that size instead of growing: the bound 1e-9 relative to the signal's
#: range leaves six orders of magnitude of headroom above it, and is still
#: six orders below anything physical (the sensors' own noise is 0.01 um
#: on a range of about 5 um, 2e-3) and below what any wiring, parameter or
#: step-count mistake changes (1e-3 and more).
RELATIVE_TOLERANCE = 1e-9


def windows_path(path: Path) -> str:
    """The path as a Windows program under wine sees it: drive Z: is the
    Unix root in every new prefix."""
    return "Z:" + str(path).replace("/", "\\")


def objdump(dll: Path) -> str:
    tool = require_tool(f"{MINGW}-objdump", "binutils-mingw-w64, to read the DLL's tables")
    return subprocess.run([tool, "-p", str(dll)], check=True, capture_output=True,
                          text=True).stdout


def dll_imports(dll: Path) -> list[str]:
    return re.findall(r"^\s*DLL Name: (\S+)", objdump(dll), re.M)


def dll_exports(dll: Path) -> set[str]:
    text = objdump(dll)
    start = text.find("[Ordinal/Name Pointer] Table")
    assert start >= 0, f"{dll}: objdump shows no export name table"
    names = set()
    for line in text[start:].splitlines()[1:]:
        match = re.match(r"^\s*\[\s*\d+\]\s+(\S+)$", line)
        if match is None:
            break
        names.add(match.group(1))
    return names


@pytest.fixture(params=MODELS)
def dll(request, tmp_path) -> tuple[str, Path]:
    return request.param, extract_binary(request.param, "win64", "dll", tmp_path)


def test_exports_every_fmi_function_unprefixed(dll):
    model, library = dll
    exports = dll_exports(library)
    expected = expected_functions(model)
    print(f"{model}.dll exports {len(exports & expected)} FMI functions"
          f"{', and ' + ', '.join(sorted(exports - expected)) if exports - expected else ''}")
    assert expected - exports == set(), f"{model}: missing {sorted(expected - exports)}"
    assert exports - expected <= TOLERATED_EXPORTS, (
        f"{model}: unexpected exports {sorted(exports - expected - TOLERATED_EXPORTS)}")
    # docs/platforms.md: "the same 44 and 34 FMI functions exported
    # unprefixed, and `callback_log`" (FlexureStage's, then PiezoController's).
    counts = [r"the same (\d+) and \d+ FMI functions", r"the same \d+ and (\d+) FMI functions"]
    problems = stale_prose("platforms.md", counts[MODELS.index(model)], str(len(exports & expected)),
                           f"{model}.dll's FMI exports", exact=True)
    problems += stale_prose("platforms.md", r"FMI functions exported unprefixed, and `([^`]*)`",
                            ", ".join(sorted(exports - expected)), f"{model}.dll's other exports",
                            exact=True)
    assert not problems, "\n".join(problems)


def test_imports_windows_system_dlls_only(dll):
    model, library = dll
    imports = dll_imports(library)
    print(f"{model}.dll imports: {', '.join(imports)}")
    assert any(i.lower() == "kernel32.dll" for i in imports), (
        f"{model}: objdump's import list was not understood: {imports}")
    foreign = [i for i in imports if i.lower() not in SYSTEM_DLLS and not API_SET.match(i.lower())]
    assert not foreign, f"{model}: imports DLLs that Windows does not ship: {foreign}"
    # docs/platforms.md lists them (the same for both FMUs), sorted by name
    # regardless of case, the lower-case spelling first.
    problems = stale_prose("platforms.md", r"imports `([^`]*)`",
                           ", ".join(sorted(imports, key=lambda i: (i.lower(), not i.islower()))),
                           f"{model}.dll's imports", exact=True)
    assert not problems, "\n".join(problems)


# --- running under wine -------------------------------------------------------


def wine_executable() -> str:
    """Debian's wine64 loader (not on PATH in Debian 12), else `wine`."""
    for candidate in (shutil.which("wine64"), "/usr/lib/wine/wine64", shutil.which("wine")):
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    pytest.fail("wine is missing (runs the win64 binaries): `make test` installs wine64 when "
                "run as root on Debian/Ubuntu", pytrace=False)


def wine_run(wine, *args: str, timeout: float = 300) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of a program under wine. Its output goes
    through files, not pipes: the services wine starts beside the program
    inherit its handles and outlive it while the server persists, so a pipe
    would not see its end."""
    executable, env = wine
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        status = subprocess.run([executable, *args], env=env, stdin=subprocess.DEVNULL,
                                stdout=out, stderr=err, timeout=timeout).returncode
        out.seek(0)
        err.seek(0)
        return status, out.read(), err.read()


@pytest.fixture(scope="module")
def wine():
    """The wine loader and its environment, with the prefix initialized and
    its wineserver kept running for the module (a start then takes about
    0.2 s instead of 3)."""
    executable = wine_executable()
    env = dict(os.environ, WINEPREFIX=str(WINE_PREFIX), WINEDEBUG="-all",
               # No Mono or Gecko: their installers would ask for the network.
               WINEDLLOVERRIDES="mscoree,mshtml=")
    env.pop("DISPLAY", None)  # console programs only; no window, no X server
    # wineserver needs the folder; wineboot fills a new one.
    WINE_PREFIX.mkdir(parents=True, exist_ok=True)
    server = Path(executable).with_name("wineserver")
    server = str(server) if server.is_file() else shutil.which("wineserver")
    if server:
        subprocess.run([server, "--persistent"], env=env, stdin=subprocess.DEVNULL,
                       stdout=subprocess.DEVNULL, check=True, timeout=60)
    try:
        started = time.perf_counter()
        # The first start of a new prefix creates it (15 s to a minute);
        # later starts find it ready.
        status, _, errors = wine_run((executable, env), "wineboot", "--init", timeout=600)
        assert status == 0, f"wineboot failed:\n{errors}"
        print(f"wine prefix {WINE_PREFIX} ready in {time.perf_counter() - started:.1f} s")
        yield executable, env
    finally:
        if server:
            # Ends this prefix's server (and anything left running in it) only.
            subprocess.run([server, "--kill"], env=env, timeout=60)


@pytest.fixture(scope="module")
def windows_programs(wine, tmp_path_factory) -> Path:
    """The C importer and master built for Windows, in one folder, with the
    bcryptprimitives.dll stand-in beside them when the wine prefix lacks it."""
    compiler = require_tool(f"{MINGW}-gcc", "mingw-w64, to build the Windows C importer")
    folder = tmp_path_factory.mktemp("windows")
    for program in ("importer", "closed_loop"):
        compile_c(compiler, C_IMPORTER / f"{program}.c", folder / f"{program}.exe")
    if not (WINE_PREFIX / "drive_c" / "windows" / "system32" / "bcryptprimitives.dll").exists():
        # The loader looks in the program's folder first, so the FMU's import
        # of bcryptprimitives.dll resolves to the stand-in (see its source).
        result = subprocess.run(
            [compiler, *C_FLAGS, "-shared",
             str(C_IMPORTER / "bcryptprimitives_for_wine.c"), "-o",
             str(folder / "bcryptprimitives.dll"), "-lbcrypt"],
            capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
        print("this wine has no bcryptprimitives.dll: the stand-in is beside the importer")
    return folder


@pytest.fixture(scope="module")
def linux_programs(tmp_path_factory) -> Path:
    compiler = require_tool("gcc", "to build the Linux C importer")
    folder = tmp_path_factory.mktemp("linux")
    for program in ("importer", "closed_loop"):
        compile_c(compiler, C_IMPORTER / f"{program}.c", folder / program, "-ldl")
    return folder


def run_under_wine(wine, program: Path, *args: str) -> str:
    status, output, errors = wine_run(wine, str(program), *args)
    assert status == 0, f"{program.name} under wine exited {status}:\n{errors}"
    return output


def run_native(program: Path, *args: str) -> str:
    result = subprocess.run([str(program), *args], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"{program.name} exited {result.returncode}:\n{result.stderr}"
    return result.stdout


@pytest.mark.parametrize("model, input_name, value, output_name", C_IMPORTER_CASES)
def test_a_c_importer_runs_the_dll_under_wine(wine, windows_programs, linux_programs, tmp_path,
                                              model, input_name, value, output_name):
    description = read_model_description(str(fmu_path(model)))
    vr = {v.name: v.valueReference for v in description.modelVariables}
    args = (description.guid, str(vr[input_name]), repr(value), str(vr[output_name]))
    dll = extract_binary(model, "win64", "dll", tmp_path)
    so = extract_binary(model, "linux64", "so", tmp_path)
    # The importer itself checks that the state restores bit for bit, in
    # memory and through the serialized bytes.
    on_windows = float(run_under_wine(wine, windows_programs / "importer.exe",
                                      windows_path(dll), *args))
    on_linux = float(run_native(linux_programs / "importer", str(so), *args))
    print(f"{model}: {output_name} after 100 steps: win64 under wine {on_windows!r}, "
          f"linux64 {on_linux!r}, difference {on_windows - on_linux:.3g}")
    # See RELATIVE_TOLERANCE: the same code, two C libraries' exp and pow.
    assert on_windows == pytest.approx(on_linux, rel=RELATIVE_TOLERANCE)
    # docs/platforms.md prints the value under wine and how it compares.
    problems = stale_prose("platforms.md", rf"{model} {output_name} = ([0-9.]+)", repr(on_windows),
                           f"{model}'s {output_name} under wine")
    problems += stale_prose(
        "platforms.md", r"under wine, (identical to the bit|differing by \S+) to linux64",
        "identical to the bit" if on_windows == on_linux else f"differing by {on_windows - on_linux:.2g}",
        f"{model}'s {output_name}, win64 against linux64", exact=True)
    assert not problems, "\n".join(problems)


def closed_loop_wiring(controller: Path, plant: Path, to_path) -> tuple[str, list[str]]:
    """The wiring file of closed_loop.c: controller (FMU 0) outputs to the
    plant (FMU 1) inputs of the same name and the plant's outputs to the
    controller's inputs of the same name, every name and value reference
    read from the FMUs' modelDescription.xml; and the connections' names in
    the order of closed_loop.c's output columns."""
    descriptions = [read_model_description(str(fmu_path(m)))
                    for m in ("PiezoController", "FlexureStage")]
    variables = [{v.name: v for v in d.modelVariables} for d in descriptions]

    def names(fmu: int, causality: str) -> set[str]:
        return {n for n, v in variables[fmu].items() if v.causality == causality}

    commands = names(0, "output") & names(1, "input")
    sensors = names(1, "output") & names(0, "input")
    # The wiring of demo/cosim.py: the three actuator commands and the three
    # laser sensors; anything else means a renamed port.
    assert len(commands) == 3 and len(sensors) == 3, (commands, sensors)
    lines = [f"library 0 {to_path(controller)}", f"guid 0 {descriptions[0].guid}",
             f"library 1 {to_path(plant)}", f"guid 1 {descriptions[1].guid}"]
    lines += [f"real 0 {variables[0][n].valueReference} {v!r}"
              for n, v in LOOP_REFERENCES.items()]
    lines.append(f"boolean 1 {variables[1]['noise.enabled'].valueReference} 1")
    lines += [f"connect 0 {variables[0][n].valueReference} 1 {variables[1][n].valueReference}"
              for n in sorted(commands)]
    lines += [f"connect 1 {variables[1][n].valueReference} 0 {variables[0][n].valueReference}"
              for n in sorted(sensors)]
    lines.append(f"run {LOOP_STEPS} {LOOP_STEP!r}")
    return "\n".join(lines) + "\n", sorted(commands) + sorted(sensors)


def test_the_closed_loop_under_wine_matches_linux(wine, windows_programs, linux_programs,
                                                  tmp_path):
    binaries = {}
    for platform, extension in (("win64", "dll"), ("linux64", "so")):
        binaries[platform] = [extract_binary(m, platform, extension, tmp_path)
                              for m in ("PiezoController", "FlexureStage")]
    windows_wiring, columns = closed_loop_wiring(*binaries["win64"], windows_path)
    linux_wiring, _ = closed_loop_wiring(*binaries["linux64"], str)
    (tmp_path / "windows.txt").write_text(windows_wiring)
    (tmp_path / "linux.txt").write_text(linux_wiring)

    started = time.perf_counter()
    on_windows = np.loadtxt(run_under_wine(wine, windows_programs / "closed_loop.exe",
                                           windows_path(tmp_path / "windows.txt")).splitlines())
    windows_seconds = time.perf_counter() - started
    on_linux = np.loadtxt(run_native(linux_programs / "closed_loop",
                                     str(tmp_path / "linux.txt")).splitlines())
    assert on_windows.shape == on_linux.shape == (LOOP_STEPS + 1, 1 + len(columns))
    assert np.array_equal(on_windows[:, 0], on_linux[:, 0]), "different communication points"

    # The loop did its job on both (so that the comparison is of a working
    # loop, not of two idle ones): y (sensor s1) within 2 % of its reference
    # at the end.
    s1 = 1 + columns.index("s1")
    print(f"y reference {LOOP_REFERENCES['y_ref']} um, s1 at the end: "
          f"linux64 {on_linux[-1, s1]:.4f} um")
    assert on_linux[-1, s1] == pytest.approx(LOOP_REFERENCES["y_ref"], rel=0.02)

    scale = np.ptp(on_linux[:, 1:], axis=0)
    difference = np.abs(on_windows[:, 1:] - on_linux[:, 1:]).max(axis=0)
    relative = difference / scale
    print(f"closed loop, {LOOP_STEPS} steps (wine run {windows_seconds:.1f} s): largest "
          f"|win64 - linux64| per signal, and relative to its range:")
    for name, d, r in zip(columns, difference, relative):
        print(f"  {name}: {d:.3g} ({r:.3g})")
    print(f"  identical samples: {np.mean(on_windows[:, 1:] == on_linux[:, 1:]):.1%}")
    assert relative.max() <= RELATIVE_TOLERANCE, dict(zip(columns, relative))
    # docs/platforms.md prints these figures: the largest relative
    # difference (in the text and in the importers' table), the signal it
    # is on, s1's in um, and the share of identical samples.
    worst = int(np.argmax(relative))
    s1_difference = difference[columns.index("s1")]
    identical = 100 * np.mean(on_windows[:, 1:] == on_linux[:, 1:])
    figure = "closed loop under wine against linux64"
    problems = stale_prose("platforms.md", r"relative to its range: \*\*([^*]+)\*\*",
                           f"{relative[worst]:.2g}", f"{figure}: largest relative difference")
    problems += stale_prose("platforms.md", r"C master: largest difference (\S+) of each signal's range",
                            f"{relative[worst]:.2g}", f"{figure}: largest relative difference (table)")
    problems += stale_prose("platforms.md", r"relative to its range: \*\*[^*]+\*\* \((\w+);",
                            columns[worst], f"{figure}: the signal of the largest difference", exact=True)
    problems += stale_prose("platforms.md", r"; s1 (\S+) µm\)", f"{s1_difference:.2g}",
                            f"{figure}: largest difference of s1")
    problems += stale_prose("platforms.md", r"(\d+) % of the samples identical to the bit",
                            f"{identical:.0f}", f"{figure}: identical samples")
    assert not problems, "\n".join(problems)
