#!/usr/bin/env bash
# The benchmarks' peers (mi_displace/bench/peers/), installed on request, never by the
# library: Mesa's EGL for headless OpenGL (llvmpipe) and VTK's off-screen window, through
# apt-get (Debian/Ubuntu, as root or with sudo), and the `peers` extra of mi-displace
# (moderngl, vtk) into .venv.  Run scripts/setup.sh first.  Blender (bpy) is separate: it
# needs its own Python 3.11 (docs/bake.md).  Re-running is cheap.
set -euo pipefail
cd "$(dirname "$0")/.."

SYSTEM_PACKAGES="libegl1 libgl1-mesa-dri libegl-mesa0"
SUDO=$([ "$(id -u)" = 0 ] || echo "sudo -n")   # root, or sudo without a password prompt
if ! ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa\.so'; then
  echo "[setup_peers] Mesa's EGL not found: installing $SYSTEM_PACKAGES (apt-get)"
  if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq $SYSTEM_PACKAGES; }; then
    echo "[setup_peers] ERROR: install them: sudo apt-get install -y $SYSTEM_PACKAGES" >&2
    exit 1
  fi
fi

if [ ! -x .venv/bin/python ]; then
  echo "[setup_peers] ERROR: no .venv; run scripts/setup.sh first" >&2
  exit 1
fi
echo "[setup_peers] installing mi-displace[peers] into .venv"
.venv/bin/python -m pip install -q -e '.[test,peers]'
