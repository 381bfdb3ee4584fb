#!/usr/bin/env bash
# Set up (idempotent) and run the showcase: every scene marked for it is compared
# (reference vs approximation) into OUT (default out/showcase), with a summary table.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
exec .venv/bin/mi-displace showcase --out "${1:-out/showcase}"
