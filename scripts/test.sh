#!/usr/bin/env bash
# Set up (idempotent) and run the test suite on two pytest-xdist workers (the suite is mostly
# single-threaded Python tracing and LLVM compilation: two workers on two cores take 0.6x the
# time of one). Extra arguments go to pytest, e.g. `./scripts/test.sh -m slow` for the long
# tests, `-n 0` for one process, `-n 4` for four workers.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
exec .venv/bin/python -m pytest -q -n 2 --durations=15 "$@"
