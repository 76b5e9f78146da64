#!/usr/bin/env sh
# Make sure the system library Open3D loads (libusb-1.0) is present; install it with apt when root.
set -eu
have_libusb() {
    ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' && return 0
    for d in /lib /usr/lib /lib64 /usr/lib64 /lib/x86_64-linux-gnu /usr/lib/x86_64-linux-gnu /lib/aarch64-linux-gnu /usr/lib/aarch64-linux-gnu; do
        [ -e "$d/libusb-1.0.so.0" ] && return 0
    done
    return 1
}
have_libusb && exit 0
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "lidarkit setup: installing libusb-1.0-0 (needed by Open3D) with apt-get"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    apt-get install -y -qq libusb-1.0-0 >/dev/null
    have_libusb && exit 0
fi
echo "lidarkit setup: Open3D needs the system library libusb-1.0, which is missing." >&2
echo "  Install it, then re-run:  sudo apt-get install libusb-1.0-0   (Debian/Ubuntu)" >&2
echo "                            sudo dnf install libusb1             (Fedora/RHEL)" >&2
exit 1
