#!/usr/bin/env bash
# Builds the FMUs' platform binaries into <out>/<platform>/ (called by
# `make fmus`, which packs every binary it finds there):
#
#   linux64  lib<crate>.so against glibc 2.17, with zig as the linker
#            (cargo-zigbuild, pinned in packaging/cross-tools.txt and installed
#            into build/tools/cross); Rust's standard library and zig's
#            unwinder are linked in, so it needs glibc's own libraries only.
#   win64    <crate>.dll for x86_64-pc-windows-gnu with Debian's mingw-w64;
#            it imports Windows' own DLLs only (libgcc's unwinder is static).
#
# It installs what is missing: the tools above, the Rust target (rustup), and
# gcc-mingw-w64-x86-64 with apt-get when run as root. When a toolchain cannot
# be had it says so loudly, leaves that platform out (linux64 falls back to
# the host build, which needs a newer glibc) and goes on; the platform's test
# then fails. A build that fails with its toolchain present is an error.
#
# usage: packaging/platform-binaries.sh <out dir> <cargo package>...

set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=$1
shift
PACKAGES=("$@")
CARGO=${CARGO:-cargo}
PYTHON3=${PYTHON3:-python3}
TOOLS=$ROOT/build/tools
CROSS=$TOOLS/cross
REQUIREMENTS=$ROOT/packaging/cross-tools.txt
LINUX_TARGET=x86_64-unknown-linux-gnu
GLIBC=2.17
WINDOWS_TARGET=x86_64-pc-windows-gnu
MINGW_CC=${MINGW_CC:-x86_64-w64-mingw32-gcc}
WARNINGS=$OUT/WARNINGS

rm -rf "$OUT"
mkdir -p "$OUT"

# A banner that stands out in the build log; kept in $WARNINGS so that
# `make fmus` repeats it after the packing.
loud() {
    local platform=$1
    shift
    {
        echo "########################################################################"
        echo "## make fmus: $platform"
        for line in "$@"; do echo "##   $line"; done
        echo "########################################################################"
    } | tee -a "$WARNINGS" >&2
}

cargo_package_flags() {
    local p
    for p in "${PACKAGES[@]}"; do printf -- '-p\n%s\n' "$p"; done
}
mapfile -t PACKAGE_FLAGS < <(cargo_package_flags)

# --- linux64: glibc 2.17 ------------------------------------------------------

# The pinned wheels, installed again only when cross-tools.txt changed.
install_zig() {
    if cmp -s "$REQUIREMENTS" "$CROSS/.installed" && [ -x "$CROSS/bin/cargo-zigbuild" ]; then
        return 0
    fi
    echo "installing zig and cargo-zigbuild into $CROSS (packaging/cross-tools.txt)"
    rm -rf "$CROSS"
    "$PYTHON3" -m venv "$CROSS" &&
        "$CROSS/bin/python" -m pip install --quiet --disable-pip-version-check \
            --only-binary :all: -r "$REQUIREMENTS" &&
        cp "$REQUIREMENTS" "$CROSS/.installed"
}

build_linux() {
    local crate
    if ! install_zig; then
        loud "linux64 binaries are the HOST build (need glibc > $GLIBC)" \
            "could not install zig/cargo-zigbuild from PyPI into $CROSS" \
            "(see the pip error above); tests/test_linux_binaries.py will fail"
        for crate in "${PACKAGES[@]//-/_}"; do
            cp "$ROOT/target/release/lib$crate.so" "$OUT/linux64/"
        done
        return 0
    fi
    # zig reports its own paths relative to the working directory when they
    # lie below it, and cargo-zigbuild hands those to build scripts (bindgen)
    # that run elsewhere: run it from a workspace member, which build/tools is
    # not below. The caches stay in build/tools, not in the home folder.
    (
        cd "$ROOT/packaging"
        CARGO_ZIGBUILD_PYTHON_PATH=$CROSS/bin/python \
            CARGO_ZIGBUILD_CACHE_DIR=$TOOLS/cargo-zigbuild-cache \
            ZIG_GLOBAL_CACHE_DIR=$TOOLS/zig-cache \
            "$CROSS/bin/cargo-zigbuild" zigbuild --release --locked "${PACKAGE_FLAGS[@]}" \
            --target "$LINUX_TARGET.$GLIBC"
    )
    for crate in "${PACKAGES[@]//-/_}"; do
        cp "$ROOT/target/$LINUX_TARGET/release/lib$crate.so" "$OUT/linux64/"
    done
}

# --- win64 --------------------------------------------------------------------

have_windows_std() {
    [ -d "$(rustc --print sysroot)/lib/rustlib/$WINDOWS_TARGET/lib" ]
}

build_windows() {
    local crate include
    if ! have_windows_std; then
        if command -v rustup >/dev/null; then
            echo "adding the Rust target $WINDOWS_TARGET (rustup)"
            rustup target add "$WINDOWS_TARGET" || true
        fi
        if ! have_windows_std; then
            loud "NO win64 BINARIES in the FMUs" \
                "Rust's standard library for $WINDOWS_TARGET is missing and rustup could not add it" \
                "(rustup target add $WINDOWS_TARGET); tests/test_windows_binaries.py will fail"
            return 0
        fi
    fi
    if ! command -v "$MINGW_CC" >/dev/null; then
        "$ROOT/packaging/apt-install.sh" "the win64 linker" gcc-mingw-w64-x86-64 || true
        if ! command -v "$MINGW_CC" >/dev/null; then
            loud "NO win64 BINARIES in the FMUs" \
                "$MINGW_CC is missing and could not be installed (the reason is above)" \
                "install it: apt-get install gcc-mingw-w64-x86-64" \
                "tests/test_windows_binaries.py will fail"
            return 0
        fi
    fi
    # libclang (bindgen, in fmi-sys) finds mingw-w64's headers but not the
    # compiler's own (stddef.h, mm_malloc.h): give it mingw-w64 gcc's.
    include=$("$MINGW_CC" -print-file-name=include)
    BINDGEN_EXTRA_CLANG_ARGS_x86_64_pc_windows_gnu="${BINDGEN_EXTRA_CLANG_ARGS_x86_64_pc_windows_gnu:-} -isystem $include" \
        "$CARGO" build --release --locked "${PACKAGE_FLAGS[@]}" --target "$WINDOWS_TARGET"
    mkdir -p "$OUT/win64"
    for crate in "${PACKAGES[@]//-/_}"; do
        cp "$ROOT/target/$WINDOWS_TARGET/release/$crate.dll" "$OUT/win64/"
    done
}

mkdir -p "$OUT/linux64"
build_linux
build_windows
