#!/usr/bin/env sh
# Make sure the system packages lidarkit needs are present; install the missing ones with apt when root:
#   libusb-1.0   loaded by Open3D (required)
#   chromium     the headless browser the report-page test opens (tests/test_report_browser.py)
set -eu
have_libusb() {
    ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' && return 0
    for d in /lib /usr/lib /lib64 /usr/lib64 /lib/x86_64-linux-gnu /usr/lib/x86_64-linux-gnu /lib/aarch64-linux-gnu /usr/lib/aarch64-linux-gnu; do
        [ -e "$d/libusb-1.0.so.0" ] && return 0
    done
    return 1
}
have_chromium() {
    [ -n "${LIDARKIT_CHROMIUM:-}" ] && [ -x "${LIDARKIT_CHROMIUM}" ] && return 0
    command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || command -v google-chrome >/dev/null 2>&1
}
missing=""
have_libusb || missing="libusb-1.0-0"
have_chromium || missing="$missing chromium"
[ -z "$missing" ] && exit 0
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "lidarkit setup: installing$(printf ' %s' $missing) with apt-get"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    # one package a call: apt installs nothing of a list with one name it does not know (Ubuntu has no "chromium"
    # package, and libusb stayed missing with it); the browser under its other name where "chromium" is unknown
    have_libusb || apt-get install -y -qq libusb-1.0-0 >/dev/null || true
    have_chromium || apt-get install -y -qq chromium >/dev/null 2>&1 || apt-get install -y -qq chromium-browser >/dev/null 2>&1 || true
fi
if ! have_chromium; then
    echo "lidarkit setup: chromium (headless browser for the report test) is missing; that test will fail." >&2
    echo "  Install it:  sudo apt-get install chromium   (or set LIDARKIT_CHROMIUM=/path/to/chrome)" >&2
fi
have_libusb && exit 0
echo "lidarkit setup: Open3D needs the system library libusb-1.0, which is missing." >&2
echo "  Install it, then re-run:  sudo apt-get install libusb-1.0-0   (Debian/Ubuntu)" >&2
echo "                            sudo dnf install libusb1             (Fedora/RHEL)" >&2
exit 1
