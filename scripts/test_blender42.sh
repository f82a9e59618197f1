#!/usr/bin/env bash
# Blender 4.2 compatibility (the manifest's blender_version_min): the tests that drive bpy, run against
# the bpy 4.2.0 wheel (Blender 4.2 LTS) with numpy 1.24.3 in .venv42. The main suite (scripts/test.sh)
# runs against bpy 5.0.1; core/ does not touch bpy. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh  # finds Python 3.11 and makes .venv, whose interpreter makes .venv42 below
if [ ! -x .venv42/bin/python ]; then
  .venv/bin/python -m venv .venv42  # a venv made from a venv's Python is based on the same interpreter
fi
.venv42/bin/python -m pip install --quiet --upgrade pip
.venv42/bin/python -m pip install --quiet "bpy==4.2.0" "numba==0.68.1" "llvmlite==0.50.0" "pytest==9.2.0"
.venv42/bin/python -m pip install --quiet --no-deps "numpy==1.24.3"  # last: bpy 4.2.0's wheel takes any numpy
# The Numba cache is the main suite's (tests/addon_support.py): same numba, same kernels.
exec .venv42/bin/python -m pytest -p no:cacheprovider \
  tests/test_addon_cli.py tests/test_addon_config.py tests/test_addon_extension.py tests/test_addon_modal.py \
  tests/test_addon_register.py tests/test_addon_render.py tests/test_addon_reuse.py tests/test_addon_scene_input.py \
  tests/test_extract.py tests/test_reliability_cancel.py tests/test_reliability_scenes.py "$@"
