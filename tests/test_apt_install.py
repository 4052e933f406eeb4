"""packaging/apt-install.sh, the one way the Makefile and the scripts install
Debian packages: it waits for the dpkg lock and, when the wait runs out, says
that the lock is held (not "needs root"), and it says "needs root" only when
that is the reason."""

from __future__ import annotations

import fcntl
import os
import pathlib
import shutil
import subprocess
import time

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parent.parent / "packaging" / "apt-install.sh"
#: The locks apt-get takes: the lists' for `update`, dpkg's for `install`.
LOCKS = ["/var/lib/apt/lists/lock", "/var/lib/dpkg/lock-frontend", "/var/lib/dpkg/lock"]


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=300,
        env={**os.environ, **(env or {})},
    )


def test_without_packages_it_says_how_to_call_it():
    result = run("a reason")
    assert result.returncode == 2
    assert "usage:" in result.stderr


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("apt-get") is None,
                    reason="holding apt's locks needs root and apt-get")
def test_a_held_lock_is_reported_as_held():
    held = []
    try:
        for path in LOCKS:
            if not os.path.exists(path):
                continue
            handle = open(path, "w")
            try:
                fcntl.lockf(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                pytest.skip(f"{path} is held by another apt process right now")
            held.append(handle)
        assert held, "none of apt's locks exists on this machine"
        started = time.monotonic()
        result = run("a test", "valgrind", env={"APT_LOCK_TIMEOUT": "3"})
        elapsed = time.monotonic() - started
    finally:
        for handle in held:
            handle.close()
    assert result.returncode == 1, result.stdout + result.stderr
    # bash counts its SECONDS in whole seconds from its start: a 3 s wait
    # lasts between 2 and 3 s.
    assert elapsed >= 2.0, f"gave up after {elapsed:.2f} s instead of waiting"
    assert "lock is still held after 3 s" in result.stderr, result.stderr
    assert "needs root" not in result.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="the not-root message needs a non-root user")
def test_not_root_says_so():
    result = run("a test", "valgrind")
    assert result.returncode == 1
    assert "needs root" in result.stderr
