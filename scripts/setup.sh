#!/usr/bin/env bash
# Idempotent set-up on a fresh Debian/Ubuntu machine: libLLVM >= 17 for Dr.Jit's CPU
# backend, a virtualenv in .venv and `pip install -e .[test]` (the test extra brings the docs extra:
# tests/test_docs*.py build the site).  Re-running is cheap.
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"
  elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo "$@"
  else return 1; fi
}

have_llvm() {  # a libLLVM of version >= 17 that the dynamic loader (or DRJIT_LIBLLVM_PATH) finds
  if [ -n "${DRJIT_LIBLLVM_PATH:-}" ] && [ -f "$DRJIT_LIBLLVM_PATH" ]; then return 0; fi
  ldconfig -p 2>/dev/null | grep -oE 'libLLVM[^ ]*' | grep -qE '(^libLLVM-|\.so\.)(1[7-9]|[2-9][0-9])'
}

if ! have_llvm; then
  echo "[setup] libLLVM >= 17 not found: installing libllvm19 (apt-get)"
  if ! { as_root apt-get update -qq && as_root apt-get install -y -qq libllvm19; }; then
    echo "[setup] ERROR: mi_displace needs libLLVM >= 17 for Dr.Jit's CPU backend." >&2
    echo "        Install it:  sudo apt-get update && sudo apt-get install -y libllvm19" >&2
    echo "        or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version >= 17." >&2
    exit 1
  fi
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  if ! "$PYTHON" -m venv .venv 2>/dev/null; then
    rm -rf .venv
    echo "[setup] python3 -m venv failed: installing python3-venv (apt-get)"
    as_root apt-get update -qq && as_root apt-get install -y -qq python3-venv || {
      echo "[setup] ERROR: install python3-venv (sudo apt-get install -y python3-venv)" >&2; exit 1; }
    "$PYTHON" -m venv .venv
  fi
fi

stamp=.venv/.mi_displace_installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "[setup] installing mi-displace and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e '.[test]'
  touch "$stamp"
fi
