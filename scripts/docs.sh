#!/usr/bin/env bash
# Set up (idempotent: scripts/setup.sh installs the docs extra with the test extra) and build
# the documentation site (Sphinx + MyST, docs/conf.py) into build/docs/index.html, warnings as
# errors and every cross reference checked. Always from scratch: an incremental build leaves
# the navigation of unchanged pages stale when a toctree changes. Extra arguments go to
# sphinx-build.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
rm -rf build/docs
exec .venv/bin/python -m sphinx -W --keep-going -n -q -b html "$@" docs build/docs
