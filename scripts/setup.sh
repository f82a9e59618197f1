#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install KD Preview with its
# development dependencies. Needs Python 3.11 (bpy 5.0.1 is built for it).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-}
if [ -z "$PY" ]; then
  for candidate in python3.11 python3 python; do
    if command -v "$candidate" >/dev/null 2>&1 && "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      PY=$candidate
      break
    fi
  done
fi
if [ -z "$PY" ]; then
  echo "KD Preview needs Python 3.11 (the bpy 5.0.1 wheel is built for it); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[dev]"
