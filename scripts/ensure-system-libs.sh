#!/usr/bin/env bash
# Install the system packages flexreg needs: the libraries its wheels load at run time (open3d
# needs libusb-1.0) and Debian's chromium, the headless browser the picker and report tests drive
# through Playwright (pointed at the system executable: no browser download).
# As root it installs them with apt-get; otherwise it prints the exact command and fails.
set -euo pipefail
missing=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib 'libusb-1.0.so.0' || missing+=(libusb-1.0-0)
have_lib 'libgomp.so.1' || missing+=(libgomp1)
have_cmd() { command -v "$1" >/dev/null 2>&1; }
have_cmd chromium || have_cmd chromium-browser || missing+=(chromium)
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "flexreg needs the system packages: ${missing[*]} (no apt-get here: install them with your package manager)" >&2
    exit 1
fi
if [ "$(id -u)" -ne 0 ]; then
    echo "flexreg needs the system packages: ${missing[*]}. Run:" >&2
    echo "    sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
    exit 1
fi
echo "installing system packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
