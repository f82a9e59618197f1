#!/usr/bin/env bash
# The tests that drive bpy, again against another Blender's bpy module (the main suite, scripts/test.sh,
# runs everything against bpy 5.0.1; core/ does not touch bpy):
#   4.2.0  the manifest's blender_version_min (Blender 4.2 LTS: Python 3.11, numpy 1.24.3)
#   5.3.0  the newest Blender (5.1 and later bundle Python 3.13 and numpy 2, and 5.2 changed the
#          geometry nodes modifier's inputs)
# Each gets its own venv (.venv-bpy-VERSION) and shares the main suite's Numba cache (Numba keys its
# cache files by Python version). Usage: bash scripts/test_blender.sh VERSION [pytest arguments]
#                                      bash scripts/test_blender.sh VERSION --setup-only
set -euo pipefail
cd "$(dirname "$0")/.."
version=${1:?"usage: bash scripts/test_blender.sh 4.2.0|5.3.0 [pytest arguments | --setup-only]"}
shift
case "$version" in
  4.2.0) python=3.11 numpy=1.24.3 ;;
  5.3.0) python=3.13 numpy=2.5.5 ;;
  *) echo "scripts/test_blender.sh: no settings for bpy $version (4.2.0 or 5.3.0)" >&2; exit 2 ;;
esac

source scripts/find_python.sh

venv=".venv-bpy-$version"
if [ ! -x "$venv/bin/python" ]; then
  interpreter=$(find_python "$python")
  if [ -z "$interpreter" ]; then
    echo "SKIPPED: the bpy $version tests need Python $python, which this machine does not have" \
         "(set PYTHON_FOR_BPY=/path/to/python$python)" >&2
    exit 0
  fi
  "$interpreter" -m venv "$venv"
fi
# Installed once per version of this script (it holds the pins).
source scripts/install_stamp.sh
if ! install_is_current "$venv" scripts/test_blender.sh; then
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  "$venv/bin/python" -m pip install --quiet "bpy==$version" "numba==0.68.1" "llvmlite==0.50.0" "pytest==9.2.0"
  "$venv/bin/python" -m pip install --quiet --no-deps "numpy==$numpy"  # last: the bpy wheels take any numpy
  mark_installed "$venv" scripts/test_blender.sh
fi
if [ "${1:-}" = "--setup-only" ]; then
  exit 0
fi
exec "$venv/bin/python" -m pytest -p no:cacheprovider tests/test_addon_*.py \
  tests/test_extract*.py tests/test_engine_*.py \
  tests/test_reliability_cancel.py tests/test_reliability_scenes.py "$@"
