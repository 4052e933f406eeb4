"""The linux64 binary in each .fmu loads on older distributions: it asks for
no glibc symbol version above 2.17 (CentOS/RHEL 7, Ubuntu 14.04 and later),
depends on no shared library outside glibc's own (Rust's standard library,
the unwinder included, is linked in), and exports the FMI 2.0 functions and
nothing else. `make fmus` builds it with zig as the linker (cargo-zigbuild,
target x86_64-unknown-linux-gnu.2.17); the fmpy and C importer tests run the
same binary.

Inspected with readelf (binutils, which gcc brings)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from tests.docs_figures import stale_prose
from tests.platform_binaries import MODELS, expected_functions, extract_binary, require_tool

#: The oldest glibc the binaries must load with (released 2012; RHEL 7).
GLIBC_BASELINE = (2, 17)
#: glibc's own libraries: present on every glibc system in a compatible
#: version, so a binary may depend on them and still be "static apart from
#: libc". libgcc_s and libstdc++ are not in the list: they are GCC's, and
#: their absence or age is what breaks binaries on other distributions.
GLIBC_LIBRARIES = {
    "libc.so.6", "libm.so.6", "libdl.so.2", "libpthread.so.0", "librt.so.1",
    "ld-linux-x86-64.so.2",
}


def readelf(*args: str) -> str:
    tool = require_tool("readelf", "binutils, to inspect the linux64 binaries")
    return subprocess.run([tool, "--wide", *args], check=True, capture_output=True,
                          text=True).stdout


def glibc_versions_needed(library: Path) -> set[tuple[int, ...]]:
    """The GLIBC_x.y[.z] versions of the .so's version-needs section (one per
    version any of its imported symbols is bound to)."""
    text = readelf("--version-info", str(library))
    needs = text[text.index("Version needs section"):] if "Version needs section" in text else ""
    return {tuple(int(part) for part in v.split("."))
            for v in re.findall(r"Name: GLIBC_([0-9.]+)", needs)}


def needed_libraries(library: Path) -> list[str]:
    return re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]",
                      readelf("--dynamic", str(library)))


def dynamic_symbols(library: Path) -> tuple[set[str], set[str]]:
    """(defined global symbols, undefined symbols) of the dynamic symbol table."""
    defined, undefined = set(), set()
    for line in readelf("--dyn-syms", str(library)).splitlines():
        # Num: Value Size Type Bind Vis Ndx Name[@version]
        fields = line.split()
        if len(fields) < 8 or not fields[0].endswith(":") or not fields[0][:-1].isdigit():
            continue
        name = fields[7].split("@")[0]
        if fields[6] == "UND":
            undefined.add(name)
        elif fields[4] in ("GLOBAL", "WEAK"):
            defined.add(name)
    return defined, undefined


@pytest.fixture(params=MODELS)
def linux_binary(request, tmp_path) -> tuple[str, Path]:
    return request.param, extract_binary(request.param, "linux64", "so", tmp_path)


def test_needs_no_glibc_newer_than_the_baseline(linux_binary):
    model, library = linux_binary
    versions = glibc_versions_needed(library)
    # No version at all means readelf's output was not understood, not "none":
    # any binary calling into libc binds at least GLIBC_2.2.5 on x86-64.
    assert versions, f"{model}: no GLIBC_ version needs found in {library}"
    highest = max(versions)
    print(f"{model}.so: highest glibc symbol version needed "
          f"GLIBC_{'.'.join(map(str, highest))}")
    assert highest <= GLIBC_BASELINE, (
        f"{model}: needs GLIBC_{'.'.join(map(str, highest))}, above the "
        f"{'.'.join(map(str, GLIBC_BASELINE))} baseline: is the FMU's binary the host build "
        f"instead of the zig one (see `make fmus` output)?")


def test_depends_on_glibc_libraries_only(linux_binary):
    model, library = linux_binary
    needed = needed_libraries(library)
    print(f"{model}.so NEEDED: {', '.join(needed)}")
    assert needed, f"{model}: readelf lists no NEEDED entry"
    # docs/platforms.md prints the list (the same for both FMUs).
    problems = stale_prose("platforms.md", r"NEEDED: `([^`]*)`", ", ".join(needed),
                           f"{model}.so's NEEDED libraries", exact=True)
    assert not problems, "\n".join(problems)
    assert set(needed) <= GLIBC_LIBRARIES, (
        f"{model}: depends on {sorted(set(needed) - GLIBC_LIBRARIES)}, which is not part of "
        f"glibc")
    _, undefined = dynamic_symbols(library)
    # The unwinder that catches panics at the C boundary must be inside the
    # binary: an undefined _Unwind_* would be resolved from whatever libgcc_s
    # the importer's process happens to hold.
    unwinder = sorted(s for s in undefined if s.startswith("_Unwind_"))
    assert not unwinder, f"{model}: the unwinder is not linked in: {unwinder}"


def test_exports_the_fmi_functions_and_nothing_else(linux_binary):
    model, library = linux_binary
    defined, _ = dynamic_symbols(library)
    expected = expected_functions(model)
    assert expected - defined == set(), f"{model}: missing {sorted(expected - defined)}"
    assert defined - expected == set(), f"{model}: also exports {sorted(defined - expected)}"
    problems = stale_prose("platforms.md", rf"the exports are exactly the FMI functions: .*?\b(\d+) of {model}",
                           str(len(defined)), f"{model}.so's exports", exact=True)
    assert not problems, "\n".join(problems)


def test_docs_platforms_prints_the_highest_glibc_version(tmp_path):
    """docs/platforms.md prints the highest glibc symbol version either
    linux64 binary needs: a build that needs another fails here until the
    document says so."""
    highest = max(max(glibc_versions_needed(extract_binary(model, "linux64", "so", tmp_path)))
                  for model in MODELS)
    problems = stale_prose("platforms.md",
                           r"the highest glibc symbol version either `\.so` needs is \*\*GLIBC_([0-9.]+)\*\*",
                           ".".join(map(str, highest)), "highest glibc version of the linux64 binaries",
                           exact=True)
    assert not problems, "\n".join(problems)
