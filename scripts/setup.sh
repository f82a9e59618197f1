#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install KD Preview with its
# development dependencies. Needs Python 3.11 (bpy 5.0.1, Blender 4.2 to 5.0) or 3.13 (bpy 5.3.0,
# Blender 5.1 and later): the bpy module exists for no other. 3.11 first, as CI runs it.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/find_python.sh
PY=${PYTHON:-$(find_python 3.11)}
PY=${PY:-$(find_python 3.13)}
if [ -z "$PY" ]; then
  echo "KD Preview needs Python 3.11 or 3.13 (the bpy module is built for those); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
BPY_PYTHONS='import sys; sys.exit(sys.version_info[:2] not in ((3, 11), (3, 13)))'
if ! "$PY" -c "$BPY_PYTHONS" 2>/dev/null; then
  echo "PYTHON=$PY is $("$PY" -V 2>&1); KD Preview needs Python 3.11 or 3.13 (the bpy module is built for those)" >&2
  exit 1
fi
# A .venv made earlier with another Python (an IDE's, a first try with PYTHON set wrong) would fail
# every install with pip's "requires a different Python" (outside QA): make it again.
if [ -e .venv ] && ! .venv/bin/python -c "$BPY_PYTHONS" 2>/dev/null; then
  echo "setup: .venv holds $(.venv/bin/python -V 2>&1 || echo 'no working Python'), not 3.11 or 3.13; making it again with $PY" >&2
  rm -rf .venv
fi
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
# Installed once per pyproject.toml (the install is editable, so code changes need none): every demo
# and test run repeated ~15 s of pip and its warnings (outside QA).
source scripts/install_stamp.sh
if ! install_is_current .venv pyproject.toml; then
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -e ".[dev]"
  mark_installed .venv pyproject.toml
fi
