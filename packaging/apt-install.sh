#!/usr/bin/env bash
# Installs Debian packages for the build and the tests, the one way every
# Makefile target and script does it:
#
#   packaging/apt-install.sh <why> <package>...
#
# - Waits up to 10 minutes for the dpkg lock (an unattended upgrade holding
#   it is common on a fresh machine) instead of failing at once.
# - Says which of the three things went wrong: not root (or no apt-get), the
#   lock still held after the wait, or apt-get itself failing; exit status 1
#   in every case, 0 when the packages are installed.
set -u

why="$1"
shift
if [ "$#" = 0 ]; then
    echo "usage: $0 <why> <package>..." >&2
    exit 2
fi
if ! command -v apt-get >/dev/null; then
    echo "cannot install $* ($why): no apt-get on this machine; install them by hand" >&2
    exit 1
fi
if [ "$(id -u)" != 0 ]; then
    echo "cannot install $* ($why): needs root; run: sudo apt-get install $*" >&2
    exit 1
fi

# APT_LOCK_TIMEOUT: seconds to wait for the lock (tests/test_apt_install.py
# shortens it).
LOCK_TIMEOUT="${APT_LOCK_TIMEOUT:-600}"
echo "installing $* ($why)"
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
deadline=$((SECONDS + LOCK_TIMEOUT))
locked() { grep -qiE "could not get lock|unable to acquire|lock-frontend|is another process using it" "$log"; }
# apt-get waits for dpkg's lock itself (DPkg::Lock::Timeout) but not, in
# every version, for the package lists' lock that `update` takes: retry
# while the only trouble is a lock and the wait has time left.
apt() {
    while true; do
        local left=$((deadline - SECONDS))
        [ "$left" -lt 0 ] && left=0
        if DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout="$left" "$@" \
            >"$log" 2>&1; then
            return 0
        fi
        if ! locked || [ "$SECONDS" -ge "$deadline" ]; then
            return 1
        fi
        sleep 1
    done
}
if apt update -qq && apt install -y -qq "$@"; then
    exit 0
fi
if locked; then
    echo "cannot install $* ($why): the dpkg lock is still held after ${LOCK_TIMEOUT} s" \
        "(another apt or an unattended upgrade is running); run the command again when it ends" >&2
else
    echo "cannot install $* ($why): apt-get failed:" >&2
    tail -n 5 "$log" >&2
fi
exit 1
