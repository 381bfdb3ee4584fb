#!/usr/bin/env bash
# Build the documentation site (Sphinx + MyST, docs/conf.py) into build/docs, warnings as
# errors and every cross reference checked. Needs the docs extra: pip install -e '.[docs]'
# (scripts/setup.sh installs it). Extra arguments go to sphinx-build, e.g. -E for a full rebuild.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-.venv/bin/python}
exec "$PYTHON" -m sphinx -W --keep-going -n -q -b html "$@" docs build/docs
