#!/usr/bin/env bash
# Set up the environment and run the whole test suite (what CI runs). Extra arguments go to pytest:
# `-m "not slow"` leaves out the long tests (pyproject.toml registers the marker) for a quick check.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# The kernels most tests need compile beside pytest, on the core a cold suite leaves idle while it
# compiles (tests/warm_kernels.py); stopped when pytest ends, whatever it had left to do.
.venv/bin/python -m tests.warm_kernels > .test-warm-kernels.log 2>&1 &
warm=$!
trap 'kill "$warm" 2>/dev/null || true' EXIT
.venv/bin/python -m pytest "$@"
