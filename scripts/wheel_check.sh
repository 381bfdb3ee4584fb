#!/usr/bin/env bash
# The installed wheel stands alone: build the wheel from this work tree, install it into a
# fresh plain virtualenv outside the checkout (dependencies from the package index; pip's
# cache is reused), and from a temporary directory run
#   mi-displace --version
#   scripts/wheel_check_load.py: mi.load_file + a 16x16 render of a packaged scene of every plugin
#   tests/core/test_resources.py against the installed package (after installing its [test] extra)
#   mi-displace showcase --quick on two packaged scenes copied into a folder of their own
#   mi-displace bench NAME --quick for each name in BENCHES
# printing the seconds of each step.  Needs python3 with venv and libLLVM >= 17 (setup.sh).
# Usage: scripts/wheel_check.sh [KEEP_DIR]   (default: a mktemp -d folder, removed at exit)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PYTHON=${PYTHON:-python3}
# Scenes for the showcase step: two quick ones, run from a copy (their include files and
# assets then come from the installed package through Mitsuba's file resolver).
SHOWCASE_SCENES=${SHOWCASE_SCENES:-"displaced_sphere.xml bump_vs_displaced.xml"}
# Every bench, in its --quick mode (the peers they cannot find are reported unavailable)
BENCHES=${BENCHES:-"bake bake_blender cluster core ddm denoise dicing frames grad grad_bunny raster slicing vdm volume"}

if [ -n "${1:-}" ]; then mkdir -p "$1"; WORK=$(cd "$1" && pwd); else
  WORK=$(mktemp -d); trap 'rm -rf "$WORK"' EXIT; fi
case "$WORK" in "$ROOT"|"$ROOT"/*) echo "wheel_check: $WORK is inside the checkout" >&2; exit 2;; esac

quiet_pip() { grep -v '^WARNING: Location' || true; }  # this machine's index set-up notes
T0=$(date +%s.%N); STEP_START=$T0
step() {  # step NAME: print the previous step's time, start the next
  local now; now=$(date +%s.%N)
  [ -n "${STEP:-}" ] && awk -v a="$STEP_START" -v b="$now" -v s="$STEP" \
    'BEGIN { printf "[wheel_check] %-40s %7.1f s\n", s, b - a }'
  STEP=$1; STEP_START=$now
}

step "build the wheel"
mkdir -p "$WORK/src" "$WORK/dist"
# a clean copy of the work tree (tracked and untracked, not ignored): no stale build/ output
(cd "$ROOT" && git ls-files -co --exclude-standard -z | tar --null -T - -cf -) | tar -xf - -C "$WORK/src"
"$PYTHON" -m pip wheel -q --no-deps -w "$WORK/dist" "$WORK/src" 2> >(quiet_pip >&2)
WHEEL=$(ls "$WORK"/dist/mi_displace-*.whl)
echo "[wheel_check] $(basename "$WHEEL"): $(du -h "$WHEEL" | cut -f1)"

step "fresh venv + pip install the wheel"
"$PYTHON" -m venv "$WORK/venv"
"$WORK/venv/bin/python" -m pip install -q "$WHEEL" 2> >(quiet_pip >&2)
echo "[wheel_check] $("$WORK/venv/bin/python" -m pip list --format=freeze 2>/dev/null | wc -l) packages in the venv"

RUN="$WORK/run"; mkdir -p "$RUN"; cd "$RUN"
BIN="$WORK/venv/bin"

step "mi-displace --version"
"$BIN/mi-displace" --version
"$BIN/python" -c "import mi_displace, sys; p = mi_displace.__file__; print('[wheel_check] imported', p); sys.exit(not p.startswith('$WORK/venv/'))"

step "load + render a scene of every plugin"
cp "$ROOT/scripts/wheel_check_load.py" "$RUN/"
"$BIN/python" "$RUN/wheel_check_load.py"

step "[test] extra + test_resources.py on the wheel"
"$BIN/python" -m pip install -q "$WHEEL[test]" 2> >(quiet_pip >&2)
mkdir -p "$RUN/tests"
cp "$ROOT/tests/conftest.py" "$ROOT/tests/core/test_resources.py" "$RUN/tests/"
MI_DISPLACE_TEST_VARIANTS=llvm_ad_rgb "$BIN/python" -m pytest -q -p no:cacheprovider "$RUN/tests"

step "showcase --quick (2 scenes, copied)"
mkdir -p "$RUN/scenes"
SCENES_DIR=$("$BIN/python" -c "from mi_displace.core.resources import scenes_dir; print(scenes_dir())")
for s in $SHOWCASE_SCENES; do cp "$SCENES_DIR/$s" "$RUN/scenes/"; done
"$BIN/mi-displace" --quiet showcase --quick --scenes "$RUN/scenes" --out "$RUN/showcase"

for b in $BENCHES; do
  step "bench $b --quick"
  "$BIN/mi-displace" --quiet bench "$b" --quick
done

step "done"
awk -v a="$T0" -v b="$(date +%s.%N)" 'BEGIN { printf "[wheel_check] total %.1f s\n", b - a }'
