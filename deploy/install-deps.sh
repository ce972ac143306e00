#!/bin/sh
# install-deps.sh — installs the Debian 12 packages fxstream needs, and only those missing.
#
# Idempotent and quick when everything is present (no apt-get update then). Runs apt-get
# as root, or through sudo when available. With --check (or FXS_NO_INSTALL=1) it only names
# what is missing and exits 1 if anything is. redis-server is for the cluster tests, which start
# their own on a free loopback port (the package's system service is not used). With
# --screenshots it also installs what make screenshots needs beyond the tests: the Godot 3
# editor build, a virtual X server and Mesa's software OpenGL (tools/screenshot_godot.sh).
set -eu

PKGS="build-essential pkg-config ocl-icd-opencl-dev opencl-headers pocl-opencl-icd clinfo gnuplot-nox
libwebsockets-dev libopenexr-dev openexr libcjson-dev libzstd-dev zstd draco nodejs python3 python3-websockets python3-numpy python3-jsonschema python3-prometheus-client
chromium clang lld wasi-libc libclang-rt-14-dev-wasm32 valgrind openssl nginx systemd strace python3-kubernetes
libhiredis-dev redis-server godot3-server"

check=0
for arg in "$@"; do
    case $arg in
    --check) check=1 ;;
    --screenshots) PKGS="$PKGS godot3 xvfb xauth libgl1-mesa-dri" ;;
    *) echo "usage: install-deps.sh [--check] [--screenshots]" >&2; exit 2 ;;
    esac
done

missing=""
for p in $PKGS; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed"; then
        missing="$missing $p"
    fi
done
[ -z "$missing" ] && exit 0

if [ "$check" = 1 ] || [ "${FXS_NO_INSTALL:-0}" = 1 ]; then
    echo "install-deps: missing packages:$missing (make deps, or make run / make test, installs them)" >&2
    exit 1
fi
echo "install-deps: installing:$missing"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO=sudo; else
        echo "install-deps: need root (or sudo) to install:$missing" >&2
        exit 1
    fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
# shellcheck disable=SC2086
$SUDO apt-get install -y -q --no-install-recommends $missing
